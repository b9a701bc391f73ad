"""Study ``calib-004``: paper 004 §3 (optimal calibration configurations), with its optical 6-D tracker.

What the paper did (papers/004_abbe750b8bbcc3aa.txt §3.3-3.4): the joint space of the Stäubli RX130L
discretised by 13 values per axis (13^6 ~ 4.8e6 configurations); the configurations the optical
tracker 3D-Creator (4 infrared diodes on the end effector, three CCD cameras, position and
orientation by stereovision) cannot see removed, leaving about 4000; 32 configurations chosen by
remove-and-replace (steps 1-4) on the observation index ``B = sigma_min(Lambda)``, ``Lambda =
Theta^T Theta`` (§3.3.1: "the minimum singular value of the covariance matrix Lambda"), i.e.
``B = O3^2`` with O3 the smallest singular value of the (whitened) identification Jacobian Theta;
"compared to a linear scan of the workspace, the observation index is reduced by the factor 18.5";
Table 2: maximum and peak-to-peak position (mm) and orientation (Cardan angles, deg) errors before
and after calibration.

What this study does, per seed of the hidden robot:

1. the 13^6 grid filtered by limits, collisions and the optical tracker's predicted visibility
   (``optical_tracker`` of robot.yaml, :mod:`pipeline.sim.optical_tracker`; nominal model and
   camera pose, no margin: the count next to the paper's ~4000); the camera pose registered from 8
   pilot readings of that set on the hidden robot (:func:`pipeline.papers.calib_004_optical.register_camera`),
   and the candidates = the configurations still visible at the registered pose with
   :class:`~pipeline.robot.instruments.OpticalMargins` (a configuration the hidden robot might
   hide is never a candidate; those it hides anyway are counted as lost);
2. 6-D design blocks (:mod:`pipeline.papers.calib_004_optical`); 32 configurations by remove-and-replace
   on O3 (= on B: same order); the paper's index ``B = O3^2`` and ``cond(Lambda)`` of every design;
3. the baselines, each a literal reading of "a linear scan of the workspace"
   (:mod:`pipeline.papers.calib_004_scans`): every (N/n)-th visible grid configuration in grid
   order; 32 equally spaced poses on the joint-space diagonal (only the visible ones measured); 32
   equally spaced among the visible points of that diagonal; each joint swept in turn; a Cartesian
   raster traversed line by line with the probe facing the cameras; plus a random visible subset.
   The factor ``B_R&R / B_baseline`` of each is printed next to the paper's 18.5;
4. every design measured on the hidden robot (poses it cannot see are lost, and counted), calibrated
   from its 6-D readings, and validated on held-out poses in the Table 2 layout (position and Cardan
   angles, maximum and half peak-to-peak, before/after);
5. experiments on why the O3 design calibrates no better than a baseline: the covariance-predicted
   error of each design next to the measured one, remove-and-replace on other criteria
   (``--criteria D A``), the same designs on the ideal (rigid, no gear error) hidden robot
   (``--truth ideal``), and the laser-tracker set-up of the study's earlier version
   (:mod:`pipeline.papers.calib_004_laser`, ``--laser-grid``).

Run time (``python -m pipeline study calib-004 --jobs 1``, defaults: seeds 1 2 3, 13^6 grid, 300
held-out poses, criteria O3 D A, both truths, laser experiment on the 9^6 grid): 1011 s measured on
the shared 2-core machine with other jobs running (the grid filter alone about 90 s); results in
docs/papers/paper_004_calibration.md. The quick variant is tests/papers/test_calib_004.py.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pinocchio as pin

from pipeline.calibration import design as ds
from pipeline.calibration import error_model as em
from pipeline.calibration import indices as ix
from pipeline.calibration import stage as st
from pipeline.core.blas import single_thread_blas
from pipeline.core.errors import SolverError
from pipeline.papers import calib_004_laser as lz
from pipeline.papers import calib_004_optical as op
from pipeline.papers import calib_004_scans as sd
from pipeline.papers.calib_common import run_parallel, save_result
from pipeline.robot.instruments import OpticalMargins, optical_spec
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot, TruthConfig

PAPER = {"grid": 13, "visible": 4000, "n": 32, "factor": 18.5,
         # Table 2: maximum uncal./cal. and half peak-to-peak uncal./cal.; mm and deg
         "table2": {"x": (7.779, 0.272, 6.171, 0.271), "y": (19.026, 0.310, 4.267, 0.303),
                    "z": (12.614, 0.414, 1.402, 0.376), "alpha": (1.140, 0.128, 0.272, 0.109),
                    "beta": (1.817, 0.191, 0.335, 0.182), "gamma": (1.160, 0.131, 0.514, 0.116)}}
BASELINES = ("grid_order", "joint_line", "joint_line_visible", "joint_sweeps", "joint_sweeps_visible",
             "cartesian_raster", "cartesian_raster_tilted", "random")
#: tilts of the probe cycled over the raster points (deviation ``cartesian_raster_tilted``)
RASTER_TILT_RAD = np.radians(20.0)
READINGS = {
    "grid_order": "every (N/n)-th visible grid configuration in grid order (axis 1 slowest)",
    "joint_line": "n equally spaced poses on the joint-space diagonal lower->upper (visible ones measured)",
    "joint_line_visible": "n equally spaced among the visible points of the densely sampled joint-space diagonal",
    "joint_sweeps": "each joint swept through its range in turn, others at a visible home pose",
    "joint_sweeps_visible": "each joint swept in turn, n/6 poses equally spaced among the visible ones of its sweep",
    "cartesian_raster": "4x4x2 raster of the visible workspace box, line by line, probe facing the cameras",
    "cartesian_raster_tilted": "the same raster, the probe tilted by 20 deg about flange x/y in a 4-cycle (deviation)",
    "random": "a random subset of the visible grid (not a scan; reference)",
}
#: experiment ``--whole-grid``: every candidate of the visible grid measured (the paper's ~4000 poses)
WHOLE_GRID = "whole_grid"
READINGS[WHOLE_GRID] = "every visible grid configuration measured (--whole-grid; B grows with the poses)"


def load_robot(robot_name: str, probe_scale: float = 1.0) -> RobotModel:
    """The nominal robot, its optical probe's diode layout scaled by ``probe_scale`` about the marker
    origin (experiment ``--probe-scale``: the orientation noise of a Kabsch fit falls as 1 / probe size
    while the position noise, the mean of the diodes' noise, stays)."""
    robot = RobotModel.load(robot_name)
    spec = robot.spec.optical_tracker
    if spec is not None and probe_scale != 1.0:
        spec.probe_diodes_m = spec.probe_diodes_m * probe_scale
    return robot


def information(G: np.ndarray) -> np.ndarray:
    return np.einsum("kmi,kmj->ij", G, G)


def index_figures(M: np.ndarray) -> dict:
    """``B = lambda_min(Lambda) = O3^2``, ``O3``, ``cond(Lambda)`` and the rank of ``Lambda``."""
    ev = np.linalg.eigvalsh(M)
    rank = int(np.sum(ev > 1e-10 * ev[-1]))
    B = float(max(ev[0], 0.0)) if rank == len(ev) else 0.0
    return {"B": B, "O3": float(np.sqrt(B)), "cond": float(ev[-1] / B) if B > 0 else float("inf"), "rank": rank,
            "p": len(ev)}


def visible_grid(robot_name: str, grid: int, margins: OpticalMargins, probe_scale: float = 1.0) -> dict:
    """The grid the nominal cameras see (no margin; computed once for every seed) and how many of it
    stay visible with the margins at the nominal camera pose."""
    robot = load_robot(robot_name, probe_scale)
    t0 = time.perf_counter()
    Q, flat, counts = op.visible_grid(robot, grid)
    keep = op.visible_mask(robot, Q, margins=margins)
    return {"Q": Q, "flat": flat, "counts": counts, "n_visible": len(Q), "n_candidates_nominal": int(keep.sum()),
            "time_s": time.perf_counter() - t0}


def baseline_configurations(robot: RobotModel, Qc: np.ndarray, n: int, visible, camera: pin.SE3
                            ) -> dict[str, np.ndarray]:
    """Commanded configurations of the literal scan readings (module docstring, step 3)."""
    spec = optical_spec(robot)
    o_fl, _ = robot.poses(Qc, robot.frame_flange)
    lo, hi = np.percentile(o_fl, 10, axis=0), np.percentile(o_fl, 90, axis=0)
    centre = 0.5 * (lo + hi)
    home = Qc[int(np.argmin(np.linalg.norm(o_fl - centre, axis=1)))]
    towards = camera.translation - centre
    R = sd.facing_rotation(spec.diode_axis, towards)
    raster, _ = sd.cartesian_raster(robot, lo, hi, (4, 4, 2), R, home)
    t = RASTER_TILT_RAD
    tilted, _ = sd.cartesian_raster(robot, lo, hi, (4, 4, 2), R, home,
                                    np.array([[t, 0, 0], [0, t, 0], [-t, 0, 0], [0, -t, 0]]))
    return {"joint_line": sd.joint_line(robot, n), "joint_line_visible": sd.joint_line_visible(robot, n, visible),
            "joint_sweeps": sd.joint_sweeps(robot, home, n),
            "joint_sweeps_visible": sd.joint_sweeps_visible(robot, home, n, visible),
            "cartesian_raster": raster, "cartesian_raster_tilted": tilted}


def _seed(args: tuple) -> dict:
    (robot_name, seed, truth_name, grid_data, n, n_heldout, criteria, margins, camera, compliance_scale,
     n_initial, probe_scale, whole_grid) = args
    with single_thread_blas():
        robot = load_robot(robot_name, probe_scale)
        truth = (TruthConfig.ideal() if truth_name == "ideal"
                 else TruthConfig(joint_compliance_scale=compliance_scale))
        real = RealRobot.create(robot, seed, truth)
        rng = np.random.default_rng([seed, 4])
        mm = em.MeasurementModel(robot, marker_points=True)
        _, basis = st.identify_parameter_set(robot, mm, st.Config(), rng)
        # the camera pose registered from pilot readings decides what the design may use (step 1)
        T_cam, n_pilot = (op.register_camera(robot, real, grid_data["Q"], rng) if camera == "registered"
                          else (optical_spec(robot).transform_camera_to_base, 0))
        keep = op.visible_mask(robot, grid_data["Q"], T_cam, margins)
        Qc = grid_data["Q"][keep]
        _, sig_rad = op.nominal_sigmas(robot, Qc, T_cam)
        sigma_rad = float(np.median(sig_rad))

        def blocks(Q: np.ndarray) -> np.ndarray:
            return op.design_blocks(mm, robot, Q, basis, T_cam, sigma_rad)

        def visible(Q: np.ndarray) -> np.ndarray:
            return op.visible_mask(robot, Q, T_cam, margins)

        G = blocks(Qc)
        designs: dict[str, np.ndarray] = {}
        run_time: dict[str, float] = {}
        for name in criteria:
            sel = ds.remove_and_replace(G, ix.IndexSpec(name), n, rng, n_initial=n_initial or n)
            designs[f"rr_{name}"] = Qc[sel.selected]
            run_time[f"rr_{name}"] = sel.run_time_s
        designs["grid_order"] = Qc[ds.linear_scan_design(G, ix.IndexSpec("O3"), n).selected]
        designs["random"] = Qc[ds.random_design(G, ix.IndexSpec("O3"), n, rng).selected]
        designs |= baseline_configurations(robot, Qc, n, visible, T_cam)
        if whole_grid:
            designs[WHOLE_GRID] = Qc
        held = op.heldout(robot, real, T_cam, n_heldout, rng)
        rows = {}
        for name, Q in designs.items():
            vis = visible(Q) if len(Q) else np.zeros(0, bool)
            fig = index_figures(information(blocks(Q[vis]))) if vis.any() else \
                {"B": 0.0, "O3": 0.0, "cond": float("inf"), "rank": 0, "p": basis.shape[1]}
            row = {"commanded": len(Q), "predicted_visible": int(vis.sum()), **fig,
                   "B_per_pose": fig["B"] / max(int(vis.sum()), 1)}
            meas, s_rad = op.measure_optical(real, Q[vis], rng)
            row["lost_on_hidden_robot"] = int(vis.sum()) - len(meas)
            row["calibrated"] = False
            if 6 * len(meas) >= basis.shape[1]:
                try:
                    est = op.calibrate_6d(mm, meas, s_rad, basis)
                except SolverError as exc:
                    row["calibration_error"] = str(exc)
                else:
                    row["calibrated"] = True
                    row["before"] = op.pose_errors(mm, np.zeros(mm.n), est.registration, held).table()
                    row["after"] = op.pose_errors(mm, est.x, est.transform_tracker_to_base, held).table()
                    _, J = mm.jacobian(held.Q, est.x, est.transform_tracker_to_base, est.basis)
                    var = np.einsum("nip,pq,niq->n", J, est.covariance, J)
                    row["predicted_model_rms_m"] = float(np.sqrt(np.mean(var)))
                    row["chi2_per_dof"] = float(est.chi2_per_dof)
            rows[name] = row
    return {"seed": seed, "truth": truth_name, "p": int(basis.shape[1]), "sigma_rad": sigma_rad,
            "n_candidates": len(Qc), "n_pilot": n_pilot,
            "n_heldout": len(held), "rr_time_s": run_time, "designs": rows}


def _factor(a: float, b: float) -> str:
    return "inf (baseline singular)" if b <= 0 else f"{a / b:.1f}"


def print_index_table(rows: list[dict], key: str) -> None:
    print(f"\nobservation index (paper: B = sigma_min(Lambda) = O3^2; factor B_{key} / B_baseline, paper 18.5)")
    print("| seed | truth | baseline (reading) | measured poses | B | cond(Lambda) | factor in B (paper 18.5) | "
          "factor in O3 = sqrt | factor in cond |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        d = r["designs"]
        rr = d[key]
        print(f"| {r['seed']} | {r['truth']} | R&R on {key[3:]} | {rr['predicted_visible']} | {rr['B']:.4g} | "
              f"{rr['cond']:.4g} | 1 | 1 | 1 |")
        for b in readings(d):
            x = d[b]
            cond = "inf" if not np.isfinite(x["cond"]) else f"{x['cond'] / rr['cond']:.1f}"
            print(f"| {r['seed']} | {r['truth']} | {b} | {x['predicted_visible']}/{x['commanded']} | {x['B']:.4g} | "
                  f"{x['cond']:.4g} | {_factor(rr['B'], x['B'])} | {_factor(rr['O3'], x['O3'])} | {cond} |")


def readings(designs: dict) -> list[str]:
    """The baselines of a seed's designs (the whole grid when it was run)."""
    return [b for b in (*BASELINES, WHOLE_GRID) if b in designs]


def print_per_pose(rows: list[dict], key: str) -> None:
    """B divided by the number of measured poses: the whole grid's B grows with its ~N poses."""
    print(f"\nobservation index per measured pose, B / N (factor (B/N)_{key} / (B/N)_baseline)")
    print("| seed | truth | design | N | B / N | factor per pose |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        d = r["designs"]
        for b in (key, *readings(d)):
            x = d[b]
            print(f"| {r['seed']} | {r['truth']} | {b} | {x['predicted_visible']} | {x['B_per_pose']:.4g} | "
                  f"{_factor(d[key]['B_per_pose'], x['B_per_pose'])} |")


def print_table2(rows: list[dict]) -> None:
    print("\nTable 2 layout, mean over seeds: max |e| and half peak-to-peak, uncal. / cal. (mm, deg); "
          "paper in brackets")
    names = sorted({k for r in rows for k in r["designs"]})
    for truth in sorted({r["truth"] for r in rows}):
        rs = [r for r in rows if r["truth"] == truth]
        for name in names:
            ok = [r["designs"][name] for r in rs if r["designs"][name]["calibrated"]]
            if not ok:
                print(f"\n{truth} truth, {name}: not calibrated (too few measured poses or singular)")
                continue
            print(f"\n{truth} truth, design {name} ({len(ok)} seeds; lost on the hidden robot: "
                  f"{[r['designs'][name]['lost_on_hidden_robot'] for r in rs]})")
            print("| error | max uncal. | max cal. | ± uncal. | ± cal. |")
            print("|---|---|---|---|---|")
            for ax, unit, f in (("x", "mm", 1e3), ("y", "mm", 1e3), ("z", "mm", 1e3), ("alpha", "deg", np.degrees(1)),
                                ("beta", "deg", np.degrees(1)), ("gamma", "deg", np.degrees(1))):
                p = PAPER["table2"][ax]
                v = [np.mean([o[k][ax][s] for o in ok]) * f for k, s in (("before", "max_abs"), ("after", "max_abs"),
                                                                         ("before", "half_peak_to_peak"),
                                                                         ("after", "half_peak_to_peak"))]
                print(f"| e{ax} [{unit}] | {v[0]:.3f} ({p[0]}) | {v[1]:.3f} ({p[1]}) | ±{v[2]:.3f} (±{p[2]}) | "
                      f"±{v[3]:.3f} (±{p[3]}) |")


def print_summary(rows: list[dict]) -> dict:
    """Held-out RMS after calibration per design (mean ± standard error over seeds) and the prediction."""
    print("\nheld-out errors after calibration, mean ± standard error over seeds")
    print("| truth | design | B | RMS |e_p| [µm] | predicted model RMS [µm] | RMS orientation [mdeg] | "
          "lost on hidden robot |")
    print("|---|---|---|---|---|---|---|")
    out: dict = {}
    for truth in sorted({r["truth"] for r in rows}):
        rs = [r for r in rows if r["truth"] == truth]
        for name in rs[0]["designs"]:
            ok = [r["designs"][name] for r in rs if r["designs"][name]["calibrated"]]
            B = np.mean([r["designs"][name]["B"] for r in rs])
            lost = [r["designs"][name]["lost_on_hidden_robot"] for r in rs]
            if not ok:
                print(f"| {truth} | {name} | {B:.4g} | not calibrated | | | {lost} |")
                continue
            e = np.array([o["after"]["position"]["rms"] for o in ok]) * 1e6
            pr = np.array([o["predicted_model_rms_m"] for o in ok]) * 1e6
            a = np.degrees([o["after"]["orientation"]["rms"] for o in ok]) * 1e3
            se = e.std(ddof=1) / np.sqrt(len(e)) if len(e) > 1 else float("nan")
            print(f"| {truth} | {name} | {B:.4g} | {e.mean():.1f} ± {se:.1f} | {pr.mean():.1f} | {a.mean():.1f} | "
                  f"{lost} |")
            out[f"{truth}/{name}"] = {"B": float(B), "rms_um": float(e.mean()), "se_um": float(se),
                                      "predicted_model_rms_um": float(pr.mean()),
                                      "orientation_rms_mdeg": float(a.mean()), "lost": lost}
    return out


def study_004(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="study calib-004")
    ap.add_argument("--robot", default="rx130l")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--grid", type=int, default=PAPER["grid"])
    ap.add_argument("--n", type=int, default=PAPER["n"])
    ap.add_argument("--heldout", type=int, default=300)
    ap.add_argument("--criteria", nargs="+", default=["O3", "D", "A"], help="R&R criteria (first: the paper's)")
    ap.add_argument("--truth", nargs="+", default=["default", "ideal"], choices=["default", "ideal"])
    ap.add_argument("--margin-angle-deg", type=float, default=1.0)
    ap.add_argument("--margin-occlusion-m", type=float, default=0.01)
    ap.add_argument("--camera", choices=["registered", "nominal"], default="registered",
                    help="camera pose that decides the candidates: registered from pilot readings, or robot.yaml's")
    ap.add_argument("--laser-grid", type=int, default=9,
                    help="grid per axis of the laser-tracker experiment (0: skip it)")
    ap.add_argument("--compliance-scale", type=float, default=1.0,
                    help="default truth's joint compliance / nominal (k = robot.yaml's joint stiffness / scale, "
                         "spread 30 %%; the stiffness experiment)")
    ap.add_argument("--n-initial", type=int, default=None,
                    help="R&R start size (default --n; below it step 3, adding configurations, runs)")
    ap.add_argument("--probe-scale", type=float, default=1.0,
                    help="optical probe's diode layout x this (orientation noise / this; the Cardan experiment)")
    ap.add_argument("--whole-grid", action="store_true",
                    help="also measure every visible grid configuration (the 'linear scan' as the whole grid)")
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    margins = OpticalMargins(np.radians(a.margin_angle_deg), 0.05, a.margin_occlusion_m)
    grid = visible_grid(a.robot, a.grid, margins, a.probe_scale)
    print(f"\npaper 004 §3.4: {a.grid}^6 = {a.grid ** 6} grid configurations; visible to the optical tracker "
          f"(nominal, no margin): {grid['n_visible']} (paper: about {PAPER['visible']}); with the visibility margins "
          f"({a.margin_angle_deg} deg, {a.margin_occlusion_m} m) at the nominal camera pose: "
          f"{grid['n_candidates_nominal']} [{grid['time_s']:.0f} s]")
    jobs = [(a.robot, s, t, grid, a.n, a.heldout, a.criteria, margins, a.camera, a.compliance_scale,
             a.n_initial, a.probe_scale, a.whole_grid)
            for t in a.truth for s in a.seeds]
    rows = run_parallel(_seed, jobs, a.jobs)
    print(f"candidates per seed (visible with the margins at the {a.camera} camera pose): "
          + ", ".join(f"seed {r['seed']} {r['n_candidates']} ({r['n_pilot']} pilot poses)" for r in rows
                      if r["truth"] == rows[0]["truth"]))
    key = f"rr_{a.criteria[0]}"
    print("\nbaselines (literal readings of 'a linear scan of the workspace'):")
    for b in readings(rows[0]["designs"]):
        print(f"- {b}: {READINGS[b]}")
    print_index_table(rows, key)
    print_per_pose(rows, key)
    print_table2(rows)
    summary = print_summary(rows)
    factors = {b: [r["designs"][key]["B"] / r["designs"][b]["B"] if r["designs"][b]["B"] > 0 else float("inf")
                   for r in rows] for b in readings(rows[0]["designs"])}
    factors_per_pose = {b: [r["designs"][key]["B_per_pose"] / r["designs"][b]["B_per_pose"]
                            if r["designs"][b]["B_per_pose"] > 0 else float("inf") for r in rows]
                        for b in readings(rows[0]["designs"])}
    print("\nfactor B_R&R / B_baseline per reading (median over seeds and truths; paper 18.5): "
          + ", ".join(f"{b} {np.median(v):.1f}" for b, v in factors.items()))
    laser: dict = {}
    if a.laser_grid:
        Ql = lz.laser_grid(a.robot, a.laser_grid)
        laser_jobs = [(a.robot, s, t, Ql, a.n, a.heldout) for t in a.truth for s in a.seeds]
        laser_rows = run_parallel(lz.laser_seed, laser_jobs, a.jobs)
        laser = {"grid": a.laser_grid, "rows": laser_rows, "summary": lz.print_laser(laser_rows)}
    elapsed = time.perf_counter() - t0
    print(f"study time {elapsed:.0f} s")
    save_result("calib-004", {"args": vars(a), "grid": {k: v for k, v in grid.items() if k not in ("Q", "flat")},
                        "rows": rows, "summary": summary, "factors_B": factors,
                        "factors_B_per_pose": factors_per_pose, "paper": PAPER,
                        "laser_experiment": laser, "time_s": elapsed})
    return 0
