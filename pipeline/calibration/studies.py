"""Paper studies of the calibration stage (``python -m pipeline study calib-004|calib-000|calib-002|calib-003``).

Each study prints a table beside the paper's numbers and writes ``data/studies/<name>/result.json``.
Runs over seeds / arms are parallel with joblib (``--jobs``, default 1 on the shared machine).

- calib-004 (papers/004 §3.4): 32 configurations from the joint grid by remove-and-replace on O3
  against a linear scan with the same number of poses (paper: index better by a factor 18.5);
  held-out errors before/after calibration (paper Table 2 layout).
- calib-000: moved to :mod:`pipeline.calibration.paper_000`.
- calib-002 (papers/002 §3): a 6-axis DH arm with a probe (25 parameters): redundant parameters by
  SVD (paper: rank 23, 2 redundant) and Gauss-Newton steps converging.
- calib-003 (papers/003 Table 2): a UR10-like arm: mean/RMS/max positioning error on 50 validation
  poses for random ("none"), DETMAX x {O1, O2, O3, Oc} and BSAA x {O1, O2, O3, Oc}.
"""

from __future__ import annotations

import argparse
import json
import math
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pinocchio as pin

from pipeline.blas import single_thread_blas
from pipeline.calibration import design as ds
from pipeline.calibration import error_model as em
from pipeline.calibration import indices as ix
from pipeline.calibration import stage as st
from pipeline.calibration.estimate import estimate


def _parallel(fn, items, jobs: int):
    if jobs <= 1:
        return [fn(i) for i in items]
    from joblib import Parallel, delayed

    return Parallel(n_jobs=jobs)(delayed(fn)(i) for i in items)


def _save(name: str, result: dict) -> None:
    from pipeline.studies import study_dir

    path = study_dir(name) / "result.json"
    path.write_text(json.dumps(result, indent=1, default=float))
    print(f"\nwritten {path}")


# ------------------------------------------------------------------------------------------------
# calib-004
# ------------------------------------------------------------------------------------------------
def _calibrate_with(robot, real, mm, basis, Q, rng, n_heldout: int):
    from pipeline.calibration import measure as ms
    from pipeline.calibration import validate as va

    meas = ms.measure_simulated(real, Q, rng)
    est = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis)
    held = st.heldout_measurements(robot, real, est, st.Config(n_heldout=n_heldout), rng)
    return va.validate(mm, est, held), len(meas)


def _study_004_seed(args) -> dict:
    robot_name, seed, grid, n, n_heldout = args
    from pipeline.robot.model import RobotModel
    from pipeline.robot.truth import RealRobot

    with single_thread_blas():
        robot = RobotModel.load(robot_name)
        real = RealRobot.create(robot, seed)
        rng = np.random.default_rng([seed, 4])
        mm = em.MeasurementModel(robot)
        cfg = st.Config(grid_per_axis=grid)
        rep, basis = st.identify_parameter_set(robot, mm, cfg, rng)
        cs = st.build_candidates(robot, cfg, basis, rng)
        spec = ix.IndexSpec("O3")
        rr = ds.remove_and_replace(cs.G, spec, n, rng, n_initial=n)
        lin = ds.linear_scan_design(cs.G, spec, n)
        rnd = ds.random_design(cs.G, spec, n, rng)
        v_rr, m_rr = _calibrate_with(robot, real, mm, basis, cs.Q[rr.selected], rng, n_heldout)
        v_lin, m_lin = _calibrate_with(robot, real, mm, basis, cs.Q[lin.selected], rng, n_heldout)
    strip = ("errors_before_m", "errors_after_m", "predicted_std_m")
    return {"seed": seed, "n_candidates": len(cs), "grid_total": cs.counts.get("total"),
            "O3_rr": rr.index_value, "O3_linear": lin.index_value, "O3_random": rnd.index_value,
            "rr_time_s": rr.run_time_s,
            "rr_evaluations": rr.evaluations, "measured_rr": m_rr, "measured_linear": m_lin,
            "rr": {k: v for k, v in v_rr.items() if k not in strip},
            "linear": {k: v for k, v in v_lin.items() if k not in strip}}


