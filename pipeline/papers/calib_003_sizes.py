"""Paper 003's searches at small subset sizes on the literal, model-consistent hidden robot (study
``calib-003-sizes``).

Paper ``003_16198f1660ab3739.txt`` §4.2 compares DETMAX and BSAA with the indices O1..Oc on a
simulated UR10 whose errors are purely geometric (uniform ±1.5 mm / mrad) and read with ±10 µm
tracker noise; the real experiment selects 500 of 583 poses. With a complete error model and 500
of 583 poses, every subset identifies the parameters to the noise floor, so no selection can help
(study ``calib-003``, table (1)). This experiment asks where selection can matter on that same
literal truth: ``n`` of the same 583 poses for ``n`` in ``--sizes`` (e.g. 30 … 200), searched on the
nominal model by DETMAX × {O1, O3, Oc} and BSAA × Oc (the paper's best), beside a random subset
("none"), each calibrated from its readings (:func:`pipeline.papers.calib_003._calibrate_all`).

Two errors per design and validation pose set (50 poses, mean over the poses):
- ``mean``: against the validation readings (the paper's measure; it contains their ±10 µm noise);
- ``model``: the calibrated model's prediction against the hidden robot's noise-free reflector
  position, ``|p_model(q) - p_true(q)|`` in the tracker frame: what the selection can change.
Each is reported as mean ± standard error over seeds and paired against "none" (same seed, same
poses), so that a selection effect smaller than the spread between seeds is still visible.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from pipeline.calibration.estimate import estimate, register_points
from pipeline.core.blas import single_thread_blas
from pipeline.core.errors import SolverError
from pipeline.papers import calib_003 as p3
from pipeline.papers import calib_003_search as ps
from pipeline.papers.registry import save_result
from pipeline.sim.truth import RealRobot, TruthConfig

#: searches of the experiment: (algorithm, index)
SEARCHES = (("detmax", "O1"), ("detmax", "O3"), ("detmax", "Oc"), ("bsaa", "Oc"))


def design_keys() -> list[str]:
    return ["none"] + [f"{alg}_{name}" for alg, name in SEARCHES]


def select(J: np.ndarray, pos_mm: np.ndarray, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """The random subset and every search of :data:`SEARCHES` for ``n`` poses of the pool."""
    scale = ps.reference_scale(J, pos_mm, n, rng)
    out = {"none": np.sort(ps.random_subset(J, n, rng))}
    fns: dict[str, Callable[..., ps.SearchResult]] = {"detmax": ps.detmax, "bsaa": ps.bsaa}
    for alg, name in SEARCHES:
        out[f"{alg}_{name}"] = np.sort(fns[alg](J, pos_mm, name, n, rng, scale).selected)
    return out


def calibrate(robot, mm, basis: np.ndarray, seed: int, truth: TruthConfig, Qp: np.ndarray, Qv: np.ndarray,
              selections: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Each selection calibrated from the pool's readings on the hidden robot; mean validation error
    against the readings and against the noise-free reflector positions (m)."""
    real = RealRobot.create(robot, seed, truth)
    rng = np.random.default_rng([seed, 3, 1])
    rp = real.tracker.measure(Qp, rng)
    rv = real.tracker.measure(Qv, rng)
    vis_v = np.asarray(rv.visible, bool)
    vis_p = np.flatnonzero(np.asarray(rp.visible, bool))
    T = real.transform_tracker_to_base
    p_base, _ = real.truth.poses(real.link_angles(Qv[vis_v]), real.truth.frame_reflector)
    p_true = (p_base - T.translation) @ T.rotation
    Yv = np.asarray(rv.position_m)[vis_v]
    P_nom, _ = mm.base_positions(Qp[vis_p], np.zeros(mm.n))
    T_reg = register_points(np.asarray(rp.position_m)[vis_p], P_nom)
    out = {"uncalibrated": {"mean": float(np.linalg.norm(Yv - mm.predict(Qv[vis_v], np.zeros(mm.n), T_reg),
                                                         axis=1).mean()), "model": float("nan")}}
    for key, sel in selections.items():
        rows = np.intersect1d(np.asarray(sel, int), vis_p)
        est = estimate(mm, Qp[rows], np.asarray(rp.position_m)[rows], np.asarray(rp.sigma_m)[rows], basis)
        if not est.converged:
            raise SolverError(None, f"calib-003-sizes seed {seed} design {key}",
                              "Levenberg-Marquardt did not converge")
        pred = mm.predict(Qv[vis_v], est.x, est.registration)
        out[key] = {"mean": float(np.linalg.norm(Yv - pred, axis=1).mean()),
                    "model": float(np.linalg.norm(p_true - pred, axis=1).mean()), "measured": int(rows.size)}
    return out


