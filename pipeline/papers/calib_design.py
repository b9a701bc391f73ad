"""Study ``calib-design``: which index x selector gives the most accurate TCP where the arm works.

``python -m pipeline study calib-design [--robots rx130l staubli_tx40] [--seeds 0 .. 9] [--quick]``

Per robot the candidate set (the filtered joint grid, ``--grid``; ``--quick``: random candidates)
and the working region (the robot's ISO 9283 cube, :func:`pipeline.calibration.task_space.default_region`)
are built once from the nominal model; the designs are computed once per robot (they depend only on
the nominal model and the selector's random start) and evaluated on every seed's hidden robot
(the rigid, ideal hidden robot ``TruthConfig.ideal()``: the study designs for the geometric error
model, and on the elastic truth the unmodelled gravity deflection, ~2 mm after a geometric fit of the
RX130L, would bury every design's estimation error of ~10-20 µm):

1. measure the design's configurations with the simulated tracker (noise), calibrate
   (registration + Levenberg-Marquardt on the identifiable parameters);
2. *actual* error: the calibrated model's reflector position error at the working configurations
   of the region against the hidden robot, **noise-free** (this study, like a test, reads the
   hidden robot after the fit; stage code never does); *predicted*: its covariance prediction
   ``sqrt(mean trace(J_k C J_k^T))`` at the same configurations (paper 000 eq. 16).

Tables: every index (O1-O5, D, A, E, Od, Oc, tcp_A = paper 000's KPI at ``--kpi-poses`` working
configurations, V = the task-space criterion on the TCP, V_refl on the reflector, V_tcp_refl on
both) with the stage's remove-and-replace (:func:`pipeline.calibration.design_rounding.approximate_remove_and_replace`:
the rounded optimal approximate design as a second start on the trace indices) at ``--n``
configurations, plus the baselines every (N/n)-th candidate and random; the selectors
(remove-and-replace, DETMAX, BSAA) on V and O3; the measurement-effort curve (``--curve`` sizes) of
the three V figures, every-(N/n)-th and O3. It prints the winner, the per-seed gains of V over the
baselines, and the fewest configurations with which each V figure reaches the baselines' RMS at
``--n``.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import design_bound as db
from pipeline.calibration import design_rounding as dr
from pipeline.calibration import error_model as em
from pipeline.calibration import indices as ix
from pipeline.calibration import measure as ms
from pipeline.calibration import stage as st
from pipeline.calibration import task_space as ts
from pipeline.calibration.estimate import calibrated_robot, estimate, register_points
from pipeline.core.blas import single_thread_blas
from pipeline.papers.calib_common import run_parallel, save_result
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot, TruthConfig

INDICES = ("O1", "O2", "O3", "O4", "O5", "D", "A", "E", "Od", "Oc", "tcp_A", "V", "V_refl", "V_tcp_refl")
#: the V criterion on other figures of the working region (study only): the reflector in the tracker
#: frame (the held-out figure) and TCP + reflector, ``W = (W_tcp + W_reflector) / 2``
CURVE_INDICES = ("V", "V_refl", "V_tcp_refl", "O3")
SELECTORS = ("remove_and_replace", "detmax", "bsaa")
BASELINES = ("every_kth", "random")


def _spec(name: str, robot: RobotModel, mm, basis, Qw, sigma_m: float, kpi_Q) -> ix.IndexSpec:
    if name == "V":
        return ts.task_space_spec(mm, Qw, basis)
    if name == "V_refl":
        return ix.IndexSpec("V", working_jacobian=db.reflector_jacobian(robot, Qw, basis), n_working=len(Qw))
    if name == "V_tcp_refl":
        J = np.vstack([ts.tcp_jacobian(mm, Qw, basis), db.reflector_jacobian(robot, Qw, basis)])
        return ix.IndexSpec("V", working_jacobian=J, n_working=2 * len(Qw))
    if name == "tcp_A":
        return ix.IndexSpec("tcp_A", working_jacobian=ts.tcp_jacobian(mm, kpi_Q, basis), n_working=len(kpi_Q))
    # Oc: O1/O3 of the un-whitened Jacobian and Od in mm (paper 003's units), as study calib-003
    return ix.IndexSpec(name, oc_jacobian_scale=sigma_m, oc_od_scale=1e-6)


@dataclass
class StudyPool:
    """What every design of the study for one robot is built from (nominal model only)."""

    robot: RobotModel
    mm: em.MeasurementModel
    basis: np.ndarray               # identifiable parameter basis (n_full, p)
    cs: cd.CandidateSet             # candidates with whitened Jacobian blocks
    region: ts.WorkingRegion
    Qw: np.ndarray                  # working configurations of the region
    rng: np.random.Generator        # the study's stream, to be used on by the selectors


def study_pool(robot_name: str, n: int, quick: bool, grid: int, n_cand: int, n_region: int) -> StudyPool:
    """Parameter set, candidates and working configurations of the study for ``n`` configurations
    (the stream ``default_rng([7, n])``: the same pool in the study and in benchmarks that reuse it)."""
    robot = RobotModel.load(robot_name)
    rng = np.random.default_rng([7, n])
    mm = em.MeasurementModel(robot)
    cfg = st.Config(candidates="random" if quick else "grid", grid_per_axis=grid, n_random_candidates=n_cand)
    _, basis = st.identify_parameter_set(robot, mm, cfg, rng)
    cs = st.build_candidates(robot, cfg, basis, rng)
    region = ts.default_region(robot)
    Qw = ts.sample_region(robot, region, n_region, rng)
    return StudyPool(robot, mm, basis, cs, region, Qw, rng)


def robot_designs(robot_name: str, n: int, curve: list[int], quick: bool, grid: int, n_cand: int,
                  n_region: int, kpi_poses: int, selectors: bool) -> dict:
    """Every design of the study for one robot: ``{key: (method, index, n, Q)}`` plus the region."""
    pool = study_pool(robot_name, n, quick, grid, n_cand, n_region)
    robot, mm, basis, cs, region, Qw, rng = pool.robot, pool.mm, pool.basis, pool.cs, pool.region, pool.Qw, pool.rng
    kpi_Q = Qw[rng.choice(len(Qw), size=min(kpi_poses, len(Qw)), replace=False)]
    sigma = float(np.median(cs.sigma_m))
    specs = {name: _spec(name, robot, mm, basis, Qw, sigma, kpi_Q) for name in INDICES}
    n_min = ms.min_configurations(basis.shape[1])
    designs: dict[str, dict] = {}

    def add(key: str, method: str, index: str, size: int, sel: np.ndarray, t: float) -> None:
        designs[key] = {"method": method, "index": index, "n": int(size), "Q": cs.Q[sel], "time_s": t}

    with single_thread_blas():
        for size in sorted({n, *[c for c in curve if c >= n_min + 1]}):
            names = INDICES if size == n else CURVE_INDICES
            for name in names:
                t = time.perf_counter()     # the stage's default selector (approximate start on trace indices)
                r = dr.approximate_remove_and_replace(cs.G, specs[name], size, rng, positions=cs.Y)
                add(f"remove_and_replace/{name}/{size}", "remove_and_replace", name, size, r.selected,
                    time.perf_counter() - t)
            kth = ds.linear_scan_design(cs.G, specs["O3"], size).selected
            add(f"every_kth/-/{size}", "every_kth", "-", size, kth, 0)
            add(f"random/-/{size}", "random", "-", size, ds.random_design(cs.G, specs["O3"], size, rng).selected, 0)
        if selectors:
            for method in ("detmax", "bsaa"):
                for name in ("V", "O3"):
                    t = time.perf_counter()
                    r = ds.select(method, cs.G, specs[name], n, rng, positions=cs.Y)
                    add(f"{method}/{name}/{n}", method, name, n, r.selected, time.perf_counter() - t)
    return {"robot": robot_name, "designs": designs, "Qw": Qw, "basis": basis, "region": region.describe(),
            "n_candidates": len(cs), "n_min": n_min}


def evaluate_seed(robot_name: str, seed: int, bundle: dict) -> dict:
    """Actual (noise-free) and predicted RMS over the working configurations for every design."""
    robot = RobotModel.load(robot_name)
    real = RealRobot.create(robot, seed, TruthConfig.ideal())    # the geometric model's robot
    mm = em.MeasurementModel(robot)
    rng = np.random.default_rng([seed, 15])
    Qw, basis = bundle["Qw"], bundle["basis"]
    # noise-free tracker-frame reflector positions of the hidden robot (study only, after the fits)
    T = real.transform_tracker_to_base
    Yw = (real.truth.positions(Qw, robot.frame_reflector) - T.translation) @ T.rotation
    p_true = real.truth.positions(Qw, robot.frame_tcp)
    spec_v = ts.task_space_spec(mm, Qw, basis)
    out = {}
    with single_thread_blas():
        for key, d in bundle["designs"].items():
            meas = ms.measure_simulated(real, d["Q"], rng)
            est = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis)
            e = np.linalg.norm(Yw - mm.predict(Qw, est.x, est.registration), axis=1)
            _, J = mm.jacobian(Qw, est.x, est.registration, est.basis)
            var = np.einsum("nip,pq,niq->n", J, est.covariance, J)
            # TCP of the calibrated model against the hidden robot's, after the best rigid alignment
            # over the region (the base/tracker frame is a gauge no calibration fixes)
            p_cal = calibrated_robot(robot, mm, est.x).positions(Qw, robot.frame_tcp)
            T_al = register_points(p_cal, p_true)
            e_tcp = np.linalg.norm(p_cal @ T_al.rotation.T + T_al.translation - p_true, axis=1)
            out[key] = {"actual_rms_m": float(np.sqrt(np.mean(e ** 2))),
                        "predicted_rms_m": float(np.sqrt(np.mean(var))), "n_measured": int(len(meas)),
                        "tcp_aligned_rms_m": float(np.sqrt(np.mean(e_tcp ** 2))),
                        "tcp_predicted_rms_m": float(np.sqrt(np.trace(spec_v.weight_matrix(len(est.theta))
                                                                        @ est.covariance)))}
    return out


def _mean(rows: list[dict], key: str, field: str = "actual_rms_m") -> float:
    return float(np.mean([r[key][field] for r in rows]))


def report(robot_name: str, bundle: dict, rows: list[dict], n: int, curve: list[int]) -> dict:
    """Print the robot's tables and return the headline figures."""
    d = bundle["designs"]
    print(f"\n## {robot_name}: {bundle['n_candidates']} candidates, working region {bundle['region']}, "
          f"{len(rows)} seeds (RMS over the working configurations, noise-free, µm: mean [min..max])")
    print("| design | configurations | actual RMS | predicted RMS | predicted/actual | selection time [s] |")
    print("|---|---|---|---|---|---|")
    keys = sorted((k for k in d if d[k]["n"] == n), key=lambda k: _mean(rows, k))
    for k in keys:
        a = np.array([r[k]["actual_rms_m"] for r in rows])
        p = np.array([r[k]["predicted_rms_m"] for r in rows])
        print(f"| {k} | {n} | {1e6 * a.mean():.1f} [{1e6 * a.min():.1f}..{1e6 * a.max():.1f}] | "
              f"{1e6 * p.mean():.1f} | {np.mean(p / a):.2f} | {d[k]['time_s']:.1f} |")
    print("\nTCP of the calibrated model vs the hidden robot over the region, after the best rigid alignment "
          "(µm; predicted = sqrt(trace(W C)), the V criterion's figure)")
    print("| design | aligned TCP RMS | predicted TCP RMS |")
    print("|---|---|---|")
    for k in sorted(keys, key=lambda k: _mean(rows, k, "tcp_aligned_rms_m")):
        print(f"| {k} | {1e6 * _mean(rows, k, 'tcp_aligned_rms_m'):.1f} | "
              f"{1e6 * _mean(rows, k, 'tcp_predicted_rms_m'):.1f} |")
    heads = {}
    for field, pred, what in (("actual_rms_m", "predicted_rms_m", "reflector in the tracker frame"),
                              ("tcp_aligned_rms_m", "tcp_predicted_rms_m", "TCP after rigid alignment")):
        print(f"\n### {what}")
        heads[field] = _headline(rows, d, n, field, pred)
    return {"headlines": heads,
            "table": {k: {f: _mean(rows, k, f) for f in ("actual_rms_m", "predicted_rms_m", "tcp_aligned_rms_m",
                                                          "tcp_predicted_rms_m")} for k in d}}