def study_004(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="study calib-004")
    ap.add_argument("--robot", default="rx130l")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--grid", type=int, default=13)
    ap.add_argument("--n", type=int, default=32)
    ap.add_argument("--heldout", type=int, default=1000)
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args(argv)
    rows = _parallel(_study_004_seed, [(a.robot, s, a.grid, a.n, a.heldout) for s in a.seeds], a.jobs)
    print(f"\npaper 004 §3.4: {a.n} configurations from the {a.grid}^6 grid, remove-and-replace on O3")
    print("(linear scan: every (N/n)-th feasible grid configuration in grid order; random: a random subset)")
    print("| seed | candidates | O3 R&R | O3 linear scan | ratio (paper 18.5) | O3 random | ratio | R&R time [s] |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['seed']} | {r['n_candidates']} | {r['O3_rr']:.4g} | {r['O3_linear']:.4g} | "
              f"{r['O3_rr'] / max(r['O3_linear'], 1e-300):.1f} | {r['O3_random']:.4g} | "
              f"{r['O3_rr'] / max(r['O3_random'], 1e-300):.1f} | {r['rr_time_s']:.1f} |")
    print("\nheld-out errors (paper Table 2: max uncal. 7.8/19.0/12.6 mm, cal. 0.27/0.31/0.41 mm per axis)")
    print("| seed | design | RMS before [mm] | max before [mm] | RMS after [µm] | max after [µm] | "
          "predicted RMS [µm] | max |ex|,|ey|,|ez| after [µm] |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        for key in ("rr", "linear"):
            v = r[key]
            ax = v["after"]["axes"]
            print(f"| {r['seed']} | {key} | {1e3 * v['before']['rms']:.3f} | {1e3 * v['before']['max']:.3f} | "
                  f"{1e6 * v['after']['rms']:.1f} | {1e6 * v['after']['max']:.1f} | {1e6 * v['predicted_rms_m']:.1f} | "
                  f"{1e6 * ax['x']['max_abs']:.0f}, {1e6 * ax['y']['max_abs']:.0f}, {1e6 * ax['z']['max_abs']:.0f} |")
    _save("calib-004", {"args": vars(a), "rows": rows, "paper": {"index_factor": 18.5}})
    return 0


# ------------------------------------------------------------------------------------------------
# calib-002: DH arm with a probe, SVD of the identification Jacobian, Gauss-Newton
# ------------------------------------------------------------------------------------------------
#: AACMM-like standard DH table (theta offset, d, a, alpha) and probe length: alternating swivel and
#: hinge joints (papers/002 Table 1 is not in the extracted text; representative values)
AACMM_DH = [(0.0, 0.25, 0.03, -np.pi / 2), (0.0, 0.05, 0.03, np.pi / 2), (0.0, 0.60, 0.03, -np.pi / 2),
            (0.0, 0.05, 0.03, np.pi / 2), (0.0, 0.55, 0.03, -np.pi / 2), (0.0, 0.05, 0.04, 0.0)]
AACMM_PROBE_M = 0.12


def dh_probe_function() -> tuple[ca.Function, list[str]]:
    """``p(q, params)`` of the DH arm: ``T_i = Rz(theta_i + q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``,
    probe tip at ``(0, 0, l)`` of the last frame (papers/002 eq. 1-5)."""
    q = ca.SX.sym("q", 6)
    prm = ca.SX.sym("p", 25)
    T = ca.SX.eye(4)
    names = []
    for i in range(6):
        th, d, a, al = prm[4 * i], prm[4 * i + 1], prm[4 * i + 2], prm[4 * i + 3]
        names += [f"theta{i + 1}", f"d{i + 1}", f"a{i + 1}", f"alpha{i + 1}"]
        c, s = ca.cos(th + q[i]), ca.sin(th + q[i])
        ca_, sa = ca.cos(al), ca.sin(al)
        A = ca.vertcat(ca.horzcat(c, -s * ca_, s * sa, a * c), ca.horzcat(s, c * ca_, -c * sa, a * s),
                       ca.horzcat(0, sa, ca_, d), ca.horzcat(0, 0, 0, 1))
        T = T @ A
    names.append("probe_l")
    tip = T @ ca.vertcat(0, 0, prm[24], 1)
    p = tip[:3]
    return ca.Function("dh", [q, prm], [p, ca.jacobian(p, prm)]), names


def study_002(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="study calib-002")
    ap.add_argument("--poses", type=int, default=60)
    ap.add_argument("--noise-um", type=float, default=5.0)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    f, names = dh_probe_function()
    nominal = np.array([v for row in AACMM_DH for v in row] + [AACMM_PROBE_M])
    Q = rng.uniform(-np.pi, np.pi, size=(a.poses, 6))
    J = np.vstack([np.asarray(f(q, nominal)[1]) for q in Q])
    rep = em.identifiability(J, names, order=list(range(25)))
    print(f"\npaper 002: DH arm with probe, {len(names)} parameters: rank {rep.rank} "
          f"(paper: 23), redundant {len(names) - rep.rank} (paper: 2)")
    for k, v in rep.combined.items():
        print(f"  {k}: combined with " + ", ".join(f"{n} ({c:+.3g})" for n, c in v))
    for k in rep.unidentifiable:
        print(f"  {k}: no effect")
    print("  SVD null-space vectors: " + "; ".join(", ".join(f"{n} {c:+.2f}" for n, c in v) for v in rep.null_space))
    # Gauss-Newton on the identifiable set from the nominal parameters
    true = nominal + rng.normal(size=25) * 2e-4   # 0.2 mm / 0.2 mrad errors
    noise = a.noise_um * 1e-6

    def meas(Qs):
        return np.array([np.asarray(f(q, true)[0]).ravel() for q in Qs]) + noise * rng.standard_normal((len(Qs), 3))

    Y = meas(Q)
    cols = rep.identifiable
    prm = nominal.copy()
    Qv = rng.uniform(-np.pi, np.pi, size=(200, 6))
    Yv_true = np.array([np.asarray(f(q, true)[0]).ravel() for q in Qv])
    print("\n| Gauss-Newton step | RMS residual [µm] | RMS validation error [µm] |")
    print("|---|---|---|")
    hist = []
    for it in range(5):
        P = np.array([np.asarray(f(q, prm)[0]).ravel() for q in Q])
        Pv = np.array([np.asarray(f(q, prm)[0]).ravel() for q in Qv])
        r = (Y - P).ravel()
        rv = np.sqrt(np.mean(np.sum((Yv_true - Pv) ** 2, axis=1)))
        hist.append((it, float(np.sqrt(np.mean(r.reshape(-1, 3) ** 2) * 3)), float(rv)))
        print(f"| {it} | {1e6 * hist[-1][1]:.2f} | {1e6 * rv:.2f} |")
        Jc = np.vstack([np.asarray(f(q, prm)[1]) for q in Q])[:, cols]
        d, *_ = np.linalg.lstsq(Jc, r, rcond=None)
        prm[cols] += d
    print(f"(noise {a.noise_um} µm per axis: the residual after one step is at the noise level, "
          f"sqrt(3) sigma = {math.sqrt(3) * a.noise_um:.1f} µm)")
    _save("calib-002", {"args": vars(a), "rank": rep.rank, "n_parameters": 25, "combined": rep.as_dict()["combined"],
                        "gauss_newton": hist, "paper": {"rank": 23, "redundant": 2}})
    return 0


# ------------------------------------------------------------------------------------------------
# calib-003: UR10-like arm, DETMAX / BSAA x {O1, O2, O3, Oc}
# ------------------------------------------------------------------------------------------------
UR10_DH = [(0.1273, 0.0, np.pi / 2), (0.0, -0.612, 0.0), (0.0, -0.5723, 0.0), (0.163941, 0.0, np.pi / 2),
           (0.1157, 0.0, -np.pi / 2), (0.0922, 0.0, 0.0)]   # (d, a, alpha), standard DH


def ur10_arm():
    """A UR10-like pin.Model (standard DH converted to joint placements) with flange, tcp and
    reflector frames; returned as a minimal robot-like namespace for the measurement model."""
    model = pin.Model()
    model.name = "ur10_like"
    parent = 0
    prev = pin.SE3.Identity()
    for i, (d, a, al) in enumerate(UR10_DH):
        placement = prev * pin.SE3(np.eye(3), np.array([0.0, 0.0, d]))
        parent = model.addJoint(parent, pin.JointModelRZ(), placement, f"j{i + 1}")
        model.appendBodyToJoint(parent, pin.Inertia.FromSphere(1.0, 0.05), pin.SE3.Identity())
        prev = pin.SE3(np.eye(3), np.array([a, 0.0, 0.0])) * pin.SE3(pin.utils.rotate("x", al), np.zeros(3))
    model.lowerPositionLimit = -np.pi * np.ones(6)
    model.upperPositionLimit = np.pi * np.ones(6)
    fl = model.addFrame(pin.Frame("flange", parent, 0, prev, pin.FrameType.OP_FRAME))
    model.addFrame(pin.Frame("tcp", parent, fl, prev * pin.SE3(np.eye(3), np.array([0, 0, 0.1])),
                             pin.FrameType.OP_FRAME))
    model.addFrame(pin.Frame("reflector", parent, fl, prev * pin.SE3(np.eye(3), np.array([0.03, 0, 0.08])),
                             pin.FrameType.OP_FRAME))
    ns = SimpleNamespace(model=model, nq=6, frame_flange="flange", frame_tcp="tcp", frame_reflector="reflector",
                         limits=SimpleNamespace(lower_rad=model.lowerPositionLimit.copy(),
                                                upper_rad=model.upperPositionLimit.copy()))
    return ns


def _study_003_seed(args) -> dict:
    seed, pool, n_sel, n_val, err_mm, noise_mm = args
    from pipeline.robot.symbolic import SymbolicRobot

    with single_thread_blas():
        arm = ur10_arm()
        sym = SymbolicRobot(arm.model, flange_frame="flange", tool_frames=("tcp", "reflector"))
        mm = em.MeasurementModel(arm, sym)
        rng = np.random.default_rng([seed, 3])
        T0 = pin.SE3.Identity()
        Qi = em.random_configurations(arm, 200, rng)
        J = mm.jacobian(Qi, np.zeros(mm.n), T0)[1].reshape(-1, mm.n)
        rep = em.identifiability(J, mm.names)
        basis = em.parameter_basis(rep, mm.n)
        # truth: errors uniform in +-err (mm / mrad) on placements, offsets, reflector; tracker ~ base
        xt = np.zeros(mm.n)
        xt[mm.sl_kin] = rng.uniform(-err_mm, err_mm, mm.n_kin) * 1e-3
        xt[mm.sl_reflector] = rng.uniform(-err_mm, err_mm, 3) * 1e-3
        Tt = pin.SE3(pin.exp3(rng.normal(size=3) * 0.01), rng.normal(size=3) * 0.01)
        Qc = em.random_configurations(arm, pool, rng)
        Yc, Jc = mm.jacobian(Qc, np.zeros(mm.n), T0, basis)
        sig = noise_mm * 1e-3 / math.sqrt(3)   # uniform +-a has sigma a/sqrt(3)
        G = Jc / sig
        Ymeas = mm.predict(Qc, xt, Tt) + rng.uniform(-noise_mm, noise_mm, (pool, 3)) * 1e-3
        Qv = em.random_configurations(arm, n_val, rng)
        Yv = mm.predict(Qv, xt, Tt)

        def evaluate(sel: np.ndarray) -> dict:
            est = estimate(mm, Qc[sel], Ymeas[sel], np.full(len(sel), sig), basis)
            e = np.linalg.norm(mm.predict(Qv, est.x, est.registration) - Yv, axis=1)
            return {"mean": float(e.mean()), "rms": float(np.sqrt(np.mean(e ** 2))), "max": float(e.max())}

        out = {"seed": seed, "rank": rep.rank}
        out["none"] = evaluate(ds.random_design(G, ix.IndexSpec("O3"), n_sel, rng).selected)
        for alg in ("detmax", "bsaa"):
            for name in ("O1", "O2", "O3", "Oc"):
                # O1/O3 of the un-whitened Jacobian and Od in mm (the paper's units) inside Oc
                spec = ix.IndexSpec(name, oc_jacobian_scale=sig, oc_od_scale=1e-6)
                sel = ds.select(alg, G, spec, n_sel, rng, positions=Yc)
                out[f"{alg}_{name}"] = evaluate(sel.selected) | {"time_s": sel.run_time_s,
                                                                 "evaluations": sel.evaluations}
    return out


PAPER_003 = {"none": (0.485, 0.558, 1.078), "detmax_O1": (0.4131, 0.4807, 1.0966), "detmax_O2": (0.430, 0.491, 1.015),
             "detmax_O3": (0.421, 0.487, 1.196), "detmax_Oc": (0.399, 0.467, 1.201),
             "bsaa_O1": (0.388, 0.457, 1.113), "bsaa_O2": (0.399, 0.463, 1.133), "bsaa_O3": (0.382, 0.430, 0.832),
             "bsaa_Oc": (0.363, 0.411, 0.982)}


def study_003(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="study calib-003")
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(5)))
    ap.add_argument("--pool", type=int, default=300)
    ap.add_argument("--select", type=int, default=30)
    ap.add_argument("--validation", type=int, default=50)
    ap.add_argument("--error-mm", type=float, default=1.5, help="truth errors uniform in +- (mm, mrad)")
    ap.add_argument("--noise-mm", type=float, default=0.01, help="measurement noise uniform in +- (mm)")
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args(argv)
    rows = _parallel(_study_003_seed, [(s, a.pool, a.select, a.validation, a.error_mm, a.noise_mm) for s in a.seeds],
                     a.jobs)
    keys = ["none"] + [f"{alg}_{n}" for alg in ("detmax", "bsaa") for n in ("O1", "O2", "O3", "Oc")]
    print(f"\npaper 003 Table 2 (UR10-like arm, {a.select} of {a.pool} poses, {a.validation} validation poses, "
          f"mean over {len(rows)} seeds)")
    print("| method | mean [µm] | RMS [µm] | max [µm] | paper mean/RMS/max [mm] |")
    print("|---|---|---|---|---|")
    table = {}
    for k in keys:
        m = np.mean([r[k]["mean"] for r in rows])
        rms = np.mean([r[k]["rms"] for r in rows])
        mx = np.mean([r[k]["max"] for r in rows])
        table[k] = (m, rms, mx)
        pm = PAPER_003[k]
        print(f"| {k.replace('_', ' x ')} | {1e6 * m:.2f} | {1e6 * rms:.2f} | {1e6 * mx:.2f} | "
              f"{pm[0]} / {pm[1]} / {pm[2]} |")
    _save("calib-003", {"args": vars(a), "rows": rows, "table": table, "paper": PAPER_003})
    return 0

