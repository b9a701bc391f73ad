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
2. **Geometric calibration** on a simulated data set of ours: the quick profile's calibration of
   the RX130L on hidden robot 0 (our remove-and-replace configurations, measured by the simulated
   laser tracker with its noise model); FIGAROH's ``BaseCalibration`` (full geometric parameters,
   unknown base frame = tracker pose and unknown marker position, closed-form frame guess,
   Levenberg-Marquardt, position residuals) fits the same points. Both are scored on the same
   1000 held-out visible poses measured on the same hidden robot. FIGAROH is run with its default
   parameter selection (``structural``) and with ``excitation`` and ``map``; the unified config of
   1.0.2 leaves ``known_baseframe``/``known_tipframe`` unset, the script sets both to False.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
from bench_help import exit_on_help
from figaroh_config import figaroh_calibration_yaml

from pipeline.calibration.elastostatic import measurement_model
from pipeline.calibration.stage import calibrate, heldout_measurements
from pipeline.core.blas import single_thread_blas
from pipeline.core.config import REPO_ROOT
from pipeline.identification.measure import process_record
from pipeline.identification.regressor import RegressorModel
from pipeline.identification.tx40 import Tx40Config, load_tx40_record, run_tx40
from pipeline.robot.model import RobotModel
from pipeline.run.stages import load_config
from pipeline.sim.truth import RealRobot
from pipeline.stage_api import stage_rng

HAVE_FIGAROH = importlib.util.find_spec("figaroh") is not None
if HAVE_FIGAROH:  # optional peer (the bench extra, not installed by default): imported only when present
    from figaroh.calibration.base_calibration import BaseCalibration
    from figaroh.calibration.calibration_tools import calc_updated_fkm
    from figaroh.identification.parameter import add_standard_additional_parameters, get_standard_parameters
    from figaroh.tools.qrdecomposition import QRDecomposer
    from figaroh.tools.regressor import build_regressor_basic, build_regressor_reduced, get_index_eliminate

    class TrackerCalibration(BaseCalibration):
        """FIGAROH's calibration with plain position residuals (a laser tracker measures points)."""

        def cost_function(self, var: np.ndarray) -> np.ndarray:
            return calc_updated_fkm(self.model, self.data, var, self.q_measured, self.calib_config) \
                - self.PEE_measured


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


#: FIGAROH's parameter selection / estimation methods compared (``figaroh.calibration.estimation``:
#: ``structural`` is its default, ``excitation`` drops poorly excited parameters, ``map`` keeps all
#: with Gaussian priors)
FIGAROH_ESTIMATION_METHODS = ("structural", "excitation", "map")


def figaroh_calibration(robot: RobotModel, Q: np.ndarray, Y: np.ndarray, Q_test: np.ndarray,
                        folder: Path, method: str = "structural") -> dict:
    """FIGAROH's geometric calibration (``BaseCalibration``: QR-selected identifiable parameters,
    closed-form frame guess, Levenberg-Marquardt) on tracker points ``Y`` at ``Q``; returns its
    predicted points at ``Q_test`` and its run time."""
    joints = [str(n) for n in robot.model.names[1:]]
    data_file = folder / "figaroh_calibration.csv"
    with data_file.open("w") as fh:
        fh.write(",".join(["x1", "y1", "z1", *joints]) + "\n")
        for y, q in zip(Y, Q, strict=True):
            fh.write(",".join(repr(float(v)) for v in (*y, *q)) + "\n")
    config_file = folder / "figaroh_calibration.yaml"
    config_file.write_text(figaroh_calibration_yaml(
        robot.name, joints, data_file, len(Q), tool_frame="flange", marker="reflector", reference_joint=joints[-1],
        measured_dof=3, method=method, sensor_type="laser_tracker"))
    model = robot.model.copy()
    fig_robot = SimpleNamespace(model=model, data=model.createData(), q0=pin.neutral(model))
    t0 = time.perf_counter()
    calib = TrackerCalibration(fig_robot, str(config_file))
    # the unified config of 1.0.2 does not set these; both frames are unknown here, as in ours
    calib.calib_config["known_baseframe"] = False
    calib.calib_config["known_tipframe"] = False
    with contextlib.redirect_stdout(io.StringIO()):     # its quality report
        calib.initialize()
        calib.solve(method="lm", max_iterations=1, enable_logging=False, plotting=False, save_results=False)
    elapsed = time.perf_counter() - t0
    test_config = {**calib.calib_config, "NbSample": len(Q_test)}
    pred = calc_updated_fkm(model, fig_robot.data, calib.var_, Q_test, test_config).reshape(3, -1).T
    fit = calc_updated_fkm(model, fig_robot.data, calib.var_, Q, calib.calib_config).reshape(3, -1).T
    return {"pred_m": pred, "fit_rms_m": float(np.sqrt(np.mean(np.sum((fit - Y) ** 2, axis=1)))),
            "time_s": elapsed, "n_parameters": len(calib.calib_config["param_name"]),
            "status": calib.STATUS}


