"""Paper studies of the calibration stage (``python -m pipeline study calib-004|calib-000|calib-002|calib-003``).

Each study prints a table beside the paper's numbers and writes ``data/studies/<name>/result.json``.
Runs over seeds / arms are parallel with joblib (``--jobs``, default 1 on the shared machine).

- calib-004: moved to :mod:`pipeline.calibration.paper_004` (``_calibrate_with`` below stays shared).
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
