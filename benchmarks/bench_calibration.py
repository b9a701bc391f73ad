"""Speed of the calibration designs and of a recorded calibration, as ratios against baselines
measured in the same run.

Run: ``.venv/bin/python benchmarks/bench_calibration.py [robot] [grid_per_axis] [n_gradient]
[full|sampled]`` (defaults rx130l, 13, 60, full), or ``... bench_calibration.py recorded [n_poses]``
for section 5 alone (default 1000 poses).

1. Filter the full ``grid^6`` joint grid and evaluate the whitened Jacobians of the survivors
   (the calibration stage's default settings: parameters, design basis, V criterion).
2. Remove-and-replace (paper 004, O3, 32 configurations) on it. Baseline: the same exhaustive
   searches done by recomputing ``M = J^T J`` from the stacked Jacobian of the whole selection for
   every candidate (one full recompute per swap candidate); its cost is measured per candidate and
   multiplied by the number of candidates every search has to visit.
3. Remove-and-replace on the default criterion (V, ``n_configurations`` of the default profile) with
   the low-rank updates of every candidate at once (:mod:`pipeline.calibration.trace_updates`).
   Baseline: the previous per-candidate path (each exchange = remove, score every candidate by its
   own p x p Sherman-Morrison-Woodbury update, put back), ``full``: the whole selection run again
   (same design required), ``sampled``: its cost per search at the final design times the number
   of searches.
4. Gradient design (paper 000) of ``n_gradient`` configurations (task-space V criterion, collision
   constraints, IPOPT) warm-started from remove-and-replace on a random candidate set, three seeds:
   IPOPT status, time against the 10 s target, index gain over remove-and-replace. Baseline: one
   evaluation of the objective (ratio = equivalent number of evaluations).
5. A recorded calibration with the defaults (``parameters: auto``: every candidate of the model
   selection x 5 spatial folds, a REML noise model in each, no validation file) on a record of
   ``n_poses`` tracker readings of the simulated arm (hidden robot 0, random visible
   configurations) written as a CSV: each run in a fresh interpreter, the first with an empty
   compiled-code cache (``PIPELINE_CACHE_DIR``: the measurement functions are compiled), then one
   with that cache. Printed: both times, the later
   one against the 30 s target and the first over the later one (target <= 2). On FIGAROH's UR10
   6-D record (``data/figaroh_ur10_mocap``) ours with the defaults and FIGAROH 1.0.2's
   ``BaseCalibration`` (full geometric parameters, 6-D marker, LM; the ``bench`` extra) in the same
   run: the ratio of the times, and the held-out RMS position and orientation over all 23 poses, on
   the same spatial folds as our model selection's (ours nested) and by FIGAROH's leave-one-out.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
from bench_help import exit_on_help
from figaroh_config import figaroh_calibration_yaml

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import indices as ix
from pipeline.calibration import measure as ms
from pipeline.calibration import stage as st
from pipeline.calibration.crossval import spatial_folds
from pipeline.calibration.design_state import DesignState, is_regular
from pipeline.calibration.elastostatic import design_basis, design_torques, measurement_model
from pipeline.calibration.gradient_design import GradientDesignConfig, gradient_design
from pipeline.calibration.model_selection import CANDIDATES
from pipeline.core.blas import single_thread_blas
from pipeline.core.config import REPO_ROOT
from pipeline.robot.model import RobotModel
from pipeline.robot.yaml_init import write_robot_yaml
from pipeline.sim.truth import RealRobot

HAVE_FIGAROH = importlib.util.find_spec("figaroh") is not None
#: FIGAROH's calibration class, an optional peer (the bench extra, not installed by default); None without it
BaseCalibration = (importlib.import_module("figaroh.calibration.base_calibration").BaseCalibration
                   if HAVE_FIGAROH else None)


class PerCandidateState(DesignState):
    """The previous candidate searches of the trace indices: no update cache; an exchange removes,
    scores every candidate by its own Sherman-Morrison-Woodbury update
    ``trace(W M^-1) - trace(S^-1 H W H^T)`` (``H = G M^-1``, ``S = I + H G^T``, O(p^2) each) and
    puts back."""

    def update_cache(self) -> None:
        return None

    def best_add(self, exclude: np.ndarray | None = None) -> tuple[int, float]:
        if self.spec.name not in ix.TRACE_INDICES or not is_regular(self.M):
            return super().best_add(exclude)
        allowed = ~self.in_set
        if exclude is not None:
            allowed[exclude] = False
        cand = np.flatnonzero(allowed)
        Minv = np.linalg.inv(self.M)
        Minv = 0.5 * (Minv + Minv.T)
        W = self.spec.weight_matrix(self.p)
        base = float(np.sum(Minv * W))
        MWM = Minv @ W @ Minv
        eye = np.eye(self.G.shape[1])
        out = np.empty(cand.size)
        for s in range(0, cand.size, 8192):
            Gc = self.G[cand[s : s + 8192]]
            S = eye + np.einsum("bmi,bni->bmn", Gc @ Minv, Gc)
            T = np.einsum("bmi,ij,bnj->bmn", Gc, MWM, Gc)
            out[s : s + Gc.shape[0]] = -(base - np.einsum("bmn,bnm->b", np.linalg.inv(S), T))
        self.evaluations += cand.size
        i = int(np.argmax(out))
        return int(cand[i]), float(out[i])


def counting(cls: type[DesignState]) -> tuple[type[DesignState], dict[str, int]]:
    """A subclass of ``cls`` counting its exhaustive searches (additions, and exchanges including
    the addition an exchange may do inside)."""
    calls = {"add": 0, "exchange": 0, "depth": 0}

    class Counting(cls):
        def best_add(self, exclude: np.ndarray | None = None) -> tuple[int, float]:
            calls["add"] += calls["depth"] == 0
            return super().best_add(exclude)

        def best_exchange(self, k: int) -> tuple[int, float]:
            calls["exchange"] += 1
            calls["depth"] += 1
            try:
                return super().best_exchange(k)
            finally:
                calls["depth"] -= 1

    return Counting, calls


def timed_selection(cls: type[DesignState], G: np.ndarray, spec: ix.IndexSpec, n: int,
                    rng: np.random.Generator, n_initial: int | None = None
                    ) -> tuple[ds.SelectionResult, float, dict[str, int]]:
    """Remove-and-replace with the state class ``cls``: result, seconds, search counts."""
    state_cls, calls = counting(cls)
    ds.DesignState = state_cls
    try:
        t0 = time.perf_counter()
        res = ds.remove_and_replace(G, spec, n, rng, n_initial=n_initial)
        return res, time.perf_counter() - t0, calls
    finally:
        ds.DesignState = DesignState


def per_search_s(cls: type[DesignState], G: np.ndarray, spec: ix.IndexSpec, selected: np.ndarray,
                 n_removals: int = 10) -> float:
    """Seconds of one exchange search (``n_removals`` removals at the design ``selected``)."""
    st_ = cls(G, spec, None, selected)
    st_.best_exchange(int(selected[0]))        # build the cache (amortised over a pass)
    t0 = time.perf_counter()
    for k in selected[:n_removals]:
        st_.best_exchange(int(k))
    return (time.perf_counter() - t0) / n_removals


def bench_default_selection(G: np.ndarray, spec: ix.IndexSpec, n: int, baseline: str) -> None:
    """Section 3 of the module docstring."""
    N, m, p = G.shape
    new, t_new, calls = timed_selection(DesignState, G, spec, n, np.random.default_rng(0))
    searches = calls["add"] + calls["exchange"]
    print(f"remove-and-replace {spec.name}, {n} of {N} candidates (m = {m}, p = {p}): {t_new:.1f} s, "
          f"{calls['exchange']} exchange + {calls['add']} addition searches, {new.evaluations} candidate "
          f"evaluations (target <= 30 s: ratio {t_new / 30:.2f})")
    c_new = per_search_s(DesignState, G, spec, new.selected)
    c_old = per_search_s(PerCandidateState, G, spec, new.selected)
    print(f"  one exchange search at the final design: low-rank updates {1e3 * c_new:.1f} ms, per-candidate "
          f"path {1e3 * c_old:.1f} ms -> speed-up {c_old / c_new:.1f}x")
    if baseline == "full":
        old, t_old, _ = timed_selection(PerCandidateState, G, spec, n, np.random.default_rng(0))
        same = sorted(old.selected.tolist()) == sorted(new.selected.tolist())
        print(f"  per-candidate path, whole selection: {t_old:.1f} s -> speed-up {t_old / t_new:.1f}x; "
              f"same design: {same} (index {new.index_value:.6g} vs {old.index_value:.6g})")
    else:
        print(f"  per-candidate path, estimated ({searches} searches x {1e3 * c_old:.1f} ms): {searches * c_old:.0f} s "
              f"-> speed-up {searches * c_old / t_new:.1f}x")


def naive_cost_per_candidate(G: np.ndarray, n: int, rng: np.random.Generator, repeat: int = 300) -> float:
    """Seconds to score one candidate by recomputing J^T J of the (n+1)-configuration selection."""
    sel = rng.choice(len(G), size=n, replace=False)
    J = G[sel].reshape(-1, G.shape[2])
    cand = rng.choice(len(G), size=repeat)
    t0 = time.perf_counter()
    for c in cand:
        Jc = np.vstack([J, G[c]])
        np.linalg.eigvalsh(Jc.T @ Jc)
    return (time.perf_counter() - t0) / repeat


def main(robot_name: str = "rx130l", grid: int = 13, n_gradient: int = 60, baseline: str = "full") -> None:
    robot = RobotModel.load(robot_name)
    rng = np.random.default_rng(0)
    with single_thread_blas():
        cfg = st.Config(grid_per_axis=grid)
        mm = measurement_model(robot, cfg)
        _, full_basis = st.identify_parameter_set(robot, mm, cfg, rng)
        basis = design_basis(mm, full_basis)
        t0 = time.perf_counter()
        cs = st.build_candidates(robot, cfg, basis, rng, design_torques(mm))
        t_cand = time.perf_counter() - t0
        print(f"{robot_name}: grid {grid}^6 = {cs.counts['total']} configurations -> {len(cs)} feasible "
              f"candidates; filter + Jacobians {t_cand:.1f} s "
              f"(target <= 120 s: ratio {t_cand / 120:.2f} of the budget)")
        rr, t_rr, calls = timed_selection(DesignState, cs.G, ix.IndexSpec("O3"), 32, rng, n_initial=32)
        n_searches = calls["add"] + calls["exchange"]
        t_naive = naive_cost_per_candidate(cs.G, 32, rng)
        naive_total = t_naive * len(cs) * n_searches
        print(f"remove-and-replace O3, 32 configurations: {t_rr:.1f} s, {n_searches} exhaustive searches over "
              f"{len(cs)} candidates, {rr.evaluations} exact index evaluations")
        print(f"  baseline (one full J^T J recompute per candidate): {1e6 * t_naive:.0f} us per candidate, "
              f"estimated {naive_total:.0f} s -> speed-up of rank-one updates + bound-and-prune: "
              f"{naive_total / t_rr:.0f}x; remove-and-replace / 120 s budget: {t_rr / 120:.2f}")
        spec_v, _ = st.index_spec(cfg, robot, mm, basis, rng)
        bench_default_selection(cs.G, spec_v, cfg.n_configurations, baseline)
        # gradient design (V criterion over the ISO 9283 cube), three seeds of the candidate set
        for seed in (0, 1, 2):
            grng = np.random.default_rng(seed)
            cfg_r = st.Config(candidates="random", n_random_candidates=2000, n_region_configurations=100)
            cs_r = st.build_candidates(robot, cfg_r, basis, grng, design_torques(mm))
            spec, _ = st.index_spec(cfg_r, robot, mm, basis, grng)
            start = ds.remove_and_replace(cs_r.G, spec, n_gradient, grng, n_initial=n_gradient)
            t0 = time.perf_counter()
            res = gradient_design(robot, mm, basis, cs_r.Q[start.selected], spec, GradientDesignConfig())
            t_grad = time.perf_counter() - t0
            G = cs_r.G[start.selected]
            t0 = time.perf_counter()
            for _ in range(20):
                M = np.einsum("kmi,kmj->ij", G, G)
                np.linalg.solve(M, spec.weight_matrix(M.shape[0]))
            t_eval = (time.perf_counter() - t0) / 20
            print(f"gradient design (seed {seed}), {n_gradient} configurations with collision constraints, index "
                  f"{spec.name}: {t_grad:.1f} s (/ 10 s target: {t_grad / 10:.2f}), {res.iterations} IPOPT iterations, "
                  f"{res.status}; index {res.index_value_start:.4g} -> {res.index_value:.4g} "
                  f"({100 * (1 - res.index_value / res.index_value_start):.1f} % better than remove-and-replace), "
                  f"{res.reverted} configurations reverted {res.reverted_reasons or ''}"
                  + (f"; FALLBACK: {res.fallback}" if res.fallback else ""))
            print(f"  ratios: gradient design / remove-and-replace warm start "
                  f"{t_grad / max(start.run_time_s, 1e-9):.2f}; / one numpy objective evaluation {t_grad / t_eval:.0f}")
    bench_recorded()

#: the 1000-pose recorded calibration's targets (section 5): seconds, first run over a later one
RECORDED_TARGET_S = 30.0
FIRST_OVER_LATER_TARGET = 2.0
UR10 = REPO_ROOT / "data" / "figaroh_ur10_mocap"
UR10_JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
               "wrist_3_joint"]


def simulated_record(robot: RobotModel, n_poses: int, path: Path) -> Path:
    """``n_poses`` visible tracker readings of hidden robot 0 at random configurations, as a CSV."""
    real = RealRobot.create(robot, 0)
    rng = np.random.default_rng(0)
    Q, _ = cd.random_candidates(cd.chain_from_robot(robot), int(1.5 * n_poses), rng)
    meas = ms.measure_simulated(real, Q, rng)
    keep = slice(0, n_poses)
    return ms.write_csv(path, ms.Measurements(meas.Q[keep], meas.Y[keep], meas.sigma_m[keep], "simulated"))


def calibrate_file(csv: str, robot: str) -> None:
    """One recorded calibration with the defaults (run in a fresh interpreter by :func:`timed_run`)."""
    t0, c0 = time.perf_counter(), time.process_time()
    cfg = st.Config(measurements_csv=csv, figures=False)
    cfg.validate()
    out = st.calibrate(RobotModel.load(robot), None, cfg, np.random.default_rng(0))
    cv = out.notes.cross_validation or {}
    sel = out.notes.model_selection
    print(f"RESULT {time.perf_counter() - t0:.3f} {time.process_time() - c0:.3f} "
          f"{sel.chosen.name if sel is not None else None}|{cv.get('rms_position_error_m')}")


def timed_run(csv: Path, robot: str, cache: Path) -> tuple[float, float, str]:
    """Wall and CPU time (s, the calibration alone, the build of compiled code included) of
    :func:`calibrate_file` in a fresh interpreter with the compiled-code cache ``cache``, and what it
    chose (the CPU time of a loaded machine's run is the better guide: the wall time waits for others)."""
    env = dict(os.environ, PIPELINE_CACHE_DIR=str(cache))
    out = subprocess.run([sys.executable, __file__, "_calibrate_file", str(csv), robot], env=env, check=True,
                         capture_output=True, text=True).stdout
    line = next(x for x in out.splitlines() if x.startswith("RESULT "))
    _, seconds, cpu, chosen = line.split(" ", 3)
    return float(seconds), float(cpu), chosen


def ur10_robot(folder: Path) -> tuple[RobotModel, Path]:
    """The UR10 record's robot (URDF as shipped, robot.yaml from robot init) and its CSV in our layout."""
    (folder / "robot.urdf").write_bytes((UR10 / "robot.urdf").read_bytes())
    write_robot_yaml(folder / "robot.urdf")
    spec = importlib.util.spec_from_file_location("mocap_rpy_csv", REPO_ROOT / "tools" / "mocap_rpy_csv.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return RobotModel.load(folder), module.convert(UR10 / "calibration.csv", folder / "ur10.csv", UR10_JOINTS)


def _figaroh_fit(folder: Path, tag: str, train_rows: list[str], held_rows: list[str], header: str):
    """FIGAROH 1.0.2's ``BaseCalibration`` of the UR10 record's ``train_rows`` (full geometric
    parameters, unknown base frame (the camera's) and marker frame on wrist_3_link, 6-D marker, LM;
    the figaroh-examples ur10 layout) with ``held_rows`` as its validation file: (seconds of
    initialise + solve, its validation metrics, as its solve stores them, or None without held-out
    rows)."""
    model = pin.buildModelFromUrdf(str(UR10 / "robot.urdf"))
    robot = SimpleNamespace(model=model, data=model.createData(), q0=pin.neutral(model))
    train = folder / f"figaroh_{tag}_train.csv"
    train.write_text("\n".join([header, *train_rows]) + "\n")
    config = folder / f"figaroh_{tag}.yaml"
    config.write_text(figaroh_calibration_yaml("ur10", list(UR10_JOINTS), train, len(train_rows),
                                               tool_frame="wrist_3_link", marker="marker",
                                               reference_joint="wrist_3_joint", measured_dof=6))
    t0 = time.perf_counter()
    calib = BaseCalibration(robot, str(config))
    calib.calib_config["known_baseframe"] = False
    calib.calib_config["known_tipframe"] = False
    if held_rows:
        held = folder / f"figaroh_{tag}_held.csv"
        held.write_text("\n".join([header, *held_rows]) + "\n")
        calib.calib_config["validation_data_file"] = str(held)
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")     # its default cost function's performance warning
        calib.initialize()
        calib.solve(method="lm", max_iterations=1, enable_logging=False, plotting=False, save_results=False)
    seconds = time.perf_counter() - t0
    metrics = calib.results_data.get("validation_metrics") if held_rows else None
    if held_rows and (metrics is None or metrics["validation_source"] != "validation_data"):
        raise RuntimeError(f"FIGAROH did not score its validation file ({metrics and metrics['validation_source']})")
    return seconds, metrics


def figaroh_ur10_folds(folder: Path, header: str, rows: list[str], fold_of_pose: np.ndarray
                       ) -> list[tuple[int, float, float, float]]:
    """Per fold of ``fold_of_pose`` (in the order of ``np.unique``), FIGAROH's fit of the other poses
    of the UR10 record (``header``, ``rows``: its CSV lines) predicting the fold: ``(poses held out,
    RMS position error m, RMS orientation error rad, seconds of the fit)``."""
    out = []
    for f in np.unique(fold_of_pose):
        held = set(np.flatnonzero(fold_of_pose == f).tolist())
        s, m = _figaroh_fit(folder, f"fold{f}", [r for i, r in enumerate(rows) if i not in held],
                            [rows[i] for i in sorted(held)], header)
        assert m is not None
        rot_rad = float(np.radians(m["orient_rmse_calibrated_deg"]))
        out.append((len(held), m["pos_rmse_calibrated_mm"] * 1e-3, rot_rad, s))
    return out


def figaroh_ur10_heldout(folder: Path, header: str, rows: list[str], fold_of_pose: np.ndarray
                         ) -> tuple[float, float, float]:
    """FIGAROH's held-out RMS position (m) and orientation (rad) over every pose of the UR10 record
    when each fold of ``fold_of_pose`` is predicted by the fit of the others
    (:func:`figaroh_ur10_folds`), and the seconds of all those fits."""
    folds = figaroh_ur10_folds(folder, header, rows, fold_of_pose)
    n = sum(k for k, *_ in folds)
    return (float(np.sqrt(sum(k * p ** 2 for k, p, _, _ in folds) / n)),
            float(np.sqrt(sum(k * r ** 2 for k, _, r, _ in folds) / n)), float(sum(s for *_, s in folds)))


def bench_ur10(folder: Path) -> None:
    """Ours with the defaults against FIGAROH 1.0.2 on FIGAROH's UR10 6-D record, in the same run:
    times, and the held-out figures over all 23 poses on the same spatial folds as our model
    selection's, and FIGAROH's by leave-one-out (its own protocol)."""
    robot, ur10_csv = ur10_robot(folder)
    with single_thread_blas():
        t0 = time.perf_counter()
        cfg = st.Config(measurements_csv=str(ur10_csv), figures=False)
        cfg.validate()
        out = st.calibrate(robot, None, cfg, np.random.default_rng(0))
        ours = time.perf_counter() - t0
    cv = out.notes.cross_validation or {}
    sel = out.notes.model_selection
    ours_pos, ours_rot = cv.get("rms_position_error_all_poses_m"), cv.get("rms_orientation_error_all_poses_rad")
    head = f"UR10 6-D record (23 poses): ours (defaults, model selection) {ours:.1f} s"
    if sel is None or ours_pos is None or ours_rot is None:
        print(f"{head}; no cross-validation to compare (model selection did not run)")
        return
    folds = spatial_folds(out.measurements.Q, sel.folds)
    with single_thread_blas():   # the chosen parameter set fixed: one fit and its cross-validation
        t0 = time.perf_counter()
        fixed = st.Config(measurements_csv=str(ur10_csv), figures=False, parameters=sel.chosen.parameters)
        fixed.validate()
        st.calibrate(robot, None, fixed, np.random.default_rng(0))
        ours_fixed = time.perf_counter() - t0
    if not HAVE_FIGAROH:
        print(f"{head}; FIGAROH skipped (pip install 'pipeline[bench]')")
        return
    header, *rows = (UR10 / "calibration.csv").read_text().splitlines()
    try:
        one_fit, _ = _figaroh_fit(folder, "all", rows, [], header)
        f_pos, f_rot, f_s = figaroh_ur10_heldout(folder, header, rows, folds)
        l_pos, l_rot, l_s = figaroh_ur10_heldout(folder, header, rows, np.arange(len(folds)))
    except Exception as exc:   # a peer's failure is a result to print, not a crash of the benchmark
        print(f"{head}; FIGAROH failed: {type(exc).__name__}: {exc}")
        return
    print(f"{head}, FIGAROH 1.0.2 (one fit, no selection) {one_fit:.2f} s; ours / FIGAROH {ours / one_fit:.1f}; "
          f"ours with the chosen set fixed ({sel.chosen.parameters}: one fit and a {sel.folds}-fold cross-validation) "
          f"{ours_fixed:.2f} s, / FIGAROH's one fit {ours_fixed / one_fit:.1f}")
    print(f"  held-out over all 23 poses, the same {sel.folds} spatial folds: ours {ours_pos * 1e3:.3f} mm / "
          f"{np.degrees(ours_rot):.3f} deg (chose {sel.chosen.name} on all poses, orientation weight nested), "
          f"FIGAROH {f_pos * 1e3:.3f} mm / "
          f"{np.degrees(f_rot):.3f} deg ({f_s:.1f} s); ours / FIGAROH {ours_pos / f_pos:.3f} position, "
          f"{ours_rot / f_rot:.3f} orientation")
    print(f"  FIGAROH leave-one-out (its protocol, 23 fits, {l_s:.1f} s): {l_pos * 1e3:.3f} mm / "
          f"{np.degrees(l_rot):.3f} deg; ours in {sel.folds} spatial folds / FIGAROH leave-one-out "
          f"{ours_pos / l_pos:.3f} position, {ours_rot / l_rot:.3f} orientation")


def bench_recorded(n_poses: int = 1000, robot_name: str = "rx130l") -> None:
    """Section 5 of the module docstring."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        csv = simulated_record(RobotModel.load(robot_name), n_poses, folder / "record.csv")
        first, first_cpu, chosen = timed_run(csv, robot_name, folder / "cache")
        later, later_cpu, _ = timed_run(csv, robot_name, folder / "cache")
        print(f"recorded calibration, {n_poses} poses ({robot_name}, defaults: {len(CANDIDATES)} candidates x 5 "
              f"spatial folds, REML "
              f"noise model per fold; chose {chosen.split('|')[0]}): first run (compiling) {first:.1f} s "
              f"(CPU {first_cpu:.1f} s in-process, gcc's builds not counted), later {later:.1f} s "
              f"(CPU {later_cpu:.1f} s); "
              f"later / {RECORDED_TARGET_S:g} s target {later / RECORDED_TARGET_S:.2f}, first / later "
              f"{first / later:.2f} (target <= {FIRST_OVER_LATER_TARGET:g})")
        bench_ur10(folder)

if __name__ == "__main__":
    exit_on_help(__doc__)
    args = sys.argv[1:]
    if args and args[0] == "_calibrate_file":
        calibrate_file(args[1], args[2])
        sys.exit(0)
    if args and args[0] == "recorded":
        bench_recorded(int(args[1]) if len(args) > 1 else 1000)
        sys.exit(0)
    main(args[0] if args else "rx130l", int(args[1]) if len(args) > 1 else 13,
         int(args[2]) if len(args) > 2 else 60, args[3] if len(args) > 3 else "full")
