"""Peers side by side: FIGAROH (``pip install 'pipeline[bench]'``, figaroh 1.0.2) on our data.

Run: ``.venv/bin/python benchmarks/bench_peers.py [identification|calibration]`` (default both).
Installs nothing: without an importable ``figaroh`` it prints that the comparison is skipped.
(toppra and ruckig are compared in ``bench_trajectory.py``.)

1. **Identification on the Stäubli TX40 record** (``data/staubli_tx40/``, FIGAROH's own example
   data). Both tools get the same joint-side samples: our motor -> joint conversion
   (``q = K^-1 q_m``, ``tau = K^T tau_m``, coupled axes 5/6) and torque processing (zero-phase
   low-pass of the positions, parallel decimation of states and torques, border samples dropped,
   :func:`pipeline.identification.measure.process_record`), the same split (first 70 % of the
   processed samples to fit, last 30 % to score). FIGAROH's model is that of its TX40 example:
   ``build_regressor_basic`` with viscous + Coulomb (``sign``) friction, actuator inertia and
   torque offset per joint, the example's three coupled-wrist columns (``Iam6``, ``fvm6``,
   ``fsm6``), columns of negligible norm removed (``get_index_eliminate``), base parameters and
   their least-squares values by its double QR (``QRDecomposer.double_decomposition``). FIGAROH's
   Gautier WLS (``weigthed_least_squares``) builds a dense (6N)² weight matrix (2.9 GB here) and is
   not run. Printed: held-out RMS per joint of FIGAROH's OLS and of our OLS, WLS and physically
   consistent fit (the stage's result), the run times, and the ratio ours / FIGAROH.
2. **Geometric calibration** on a simulated data set of ours (see :func:`calibration_side_by_side`).
"""

from __future__ import annotations

import importlib.util
import sys
import time
from types import SimpleNamespace

import numpy as np

from pipeline.blas import single_thread_blas
from pipeline.identification.measure import process_record
from pipeline.identification.regressor import RegressorModel
from pipeline.identification.tx40 import Tx40Config, load_tx40_record, run_tx40
from pipeline.robot.model import RobotModel

HAVE_FIGAROH = importlib.util.find_spec("figaroh") is not None
if HAVE_FIGAROH:
    from figaroh.identification.parameter import add_standard_additional_parameters, get_standard_parameters
    from figaroh.tools.qrdecomposition import QRDecomposer
    from figaroh.tools.regressor import build_regressor_basic, build_regressor_reduced, get_index_eliminate


def _rms_per_joint(tau: np.ndarray, pred: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean((tau - pred) ** 2, axis=0))


def _figaroh_regressor(robot: SimpleNamespace, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                       config: dict) -> np.ndarray:
    """FIGAROH's joint-major regressor (row ``j*N + i``) plus the TX40 example's coupled-wrist
    columns (figaroh-examples ``staubli_tx40_tools.TX40Identification._add_coupling``)."""
    W = build_regressor_basic(robot, q, v, a, config)
    n = q.shape[0]
    extra = np.zeros((W.shape[0], 3))
    s = np.sign(v[:, 4] + v[:, 5])
    extra[4 * n:5 * n] = np.c_[a[:, 5], v[:, 5], s]
    extra[5 * n:6 * n] = np.c_[a[:, 4], v[:, 4], s]
    return np.c_[W, extra]


