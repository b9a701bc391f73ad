"""Paper 000's outlook measured: the KPI with joint elasticity modelled (``study calib-000``).

Paper 000 (``papers/000_bd0c20fcd494d4a1.txt``, Outlook): "the improvements are achieved by
considering a kinematic model of the manipulator only. However, the improvement could be increased
by incorporating [...] nongeometric errors like joint mobilities or elasticities." The paper gives
no number for it ("outlook, not measured"). This experiment measures it on the study's own
TCP-criterion design (``tcp_ca``, same configurations) for an arm in its cell:

1. the design is measured on the default hidden robot (:class:`pipeline.sim.truth.RealRobot`,
   ``TruthConfig()``: elastic joints with a per-seed stiffness spread, gear transmission error,
   tracker noise) with the simulated tracker, for ``seeds`` hidden robots;
2. the readings are calibrated (the stage's robust estimator,
   :func:`pipeline.calibration.robust.robust_estimate`, its defaults and gravity-model prior) with
   (a) the geometric model (``calibration.parameters: geometric``, DH/Hayati as the study) and
   (b) the compliance-aware model (``all``: geometric + joint compliances ``j{i}.c``,
   ``q_link = q - c g(q)`` with the nominal gravity torques, :mod:`pipeline.calibration.error_model`);
3. the KPI, the TCP position at the working configuration ``q_work``, is evaluated

   - covariance-predicted (paper 000 eq. 16, 24a with ``C_s``): ``trace(J_w M^-1 J_w^T) / 3``
     with ``M`` the tracker-noise information of the design on each model's identifiable set; for
     the compliance-aware model ``J_w`` has the compliance columns ``dp/dc_i = -J_q[:, i] g_i(q_work)``
     (the TCP deflects under gravity at the working configuration too);
   - actual: the error of the calibrated model's TCP against the hidden robot's TCP at its
     deflected link angles (:meth:`RealRobot.link_angles`) at ``q_work``, and its RMS over
     ``n_random`` random configurations of the arm's range (not only where the design aimed);
     the compliance-aware TCP is ``fk(q - c_hat g(q))`` of the calibrated kinematics, the
     geometric one ``fk(q)``.

The gain of modelling elasticity is ``1 - RMS_b / RMS_a`` of the actual TCP error (RMS over the
seeds). The predicted figure of (a) assumes a rigid arm, so on the elastic truth it is not what (a)
achieves; the predicted figure of (b) is the KPI of the design on the extended parameter set.
Cost: about 10-30 s per arm and seed on the shared 2-core machine.
"""

from __future__ import annotations

import numpy as np

from pipeline.calibration import error_model as em
from pipeline.calibration import indices as ix
from pipeline.calibration import measure as ms
from pipeline.calibration import stage as st
from pipeline.calibration.estimate import Estimate, calibrated_robot
from pipeline.calibration.gravity_uncertainty import GravityCovariance
from pipeline.calibration.robust import robust_estimate
from pipeline.core.errors import SolverError
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot, TruthConfig

MODELS = ("geometric", "all")
#: the reference: the geometric model on the rigid hidden robot (``TruthConfig.ideal()``), the
#: paper's own setting; its error is the floor of position-only calibration (tool rotations are not
#: observable from one reflector, so a tool rotation error moves the TCP unseen)
RIGID = "geometric_rigid_truth"


