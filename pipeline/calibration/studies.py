"""Paper studies of the calibration stage (``python -m pipeline study calib-004|calib-000|calib-002|calib-003``).

Each study prints a table beside the paper's numbers and writes ``data/studies/<name>/result.json``.
Runs over seeds / arms are parallel with joblib (``--jobs``, default 1 on the shared machine).

- calib-004 (papers/004 §3.4): 32 configurations from the joint grid by remove-and-replace on O3
  against a linear scan with the same number of poses (paper: index better by a factor 18.5);
  held-out errors before/after calibration (paper Table 2 layout).
- calib-000 (papers/000 §3.3, Tables 6-8): 60 configurations; average TCP variance at one working
  configuration for random (heuristic) vs parameter-covariance OED vs TCP-covariance OED
  (remove-and-replace warm start + IPOPT with collision constraints), over arms whose link 2 and
  link 4 lengths vary (paper: 90 notional arms; TCP criterion 40-44 % better than heuristic and
  10-19 % better than the parameter criterion).
- calib-002 and calib-003: :mod:`pipeline.calibration.paper_002`, :mod:`pipeline.calibration.paper_003`.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
import pinocchio as pin

from pipeline.blas import single_thread_blas
from pipeline.calibration import candidates as cd
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
# calib-000
# ------------------------------------------------------------------------------------------------
def scaled_arm(robot, f2: float, f4: float):
    """A notional arm: link 2 (joint 2 -> 3) and link 4 (joint 3 -> 4 offset) lengths scaled,
    capsules scaled with them (paper 000 §3.3: 90 arms with varied link lengths)."""
    model = robot.model.copy()
    spec = __import__("copy").deepcopy(robot.spec)
    for j, f in ((3, f2), (4, f4)):
        M = model.jointPlacements[j]
        model.jointPlacements[j] = pin.SE3(M.rotation, M.translation * f)
    for c in spec.capsules:
        jid = model.frames[model.getFrameId(c.frame)].parentJoint
        if jid == 2:   # upper arm spans joint 2 -> 3
            c.p0, c.p1 = np.asarray(c.p0) * f2, np.asarray(c.p1) * f2
        if jid == 4:   # forearm spans joint 4 -> wrist (joint 4 -> 5 offset is along its axis)
            c.p0, c.p1 = np.asarray(c.p0) * f4, np.asarray(c.p1) * f4
    return robot.with_model(model, spec)


def _study_000_arm(args) -> dict:
    robot_name, f2, f4, seed, n, n_cand, iters = args
    from pipeline.calibration.gradient_design import GradientDesignConfig, gradient_design
    from pipeline.robot.model import RobotModel

    with single_thread_blas():
        robot = scaled_arm(RobotModel.load(robot_name), f2, f4)
        rng = np.random.default_rng([seed, int(f2 * 1000), int(f4 * 1000)])
        mm = em.MeasurementModel(robot)
        cfg = st.Config(candidates="random", n_random_candidates=n_cand)
        rep, basis = st.identify_parameter_set(robot, mm, cfg, rng)
        cs = st.build_candidates(robot, cfg, basis, rng)
        chain = cd.chain_from_robot(robot)
        Qw, _ = cd.random_candidates(chain, 1, rng, visibility=False)
        Jw = st.working_jacobian(robot, mm, Qw, basis)
        tcp = ix.IndexSpec("tcp_A", working_jacobian=Jw, n_working=1)
        # parameter criterion on the robot's own geometric parameters (paper 000 eq. 25, P onto p)
        robot_rows = np.array([not n.startswith(("tracker.", "reflector.")) for n in rep.identifiable_names], float)
        par = ix.IndexSpec("A", parameter_weights=robot_rows)

        def tcp_var(Q: np.ndarray) -> float:
            G = cd.build_candidate_set(chain, Q, basis, robot.tracker.transform_tracker_to_base).G
            M = np.einsum("kmi,kmj->ij", G, G)
            return ix.evaluate(tcp, M, len(Q)) / 3.0  # mean variance per TCP coordinate

        out = {"f2": f2, "f4": f4, "n_candidates": len(cs)}
        rnd = ds.random_design(cs.G, tcp, n, rng)
        out["random"] = tcp_var(cs.Q[rnd.selected])
        gcfg = GradientDesignConfig(max_iterations=iters)
        for key, spec in (("parameter_oed", par), ("tcp_oed", tcp)):
            t0 = time.perf_counter()
            sel = ds.remove_and_replace(cs.G, spec, n, rng, n_initial=n)
            out[key + "_discrete"] = tcp_var(cs.Q[sel.selected])
            g = gradient_design(robot, mm, basis, cs.Q[sel.selected], spec, gcfg)
            out[key] = tcp_var(g.Q)
            out[key + "_time_s"] = time.perf_counter() - t0
            out[key + "_gradient_time_s"] = g.run_time_s
            out[key + "_reverted"] = g.reverted
    return out


def study_000(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="study calib-000")
    ap.add_argument("--robot", default="rx130l")
    ap.add_argument("--arms", type=int, default=20, help="number of notional arms (paper: 90)")
    ap.add_argument("--n", type=int, default=60)
    ap.add_argument("--candidates", type=int, default=1500)
    ap.add_argument("--iterations", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args(argv)
    k2 = int(math.ceil(math.sqrt(a.arms)))
    k4 = int(math.ceil(a.arms / k2))
    f2s = np.linspace(0.8, 1.2, k2)
    f4s = np.linspace(0.8, 1.2, k4)
    arms = [(a.robot, float(f2), float(f4), a.seed, a.n, a.candidates, a.iterations)
            for f2 in f2s for f4 in f4s][: a.arms]
    rows = _parallel(_study_000_arm, arms, a.jobs)
    print(f"\npaper 000: {a.n} configurations, mean TCP variance at one working configuration, "
          f"{len(rows)} arms (link 2 x {f2s.min():.2f}..{f2s.max():.2f}, link 4 x {f4s.min():.2f}..{f4s.max():.2f})")
    print("| link2 | link4 | random [µm²] | param. OED [µm²] | TCP OED [µm²] | TCP vs random | TCP vs param. |")
    print("|---|---|---|---|---|---|---|")
    imp_r, imp_p = [], []
    for r in rows:
        ir = 1 - r["tcp_oed"] / r["random"]
        ip = 1 - r["tcp_oed"] / r["parameter_oed"]
        imp_r.append(ir)
        imp_p.append(ip)
        print(f"| {r['f2']:.2f} | {r['f4']:.2f} | {1e12 * r['random']:.2f} | {1e12 * r['parameter_oed']:.2f} | "
              f"{1e12 * r['tcp_oed']:.2f} | {100 * ir:.0f} % | {100 * ip:.0f} % |")
    print(f"\nmean improvement of the TCP criterion: {100 * np.mean(imp_r):.0f} % vs random (paper 40-44 %), "
          f"{100 * np.mean(imp_p):.0f} % vs parameter criterion (paper 10-19 %)")
    grad_t = [r["tcp_oed_gradient_time_s"] for r in rows]
    print(f"gradient design time (TCP OED, {a.n} configurations, collision constraints): "
          f"median {np.median(grad_t):.1f} s, max {np.max(grad_t):.1f} s")
    _save("calib-000", {"args": vars(a), "rows": rows, "mean_improvement_vs_random": float(np.mean(imp_r)),
                        "mean_improvement_vs_parameter": float(np.mean(imp_p)),
                        "paper": {"vs_random": [0.40, 0.44], "vs_parameter": [0.10, 0.19]}})
    return 0