def figaroh_tx40(robot: RobotModel, train_fraction: float) -> dict:
    """FIGAROH's identification on our processed TX40 samples (module docstring, item 1)."""
    cfg = Tx40Config()
    t0 = time.perf_counter()
    rec = load_tx40_record(robot)
    act = robot.actuation
    data = process_record(rec, RegressorModel(robot.model, act.gear_matrix, act.coulomb_smoothing_rad_s),
                          cfg.cutoff_hz, cfg.decimation, cfg.border_samples)
    t_process = time.perf_counter() - t0
    nq = robot.nq
    ntr = int(train_fraction * data.n_samples)
    model = robot.model
    fig_robot = SimpleNamespace(model=model, data=model.createData())
    config = {"has_friction": True, "has_actuator_inertia": True, "has_joint_offset": True,
              "is_joint_torques": True, "is_external_wrench": False, "act_idxv": list(range(nq)),
              "fv": [0.0] * nq, "fs": [0.0] * nq, "Ia": [0.0] * nq, "off": [0.0] * nq}
    t1 = time.perf_counter()
    params_std = get_standard_parameters(model, config) | add_standard_additional_parameters(model, config)
    params_std.update({"Iam6": 0.0, "fvm6": 0.0, "fsm6": 0.0})
    tr, te = slice(0, ntr), slice(ntr, None)
    W_tr = _figaroh_regressor(fig_robot, data.q[tr], data.v[tr], data.a[tr], config)
    tau_tr = data.tau[tr].T.ravel()                                     # joint-major, like W
    idx_e, params_r = get_index_eliminate(W_tr, params_std, tol_e=1e-6)
    W_e = build_regressor_reduced(W_tr, idx_e)
    qr = QRDecomposer()
    _W_b, _base, names, phi_b = qr.double_decomposition(tau_tr, W_e, params_r)
    t_fit = time.perf_counter() - t1
    train_rms = float(np.sqrt(np.mean((W_e[:, qr.base_indices] @ phi_b - tau_tr) ** 2)))
    W_te = build_regressor_reduced(_figaroh_regressor(fig_robot, data.q[te], data.v[te], data.a[te], config), idx_e)
    pred = (W_te[:, qr.base_indices] @ phi_b).reshape(nq, -1).T
    return {"rms_per_joint_Nm": _rms_per_joint(data.tau[te], pred),
            "rms_Nm": float(np.sqrt(np.mean((data.tau[te] - pred) ** 2))),
            "train_rms_Nm": train_rms, "n_base": len(names), "n_train": ntr, "n_samples": data.n_samples,
            "process_s": t_process, "fit_s": t_fit}


def identification_side_by_side() -> dict:
    robot = RobotModel.load("staubli_tx40")
    cfg = Tx40Config()
    t0 = time.perf_counter()
    ours = run_tx40(robot, cfg)
    t_ours = time.perf_counter() - t0
    print(f"TX40 record: {ours.details['n_samples']} processed samples, fit on the first "
          f"{ours.details['n_train']} ({cfg.train_fraction:.0%}), scored on the rest")
    print(f"ours: {ours.n_base_parameters} base parameters, whole run (load, process, OLS, WLS, physical fit) "
          f"{t_ours:.2f} s")
    if not HAVE_FIGAROH:
        print("FIGAROH: skipped (figaroh is not importable; pip install 'pipeline[bench]')")
        return {"ours": ours}
    with single_thread_blas():
        fig = figaroh_tx40(robot, cfg.train_fraction)
    print(f"FIGAROH 1.0.2: {fig['n_base']} base parameters, processing {fig['process_s']:.2f} s (ours, shared) "
          f"+ regressor, elimination, double QR {fig['fit_s']:.2f} s")
    header = "held-out RMS per joint (N m)"
    print(f"{header:<34}" + "".join(f"{'j' + str(j + 1):>8}" for j in range(robot.nq)) + f"{'all':>8}")
    rows = {"FIGAROH OLS": (fig["rms_per_joint_Nm"], fig["rms_Nm"])}
    for key, label in (("ols", "ours OLS"), ("wls", "ours WLS"), ("physical", "ours physical (stage result)")):
        rows[label] = (np.asarray(ours.heldout_rms_per_joint_Nm[key]), ours.heldout_rms_Nm[key])
    for label, (per_joint, total) in rows.items():
        print(f"{label:<34}" + "".join(f"{x:8.3f}" for x in per_joint) + f"{total:8.3f}")
    print(f"in-sample (fit) RMS, N m: FIGAROH OLS {fig['train_rms_Nm']:.3f}; ours OLS {ours.train_rms_Nm['ols']:.3f}, "
          f"WLS {ours.train_rms_Nm['wls']:.3f}, physical {ours.train_rms_Nm['physical']:.3f}")
    ratio = ours.heldout_rms_Nm["physical"] / fig["rms_Nm"]
    per_joint_ratio = np.asarray(ours.heldout_rms_per_joint_Nm["physical"]) / fig["rms_per_joint_Nm"]
    print(f"ratio ours physical / FIGAROH held-out RMS: {ratio:.3f} (per joint "
          + ", ".join(f"{r:.2f}" for r in per_joint_ratio) + ")"
          + ("  ours not worse" if ratio <= 1.0 else "  OURS WORSE"))
    print(f"run time ours (whole run) / FIGAROH (processing + fit): {t_ours / (fig['process_s'] + fig['fit_s']):.2f}")
    return {"ours": ours, "figaroh": fig}


def main(argv: list[str]) -> None:
    which = argv[0] if argv else "both"
    if which in ("both", "identification"):
        identification_side_by_side()
    if which in ("both", "calibration"):
        calibration_side_by_side()


def calibration_side_by_side() -> None:
    print("calibration: not yet compared")


if __name__ == "__main__":
    main(sys.argv[1:])