def tcp_jacobian(robot: RobotModel, mm: em.MeasurementModel, q: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """``(3, p)`` TCP-position Jacobian at ``q`` wrt the identifiable ``theta`` (``x = basis theta``):
    :func:`pipeline.calibration.stage.working_jacobian`, whose elastostatic columns are
    ``dp/dc_i = -J_q[:, i] g_i(q)`` (``q_link = q - c g(q)``)."""
    return st.working_jacobian(robot, mm, q[None], basis)


def predicted_tcp_variance(robot: RobotModel, mm: em.MeasurementModel, basis: np.ndarray, Q: np.ndarray,
                           q_work: np.ndarray) -> float:
    """Mean variance per TCP coordinate at ``q_work`` (m^2) of design ``Q`` with the parameters
    ``basis`` of ``mm`` (paper 000 eq. 16 and 24a, ``C_s``; tracker-noise information at the nominal
    model, the identifiable set's whitened Jacobian)."""
    T_tb = robot.tracker.transform_tracker_to_base
    Y, J = mm.jacobian(Q, np.zeros(mm.n), T_tb, basis)
    G = (J / ms.noise_model_sigma(robot, Y)[:, None, None]).reshape(-1, basis.shape[1])
    spec = ix.IndexSpec("tcp_A", working_jacobian=tcp_jacobian(robot, mm, q_work, basis), n_working=1)
    return ix.evaluate(spec, G.T @ G, len(Q)) / 3.0


def model_tcp(robot: RobotModel, mm: em.MeasurementModel, est: Estimate, Q: np.ndarray) -> np.ndarray:
    """``(N, 3)`` TCP positions (base frame) the calibrated model predicts at encoder angles ``Q``:
    the calibrated kinematics (:func:`pipeline.calibration.estimate.calibrated_robot`: the reflector
    correction moves the tool) at ``q - c_hat g(q)`` (elastostatic) or ``q`` (geometric)."""
    Q = np.atleast_2d(Q)
    q_link = Q - est.x[mm.sl_compliance] * mm.static_torques(Q) if mm.compliance else Q
    new = calibrated_robot(robot, mm, est.x)
    return new.positions(q_link, new.frame_tcp)


def true_tcp(real: RealRobot, Q: np.ndarray) -> np.ndarray:
    """``(N, 3)`` TCP positions of the hidden robot at encoder angles ``Q`` (deflected under gravity)."""
    return real.truth.positions(real.link_angles(np.atleast_2d(Q)), real.truth.frame_tcp)


def _calibrate(robot: RobotModel, mm: em.MeasurementModel, basis: np.ndarray, meas: ms.Measurements,
               cfg: st.Config) -> Estimate:
    """The stage's estimator with its defaults (robust loss, outlier test, gravity-model prior)."""
    est, _ = robust_estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis, meas.source, cfg.max_lm_iterations,
                             meas.payload_mounted, cfg.robust_loss, cfg.outlier_confidence,
                             cfg.max_outlier_fraction, None, GravityCovariance(mm, cfg.gravity_prior()))
    return est


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(np.asarray(e) ** 2, axis=-1))))


def _seed_rows(robot: RobotModel, mms: dict, bases: dict, cfgs: dict, Q: np.ndarray, q_work: np.ndarray,
               Q_random: np.ndarray, seed: int, rng: np.random.Generator) -> dict[str, dict[str, float]]:
    """One seed: the geometric and compliance-aware calibrations on the elastic hidden robot and the
    geometric one on the rigid hidden robot; TCP errors at ``q_work`` and over ``Q_random``."""
    rows: dict[str, dict[str, float]] = {}
    for m, truth, model in (("geometric", TruthConfig(), "geometric"), ("all", None, "all"),
                            (RIGID, TruthConfig.ideal(), "geometric")):
        if truth is not None:   # one hidden robot per seed and truth: (a) and (b) fit the same readings
            real = RealRobot.create(robot, seed, truth)
            meas = ms.measure_simulated(real, Q, rng)
            work_true, random_true = true_tcp(real, q_work)[0], true_tcp(real, Q_random)
        mm, basis = mms[model], bases[model]
        est = _calibrate(robot, mm, basis, meas, cfgs[model])
        Jw = tcp_jacobian(robot, mm, q_work, basis)
        rows[m] = {"work_m": float(np.linalg.norm(model_tcp(robot, mm, est, q_work)[0] - work_true)),
                   "random_rms_m": _rms(model_tcp(robot, mm, est, Q_random) - random_true),
                   "chi2_per_dof": est.chi2_per_dof,
                   "predicted_work_rms_m": float(np.sqrt(np.trace(Jw @ est.covariance @ Jw.T)))}
    return rows


