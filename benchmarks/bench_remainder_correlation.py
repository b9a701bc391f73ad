"""Does a recorded calibration miss a held-out pose because the pose lies off the training poses?
Leave-one-out with the remainder taken independent between poses (the stage's noise model) against
a remainder correlated between nearby poses, whose prediction widens away from the training poses.

Run: ``.venv/bin/python benchmarks/bench_remainder_correlation.py [ur10 | ROBOT_DIR RECORD.csv]
[--parameters joint_axes] [--seed 0]`` (default ``ur10``: FIGAROH's UR10 6-D record, ``data/figaroh_ur10_mocap``,
its URDF through ``robot init``; about 2 min).

Positions only, one parameter subset (``--parameters``, the one the model selection chooses on the
UR10 record by default), each pose held out in turn and the other ``N - 1`` fitted with equal weights
(ordinary least squares, ``A = (J^T J)^-1 J^T``). The held-out error ``e* = r* - J* A r + n*`` of a
remainder ``r`` with covariance ``V`` has

    E|e*|^2 = trace V** + trace(J* A V A^T J*^T) - 2 trace(J* A V_*)

* **independent** (``V = s^2 I``, ``s^2 = sigma^2 + tau^2``: the readings' stated 1-sigma and the
  stage's REML remainder, :func:`pipeline.calibration.noise_model.reml_remainder`): the stage's
  prediction, ``trace(J* C J*^T) + 3 s^2``;
* **correlated** (``V = s_n^2 I + tau^2 k(x, x') I_3``, ``k = exp(-|x - x'|^2 / (2 l^2))``, ``s_n``,
  ``tau``, ``l`` by REML on the training residuals, best of four starts of ``l``): ``x`` the marker's
  nominal position (m) or the joint angles (rad). Far from every training pose ``V_* -> 0`` and the
  parameter term grows with the correlation: the prediction widens where the fit extrapolates.

Printed per pose: its error, both predictions and their ratios, its distance to the nearest training
pose in each metric; per metric the REML log-likelihood gain of the correlation over the independent
remainder (median over the runs) and the largest ratio.
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from bench_calibration import ur10_robot
from bench_help import exit_on_help
from scipy.optimize import minimize

from pipeline.calibration import measure as ms
from pipeline.calibration.config import Config
from pipeline.calibration.design import identify_parameter_set
from pipeline.calibration.elastostatic import measurement_model
from pipeline.calibration.estimate import estimate
from pipeline.calibration.noise_model import reml_remainder
from pipeline.robot.model import RobotModel

#: starting length scales of the REML search, per metric (m for the marker position, rad for joints)
LENGTH_STARTS = {"marker position": (0.05, 0.1, 0.2, 0.4), "joint angles": (0.3, 0.6, 1.2, 2.4)}


@dataclass
class Correlated:
    """A remainder correlated between poses: white part, correlated part (m, per axis), length scale."""

    white_m: float
    correlated_m: float
    length: float
    reml_gain: float      # REML log-likelihood over the independent remainder's


def kernel(A: np.ndarray, B: np.ndarray, length: float) -> np.ndarray:
    d2 = np.sum((A[:, None, :] - B[None, :, :]) ** 2, axis=-1)
    return np.exp(-0.5 * d2 / length ** 2)


def remainder_covariance(X: np.ndarray, white_m: float, correlated_m: float, length: float) -> np.ndarray:
    """``(3N, 3N)`` covariance of the stacked remainder at the poses ``X``."""
    return white_m ** 2 * np.eye(3 * len(X)) + correlated_m ** 2 * np.kron(kernel(X, X, length), np.eye(3))


def reml_negative_log_likelihood(V: np.ndarray, r: np.ndarray, J: np.ndarray) -> float:
    """``(log|V| + log|J^T V^-1 J| + r^T P r) / 2``, ``P = V^-1 - V^-1 J (J^T V^-1 J)^-1 J^T V^-1``."""
    L = np.linalg.cholesky(V)
    LJ, Lr = np.linalg.solve(L, J), np.linalg.solve(L, r)
    A = LJ.T @ LJ
    b = LJ.T @ Lr
    return 0.5 * (2.0 * np.sum(np.log(np.diag(L))) + np.linalg.slogdet(A)[1] + Lr @ Lr - b @ np.linalg.solve(A, b))


def fit_correlated(r: np.ndarray, J: np.ndarray, X: np.ndarray, s_iid: float, starts: tuple[float, ...]
                   ) -> Correlated:
    def objective(log_params: np.ndarray) -> float:
        try:
            return reml_negative_log_likelihood(remainder_covariance(X, *np.exp(log_params)), r, J)
        except np.linalg.LinAlgError:
            return np.inf

    best = min((minimize(objective, np.log([s_iid / 2, s_iid, start]), method="Nelder-Mead",
                         options={"xatol": 1e-3, "fatol": 1e-4, "maxiter": 600}) for start in starts),
               key=lambda res: res.fun)
    independent = reml_negative_log_likelihood(s_iid ** 2 * np.eye(len(r)), r, J)
    white, corr, length = np.exp(best.x)
    return Correlated(float(white), float(corr), float(length), float(independent - best.fun))


def main() -> None:
    exit_on_help(__doc__)
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("record", nargs="*", default=["ur10"])
    parser.add_argument("--parameters", default="joint_axes")
    parser.add_argument("--seed", type=int, default=0, help="the identifiability check's random configurations")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if args.record == ["ur10"]:
            folder = Path(tmp) / "ur10"
            folder.mkdir()
            robot, csv = ur10_robot(folder)
        elif len(args.record) == 2:
            robot, csv = RobotModel.load(Path(args.record[0]).resolve()), Path(args.record[1]).resolve()
        else:
            raise SystemExit("give ur10, or a robot folder and a record CSV")
        meas = ms.read_csv(csv, robot)
    cfg = replace(Config(), parameters=args.parameters)
    mm = measurement_model(robot, cfg, marker_points=False)
    basis = identify_parameter_set(robot, mm, cfg, np.random.default_rng(args.seed))[1]
    Q, Y, N = meas.Q, meas.Y, len(meas)
    metrics = {"marker position": mm.base_positions(Q, np.zeros(mm.n), None, None)[0], "joint angles": Q}
    errors, iid, corr = np.zeros(N), np.zeros(N), {m: np.zeros(N) for m in metrics}
    gains = {m: np.zeros(N) for m in metrics}
    nearest = {m: np.zeros(N) for m in metrics}
    for k in range(N):
        train = np.arange(N) != k
        sigma_m = np.full(int(train.sum()), float(np.sqrt(np.mean(meas.sigma_m[train] ** 2))))   # equal weights
        est = estimate(mm, Q[train], Y[train], sigma_m, basis, max_iterations=cfg.max_lm_iterations)
        pred, J_blocks = mm.jacobian(Q[train], est.x, est.registration, est.basis)
        pred_k, J_k = mm.jacobian(Q[k:k + 1], est.x, est.registration, est.basis)
        r, J, Jk = (Y[train] - pred).ravel(), J_blocks.reshape(-1, J_blocks.shape[2]), J_k[0]
        errors[k] = np.linalg.norm(Y[k] - pred_k[0])
        G = np.linalg.inv(J.T @ J)
        A = G @ J.T
        s2 = sigma_m[0] ** 2 + reml_remainder(Y[train] - pred, J_blocks, sigma_m)[0] ** 2
        iid[k] = np.sqrt(s2 * (np.trace(Jk @ G @ Jk.T) + 3.0))
        for name, X in metrics.items():
            c = fit_correlated(r, J, X[train], np.sqrt(s2), LENGTH_STARTS[name])
            V = remainder_covariance(X[train], c.white_m, c.correlated_m, c.length)
            V_k = c.correlated_m ** 2 * np.kron(kernel(X[train], X[k:k + 1], c.length), np.eye(3))
            corr[name][k] = np.sqrt(3.0 * (c.white_m ** 2 + c.correlated_m ** 2) + np.trace(Jk @ A @ V @ A.T @ Jk.T)
                                    - 2.0 * np.trace(Jk @ A @ V_k))
            gains[name][k] = c.reml_gain
            nearest[name][k] = np.min(np.linalg.norm(X[train] - X[k], axis=1))
    worst = int(np.argmax(errors / iid))
    print(f"{csv.name}, {N} poses, positions only, `{args.parameters}` ({basis.shape[1]} parameters), leave-one-out: "
          f"the largest error/predicted is pose {worst}, {errors[worst] / iid[worst]:.2f} independent, "
          + ", ".join(f"{errors[worst] / corr[m][worst]:.2f} correlated in {m}" for m in metrics))
    print(f"  RMS error {1e3 * np.sqrt(np.mean(errors ** 2)):.3f} mm, predicted independent "
          f"{1e3 * np.sqrt(np.mean(iid ** 2)):.3f} mm (mean |e|^2/predicted^2 {np.mean((errors / iid) ** 2):.3f})")
    for m in metrics:
        ratio = errors / corr[m]
        print(f"  correlated in {m}: predicted {1e3 * np.sqrt(np.mean(corr[m] ** 2)):.3f} mm (mean |e|^2/predicted^2 "
              f"{np.mean(ratio ** 2):.3f}), REML gain over independent median {np.median(gains[m]):.2f} "
              f"(range {gains[m].min():.2f}..{gains[m].max():.2f}), largest ratio {ratio.max():.2f} (pose "
              f"{int(np.argmax(ratio))}); nearest training pose median {np.median(nearest[m]):.3g}")
    names = list(metrics)
    print("pose  error mm  independent mm (ratio)  " + "  ".join(f"{m}: mm (ratio) nearest" for m in names))
    for k in np.argsort(-errors / iid):
        cols = "  ".join(f"{1e3 * corr[m][k]:5.2f} ({errors[k] / corr[m][k]:4.2f}) {nearest[m][k]:.3g}" for m in names)
        print(f"{k:4d}  {1e3 * errors[k]:8.2f}  {1e3 * iid[k]:8.2f} ({errors[k] / iid[k]:4.2f})  {cols}")


if __name__ == "__main__":
    main()