def _headline(rows: list[dict], d: dict, n: int, field: str, pred: str) -> dict:
    """Winner, per-seed gains of V, predicted/actual and the effort curve on one error measure."""
    keys = sorted((k for k in d if d[k]["n"] == n), key=lambda k: _mean(rows, k, field))
    win = keys[0]
    v_key, kth, o3 = f"remove_and_replace/V/{n}", f"every_kth/-/{n}", f"remove_and_replace/O3/{n}"
    gain_kth = [1 - r[v_key][field] / r[kth][field] for r in rows]
    gain_o3 = [1 - r[v_key][field] / r[o3][field] for r in rows]
    ratio = [r[v_key][pred] / r[v_key][field] for r in rows]
    print(f"winner at {n} configurations: {win} ({1e6 * _mean(rows, win, field):.1f} µm)")
    print("V (remove-and-replace) vs every (N/n)-th, per seed gain: " + ", ".join(f"{100 * g:.0f} %" for g in gain_kth))
    print("V (remove-and-replace) vs O3 remove-and-replace, per seed gain: "
          + ", ".join(f"{100 * g:.0f} %" for g in gain_o3))
    print(f"V predicted/actual per seed: {', '.join(f'{x:.2f}' for x in ratio)} (mean of the RMS: "
          f"{_mean(rows, v_key, pred) / _mean(rows, v_key, field):.2f})")
    print("measurement-effort curve (mean RMS, µm)")
    sizes = sorted({d[k]["n"] for k in d})
    print("| configurations | " + " | ".join(str(s) for s in sizes) + " |")
    print("|---|" + "---|" * len(sizes))
    curves = {}
    for label, pat in (("V remove-and-replace", "remove_and_replace/V/{}"),
                       ("V on the reflector", "remove_and_replace/V_refl/{}"),
                       ("V on TCP + reflector", "remove_and_replace/V_tcp_refl/{}"),
                       ("O3 remove-and-replace", "remove_and_replace/O3/{}"), ("every (N/n)-th", "every_kth/-/{}"),
                       ("random", "random/-/{}")):
        vals = [(_mean(rows, pat.format(s), field) if pat.format(s) in d else math.nan) for s in sizes]
        curves[label] = dict(zip(sizes, vals, strict=True))
        print(f"| {label} | " + " | ".join(f"{1e6 * v:.1f}" for v in vals) + " |")
    effort = {}
    for crit in ("V remove-and-replace", "V on the reflector", "V on TCP + reflector"):
        for base, label in ((kth, "every (N/n)-th"), (o3, "O3 remove-and-replace")):
            target = _mean(rows, base, field)
            reach = [s for s in sizes if curves[crit][s] <= target]
            effort[label if crit.startswith("V remove") else f"{crit}: {label}"] = (min(reach) / n) if reach else None
            print(f"{crit} reaches the {label} RMS at {n} ({1e6 * target:.1f} µm) with "
                  + (f"{min(reach)} configurations ({100 * min(reach) / n:.0f} % of the measurements)" if reach
                     else "none of the sizes tried"))
    return {"winner": win, "gain_vs_every_kth": gain_kth, "gain_vs_O3": gain_o3, "predicted_over_actual": ratio,
            "curves": curves, "effort_fraction": effort}