def calibration_side_by_side(seed: int = 0) -> dict:
    """Ours and FIGAROH's geometric calibration on the same simulated tracker data: the quick
    profile's 40 remove-and-replace configurations of the RX130L measured on hidden robot ``seed``
    (tracker noise of the sensor model), both scored on the same 1000 held-out visible poses."""
    cfg = load_config(REPO_ROOT / "configs" / "quick.yaml", [f"seed={seed}"])
    robot = RobotModel.load(cfg.robot)
    real = RealRobot.create(robot, cfg.seed, cfg.sections["truth"])
    cal_cfg = cfg.sections["calibration"]
    t0 = time.perf_counter()
    out = calibrate(robot, real, cal_cfg, stage_rng(cfg.seed, "calibration"))
    t_ours = time.perf_counter() - t0
    held = heldout_measurements(robot, real, out.estimate, cal_cfg, np.random.default_rng([seed, 7]))
    mm = measurement_model(robot, cal_cfg)     # the stage's error model (elastostatic when it fits compliances)
    ours_err = np.linalg.norm(mm.predict(held.Q, out.estimate.x, out.estimate.registration) - held.Y, axis=1)
    meas = out.measurements
    print(f"calibration ({robot.name}, hidden robot {seed}): {len(meas)} measured poses, {len(held)} held-out poses, "
          f"tracker sigma {np.median(meas.sigma_m) * 1e6:.1f} um (median)")
    print(f"ours: held-out RMS {np.sqrt(np.mean(ours_err ** 2)) * 1e6:.1f} um, max {ours_err.max() * 1e6:.1f} um; "
          f"fit (registration + LM) {out.timings_s['estimate_s']:.2f} s, whole stage (design, measure, fit, "
          f"validation) {t_ours:.2f} s")
    if not HAVE_FIGAROH:
        print("FIGAROH: skipped (figaroh is not importable; pip install 'pipeline[bench]')")
        return {"ours_rms_m": float(np.sqrt(np.mean(ours_err ** 2)))}
    ours_rms = float(np.sqrt(np.mean(ours_err ** 2)))
    result = {"ours_rms_m": ours_rms}
    for method in FIGAROH_ESTIMATION_METHODS:
        with tempfile.TemporaryDirectory() as tmp, single_thread_blas():
            fig = figaroh_calibration(robot, meas.Q, meas.Y, held.Q, Path(tmp), method)
        fig_err = np.linalg.norm(fig["pred_m"] - held.Y, axis=1)
        fig_rms = float(np.sqrt(np.mean(fig_err ** 2)))
        print(f"FIGAROH 1.0.2 estimation '{method}' ({fig['status']}, {fig['n_parameters']} parameters): held-out RMS "
              f"{fig_rms * 1e6:.1f} um, max {fig_err.max() * 1e6:.1f} um; in-sample RMS "
              f"{fig['fit_rms_m'] * 1e6:.1f} um; fit {fig['time_s']:.2f} s")
        print(f"  ratio ours / FIGAROH '{method}' held-out RMS: {ours_rms / fig_rms:.3f}")
        result[f"figaroh_{method}_rms_m"] = fig_rms
    return result


def main(argv: list[str]) -> None:
    which = argv[0] if argv else "both"
    if which in ("both", "identification"):
        identification_side_by_side()
    if which in ("both", "calibration"):
        calibration_side_by_side()




if __name__ == "__main__":
    exit_on_help(__doc__)
    main(sys.argv[1:])