def elastic_gain(robot: RobotModel, mm_geometric: em.MeasurementModel, Q: np.ndarray, q_work: np.ndarray,
                 seeds: list[int], rng: np.random.Generator, n_random: int = 200) -> dict:
    """The experiment of the module docstring for design ``Q`` of ``robot`` (in its cell). A seed whose
    calibration fails (:class:`SolverError`) is left out of every model's figures and named in
    ``failed_seeds``; SolverError when none calibrates."""
    cfgs = {m: st.Config(error_model="mdh_hayati", parameters=m) for m in MODELS}
    mms = {"geometric": mm_geometric,
           "all": em.MeasurementModel(robot, mm_geometric.sym, compliance=True, payload=cfgs["all"].payload())}
    bases = {m: st.identify_parameter_set(robot, mms[m], cfgs[m], rng)[1] for m in MODELS}
    Q_random = em.random_configurations(robot, n_random, rng)
    out: dict = {"seeds": list(seeds), "n_configurations": int(len(Q)), "n_random": int(n_random),
                 "n_parameters": {m: int(bases[m].shape[1]) for m in MODELS},
                 "predicted_tcp_var": {m: predicted_tcp_variance(robot, mms[m], bases[m], Q, q_work) for m in MODELS}}
    per_seed: dict[str, dict[str, list[float]]] = {m: {"work_m": [], "random_rms_m": [], "chi2_per_dof": [],
                                                        "predicted_work_rms_m": []} for m in MODELS}
    per_seed[RIGID] = {k: [] for k in per_seed["geometric"]}
    failed: dict[str, str] = {}
    for seed in seeds:
        try:
            rows = _seed_rows(robot, mms, bases, cfgs, Q, q_work, Q_random, seed, rng)
        except SolverError as exc:   # e.g. the readings the outlier test keeps leave a parameter unexcited
            failed[str(seed)] = str(exc)
            continue
        for m, row in rows.items():
            for k, v in row.items():
                per_seed[m][k].append(v)
    if not per_seed["geometric"]["work_m"]:
        raise SolverError(None, "elasticity experiment", f"no seed calibrated: {failed}")
    out["per_seed"] = per_seed
    out["seeds"] = [seed for seed in seeds if str(seed) not in failed]     # the seeds the figures are over
    out["failed_seeds"] = failed
    for m in (*MODELS, RIGID):
        w = np.asarray(per_seed[m]["work_m"])
        out[m] = {"work_rms_m": _rms(w[:, None]),
                  "work_sem_m": float(w.std(ddof=1) / np.sqrt(len(w))) if len(w) > 1 else float("nan"),
                  "random_rms_m": _rms(np.asarray(per_seed[m]["random_rms_m"])[:, None]),
                  "chi2_per_dof": float(np.mean(per_seed[m]["chi2_per_dof"]))}
    out["gain_work"] = 1.0 - out["all"]["work_rms_m"] / out["geometric"]["work_rms_m"]
    out["gain_random"] = 1.0 - out["all"]["random_rms_m"] / out["geometric"]["random_rms_m"]
    return out


def _um(x: float) -> str:
    return f"{1e6 * x:.0f}"


def elastic_table(rows: list[dict]) -> list[str]:
    """Per arm: predicted and actual TCP error of both models, the rigid-truth floor and the gain of
    modelling elasticity (paper 000: outlook, not measured)."""
    rows = [r for r in rows if "elastic" in r]
    if not rows:
        return []
    out = ["| arm | seeds | predicted KPI (design, sqrt trace C_s) geometric / with compliance [µm] | actual TCP "
           "error at q_work, RMS ± s.e. over seeds: geometric / with compliance / geometric on a rigid truth [µm] | "
           "gain at q_work (paper: outlook, not measured) | RMS over random poses: geometric / with compliance / "
           "rigid truth [µm] | gain there | chi²/dof geometric / with compliance |", "|---" * 8 + "|"]
    for r in rows:
        e = r["elastic"]
        g, a, f = e["geometric"], e["all"], e[RIGID]
        pg, pa = (1e6 * np.sqrt(3 * e["predicted_tcp_var"][m]) for m in MODELS)
        work = " / ".join(f"{_um(v['work_rms_m'])} ± {_um(v['work_sem_m'])}" for v in (g, a, f))
        rand = " / ".join(_um(v["random_rms_m"]) for v in (g, a, f))
        out.append(f"| {r['arm']} | {len(e['seeds'])} | {pg:.1f} / {pa:.1f} | {work} | {100 * e['gain_work']:.0f} % | "
                   f"{rand} | {100 * e['gain_random']:.0f} % | {g['chi2_per_dof']:.0f} / {a['chi2_per_dof']:.2f} |")
    return out