def study_design(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="study calib-design")
    ap.add_argument("--robots", nargs="+", default=["rx130l", "staubli_tx40"])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    ap.add_argument("--n", type=int, default=32)
    ap.add_argument("--curve", type=int, nargs="+", default=[12, 16, 20, 24, 32, 40, 48, 60])
    ap.add_argument("--grid", type=int, default=13)
    ap.add_argument("--quick", action="store_true", help="random candidates instead of the grid, no DETMAX/BSAA")
    ap.add_argument("--candidates", type=int, default=1500, help="random candidates (--quick)")
    ap.add_argument("--region-poses", type=int, default=300)
    ap.add_argument("--kpi-poses", type=int, default=5, help="working configurations of paper 000's KPI (tcp_A)")
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args(argv)
    result = {"args": vars(a), "robots": {}}
    for name in a.robots:
        bundle = robot_designs(name, a.n, a.curve, a.quick, a.grid, a.candidates, a.region_poses, a.kpi_poses,
                               not a.quick)
        rows = run_parallel(lambda s, b=bundle, rn=name: evaluate_seed(rn, s, b), a.seeds, a.jobs)
        result["robots"][name] = report(name, bundle, rows, a.n, a.curve) | {"rows": rows}
    save_result("calib-design", result)
    return 0