def run_seed(seed: int, pool: int, sizes: Sequence[int], n_val: int, truth: TruthConfig) -> dict:
    """Selections of every size (nominal model) and their calibrations on the seed's hidden robot."""
    with single_thread_blas():
        robot, mm, _, basis, Qp, Qv, J, pos_mm, rng = p3.pool_setup(seed, pool, n_val)
        out: dict = {"seed": seed, "sizes": {}}
        for n in sizes:
            t0 = time.perf_counter()
            sel = select(J, pos_mm, n, rng)
            indices = {k: ps.index_values(J, pos_mm, v) for k, v in sel.items()}
            errors = calibrate(robot, mm, basis, seed, truth, Qp, Qv, sel)
            out["sizes"][str(n)] = {"errors": errors, "indices": indices, "time_s": time.perf_counter() - t0}
    return out


def _mse(v: Sequence[float]) -> list[float]:
    a = np.asarray(v, float)
    return [float(a.mean()), float(a.std(ddof=1) / math.sqrt(a.size)) if a.size > 1 else 0.0]


def summarise(rows: Sequence[dict], sizes: Sequence[int]) -> dict:
    """Per size and design: mean ± SE over seeds (µm) of both errors, their paired differences from
    "none", and the O1 / O3 reached (mean over seeds)."""
    table: dict = {}
    for n in sizes:
        per = [r["sizes"][str(n)] for r in rows]
        table[str(n)] = {}
        for key in design_keys():
            e = {m: [1e6 * p["errors"][key][m] for p in per] for m in ("mean", "model")}
            d = {m: [1e6 * (p["errors"][key][m] - p["errors"]["none"][m]) for p in per] for m in ("mean", "model")}
            table[str(n)][key] = {"mean_um": _mse(e["mean"]), "model_um": _mse(e["model"]),
                                  "paired_mean_um": _mse(d["mean"]), "paired_model_um": _mse(d["model"]),
                                  "O1": float(np.mean([p["indices"][key]["O1"] for p in per])),
                                  "O3": float(np.mean([p["indices"][key]["O3"] for p in per]))}
    return table


def markdown(table: dict) -> str:
    lines = ["| poses of 583 | design | mean vs readings [µm] | paired − none [µm] | model error [µm] | "
             "paired − none [µm] | O1 | O3 [mm] |", "|---|---|---|---|---|---|---|---|"]
    for n, designs in table.items():
        for key, v in designs.items():
            lines.append(f"| {n} | {key} | {v['mean_um'][0]:.2f} ± {v['mean_um'][1]:.2f} | "
                         f"{v['paired_mean_um'][0]:+.2f} ± {v['paired_mean_um'][1]:.2f} | "
                         f"{v['model_um'][0]:.2f} ± {v['model_um'][1]:.2f} | "
                         f"{v['paired_model_um'][0]:+.2f} ± {v['paired_model_um'][1]:.2f} | "
                         f"{v['O1']:.4g} | {v['O3']:.4g} |")
    return "\n".join(lines)


def study_sizes(seeds: int, pool: int, sizes: Sequence[int], n_val: int) -> dict:
    """Run, print and return the experiment (the caller saves it)."""
    t0 = time.perf_counter()
    print(f"paper 003 searches on the literal hidden robot (geometric errors ±1.5 mm / mrad, tracker noise "
          f"±10 µm, nothing unmodelled): {list(sizes)} of {pool} poses, {n_val} validation poses, {seeds} seeds")
    rows = []
    for s in range(seeds):
        rows.append(run_seed(s, pool, sizes, n_val, p3.paper_truth()))
        print(f"seed {s} done ({time.perf_counter() - t0:.0f} s)", flush=True)
    table = summarise(rows, sizes)
    print("\nmean ± standard error over seeds; paired: the design minus 'none' of the same seed; model error: "
          "prediction vs the noise-free reflector position\n")
    print(markdown(table))
    elapsed = time.perf_counter() - t0
    print(f"\nrun time {elapsed:.0f} s")
    return {"args": {"seeds": seeds, "pool": pool, "sizes": list(sizes), "validation": n_val},
            "table_sizes": table, "rows": rows, "run_time_s": elapsed}


def study(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="study calib-003-sizes", description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--pool", type=int, default=583, help="pool size (the paper's real experiment: 583)")
    ap.add_argument("--sizes", type=int, nargs="+", default=[30, 60, 100, 200])
    ap.add_argument("--validation", type=int, default=50)
    ap.add_argument("--quick", action="store_true", help="at most 2 seeds, 20 and 40 of 120 poses (the test)")
    a = ap.parse_args(argv)
    if a.quick:
        a.seeds, a.pool, a.sizes = min(a.seeds, 2), 120, [20, 40]
    save_result("calib-003-sizes", study_sizes(a.seeds, a.pool, a.sizes, a.validation))
    return 0
