"""How much better than the baselines can ANY calibration design be? (``calib-design`` setting)

Run: ``.venv/bin/python benchmarks/bench_design_bound.py [--robots rx130l staubli_tx40] [--n 32]``
(about 1 min on one core).

Per robot, on the pool of the ``calib-design`` study as documented in ``docs/calibration_design.md``
(``--quick``: 1500 random feasible candidates, the robot's ISO 9283 cube with 300 working
configurations, all identifiable geometric parameters, the tracker noise model; built by
:func:`pipeline.papers.calib_design.study_pool`, same stream, so the same pool):

1. the optimal approximate design (:func:`pipeline.calibration.design_bound.optimal_approximate_design`,
   multiplicative algorithm, equivalence-theorem certificate) gives ``V* / n``, a lower bound on the
   criterion of every design of ``n`` configurations from the pool; printed as predicted RMS
   ``sqrt(V)`` next to the V design (the stage's default: V on TCP + reflector, remove-and-replace from
   a random start and from the rounded optimal approximate design, :mod:`pipeline.calibration.design_rounding`),
   every (N/n)-th candidate,
   a random design and remove-and-replace on O3, with the largest possible expected gain of any
   design over each baseline, ``1 - sqrt(V_bound / V_baseline)``. Two figures: the TCP over the
   working region (the V criterion itself) and the reflector in the tracker frame at the working
   configurations (the study's held-out "actual RMS" figure). The bound is also computed on a larger
   pool (``--large-pool`` random feasible candidates; the stage's ``n_random_candidates`` is 20000) with
   the same weighting, to show how little a larger pool would add.
2. the per-robot spread (linearised model): the realised RMS of each design is a random draw
   (:func:`pipeline.calibration.design_bound.rms_samples`; each design its own noise); printed
   ``P(RMS_design <= 0.85 RMS_baseline)`` on one seed, on all ``--seeds`` seeds (``p^seeds``), for the
   V design and for a design AT the bound, and how far below the bound a design would have to be to
   pass on all seeds with probability 0.5;
3. the measurement effort: the fewest configurations with which the bound reaches the baseline's
   ``n``-configuration predicted RMS (as a share of ``n``), and with which the V design does; then, on
   both figures, the same for remove-and-replace on V from paper 004's random start alone and for the
   default selector on three criteria: the TCP (V), the reflector (the held-out figure) and TCP +
   reflector (``W = (W_tcp + W_reflector) / 2``).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from pipeline.calibration import design as ds
from pipeline.calibration import design_bound as db
from pipeline.calibration import design_rounding as dr
from pipeline.calibration import indices as ix
from pipeline.calibration import measure as ms
from pipeline.calibration import stage as st
from pipeline.calibration import task_space as ts
from pipeline.core.blas import single_thread_blas
from pipeline.papers.calib_design import study_pool

GAIN_FACTOR = 0.85        # the acceptance: >= 15 % lower RMS
PREDICTION_FACTOR = 1.2   # the acceptance's predicted/actual bound
EFFORT_SHARE = 0.60       # the acceptance: the baseline's RMS with <= 60 % of the measurements
BASELINES = ("every (N/n)-th", "random", "O3 remove-and-replace")


def _um(v: float) -> str:
    return f"{1e6 * math.sqrt(v):.2f}"


def robot_case(name: str, a: argparse.Namespace) -> dict:
    t0 = time.perf_counter()
    pool = study_pool(name, a.n, True, 13, a.candidates, a.region_poses)
    G, p, rng = pool.cs.G, pool.basis.shape[1], pool.rng
    spec_tcp = ts.task_space_spec(pool.mm, pool.Qw, pool.basis, "tcp")
    spec_v = ts.task_space_spec(pool.mm, pool.Qw, pool.basis, st.Config().design_figure)    # the default design's
    weights = {"TCP over the working region (V)": spec_tcp.weight_matrix(p),
               "reflector at the working configurations (study's held-out figure)":
               db.reflector_weight(pool.robot, pool.Qw, pool.basis)}
    # the default design (V on the stage's default figure, TCP + reflector): remove-and-replace from a random
    # start (the stream's first draw, as before) and from the rounded optimal approximate design, the better
    # one (design_rounding); the same stream after it
    designs = {"V design (default)": dr.approximate_remove_and_replace(G, spec_v, a.n, rng,
                                                                                          positions=pool.cs.Y),
               "every (N/n)-th": ds.linear_scan_design(G, ix.IndexSpec("O3"), a.n),
               "random": ds.random_design(G, ix.IndexSpec("O3"), a.n, rng),
               "O3 remove-and-replace": ds.remove_and_replace(G, ix.IndexSpec("O3"), a.n, rng, positions=pool.cs.Y)}
    sel = {k: r.selected for k, r in designs.items()}
    large = None
    if a.large_pool:
        cfg = st.Config(candidates="random", n_random_candidates=a.large_pool)
        large = st.build_candidates(pool.robot, cfg, pool.basis, np.random.default_rng([7, a.n, a.large_pool]))
    # the V design at fewer configurations, for the effort question (own stream per size)
    sizes = range(ms.min_configurations(p) + 1, a.n + 1)
    opt_v = db.optimal_approximate_design(G, spec_v.weight_matrix(p), tol=dr.START_TOL,
                                          max_iterations=dr.START_MAX_ITERATIONS)
    rr_sizes = {k: dr.approximate_remove_and_replace(G, spec_v, k, np.random.default_rng([7, k, 1]),
                                                     positions=pool.cs.Y, approximate=opt_v).selected for k in sizes}
    print(f"\n## {name}: {len(pool.cs)} candidates (the calib-design study's pool), {len(pool.Qw)} working "
          f"configurations in the {pool.region.describe()}, {p} identifiable parameters, n = {a.n}")
    out = {}
    for wname, W in weights.items():
        out[wname] = _figure(wname, W, G, sel, rr_sizes, large, a)
    out["effort"] = _effort_by_criterion(pool, G, weights, sel, sizes, a)
    print(f"\n({name}: {time.perf_counter() - t0:.0f} s)")
    return out


def _effort_by_criterion(pool, G: np.ndarray, weights: dict, sel: dict, sizes: range, a) -> dict:
    """Configurations each design needs to reach each baseline's ``n``-configuration predicted RMS on
    each figure: V on the TCP from a random start only (paper 004's start, the previous default), and
    the default selector (approximate start) on the TCP, on the reflector and on TCP + reflector
    (``W = (W_tcp + W_reflector) / 2``, the default); with the bound of each figure."""
    n, p = a.n, pool.basis.shape[1]
    Jt = ts.tcp_jacobian(pool.mm, pool.Qw, pool.basis)
    Jr = db.reflector_jacobian(pool.robot, pool.Qw, pool.basis)
    nw = len(pool.Qw)
    criteria = {"TCP (V)": ix.IndexSpec("V", working_jacobian=Jt, n_working=nw),
                "reflector": ix.IndexSpec("V", working_jacobian=Jr, n_working=nw),
                "TCP + reflector": ix.IndexSpec("V", working_jacobian=np.vstack([Jt, Jr]), n_working=2 * nw)}
    runs: dict[str, dict[int, np.ndarray]] = {
        "TCP (V) criterion, random start only (the previous default)": {k: ds.remove_and_replace(
            G, criteria["TCP (V)"], k, np.random.default_rng([7, k, 1]), positions=pool.cs.Y).selected for k in sizes}}
    for cname, spec in criteria.items():
        opt = db.optimal_approximate_design(G, spec.weight_matrix(p), tol=dr.START_TOL,
                                            max_iterations=dr.START_MAX_ITERATIONS)
        runs[f"{cname} criterion, approximate start" + (" (default)" if cname == "TCP + reflector" else "")] = {
            k: dr.approximate_remove_and_replace(G, spec, k, np.random.default_rng([7, k, 1]), positions=pool.cs.Y,
                                                 approximate=opt).selected for k in sizes}
    figs = dict(zip(("TCP", "reflector"), weights.values(), strict=True))
    bounds = {f: db.optimal_approximate_design(G, W, tol=a.tol) for f, W in figs.items()}
    _rounding_table(G, criteria, bounds, figs, [k for k in a.compare_sizes if k in sizes], pool.cs.Y)
    base = {(f, b): db.design_value(G, W, sel[b]) for f, W in figs.items() for b in ("every (N/n)-th",
                                                                                     "O3 remove-and-replace")}
    print(f"\n### measurement effort by criterion: configurations to reach the baseline's {n}-configuration "
          f"predicted RMS (share of {n}; acceptance <= {100 * EFFORT_SHARE:.0f} % = "
          f"{math.floor(EFFORT_SHARE * n + 1e-9)}), and the predicted RMS at {n} [µm]")
    cols = [(f, b) for f in figs for b in ("every (N/n)-th", "O3 remove-and-replace")]
    print("| design | " + " | ".join(f"{f} vs {b} ({_um(base[(f, b)])} µm)" for f, b in cols)
          + f" | TCP at {n} | reflector at {n} |")
    print("|---|" + "---|" * (len(cols) + 2))

    def cell(k: int | None) -> str:
        return f"{k} ({100 * k / n:.0f} %)" if k else f"> {n}"

    out = {}
    print("| bound (any design of the pool) | " + " | ".join(
        cell(db.configurations_to_reach(bounds[f], base[(f, b)])) for f, b in cols) + " | "
        + " | ".join(_um(bounds[f].exact_bound(n)) for f in figs) + " |")
    for label, by_size in runs.items():
        need = {}
        for f, b in cols:
            reach = [k for k in sizes if db.design_value(G, figs[f], by_size[k]) <= base[(f, b)]]
            need[(f, b)] = reach[0] if reach else None
        out[label] = need
        print(f"| {label} | " + " | ".join(cell(need[c]) for c in cols) + " | "
              + " | ".join(_um(db.design_value(G, figs[f], by_size[n])) for f in figs) + " |")
    return out


def _figure(wname: str, W: np.ndarray, G: np.ndarray, sel: dict, rr_sizes: dict, large, a) -> dict:
    n = a.n
    t = time.perf_counter()
    opt = db.optimal_approximate_design(G, W, tol=a.tol)
    t_opt = time.perf_counter() - t
    if not opt.converged:
        raise SystemExit(f"multiplicative algorithm stopped at gap {opt.gap:.2e} > tol {a.tol:.1e}")
    Vb = opt.exact_bound(n)
    V = {k: db.design_value(G, W, s) for k, s in sel.items()}
    print(f"\n### {wname}")
    print(f"optimal approximate design: {opt.iterations} multiplicative iterations ({t_opt:.1f} s), "
          f"certificate max_i d_i / V(w) - 1 = {opt.gap:.1e} <= {a.tol:.0e}, {opt.support().size} candidates "
          f"carry weight; bound V >= V*/n for every {n}-configuration design of the pool")
    if large is not None:
        opt_l = db.optimal_approximate_design(large.G, W, tol=a.large_tol)
        print(f"same bound from a larger pool, {len(large)} random feasible candidates: "
              f"{_um(opt_l.exact_bound(n))} µm ({_um(Vb)} µm from the study's pool; gap {opt_l.gap:.1e})")
    print("| design | predicted RMS sqrt(V) [µm] | V / V_bound | largest possible gain of any design over it |")
    print("|---|---|---|---|")
    print(f"| bound: any {n} configurations of the pool | {_um(Vb)} | 1.000 | - |")
    for k, v in V.items():
        gain = "-" if k.startswith("V design") else f"{100 * (1 - math.sqrt(Vb / v)):.1f} %"
        print(f"| {k} | {_um(v)} | {v / Vb:.3f} | {gain} |")
    v_key = next(iter(V))
    print("expected gain of the V design: " + ", ".join(
        f"{100 * (1 - math.sqrt(V[v_key] / V[b])):.1f} % over {b}" for b in BASELINES))

    # per-seed spread, linearised: each design's own noise, independent draws
    rng = np.random.default_rng([15, n, len(W)])
    C = {k: np.linalg.inv(db.exact_information(G, s)) for k, s in sel.items()}
    C["bound"] = np.linalg.inv(n * db.information(G, opt.weights))
    draws = {k: db.rms_samples(c, W, a.samples, rng) for k, c in C.items()}
    print(f"\nper-seed spread ({a.samples} draws per design; RMS of the realised error, linearised): "
          f"p = P(RMS <= {GAIN_FACTOR:.2f} RMS_baseline) on one seed")
    print(f"| design | vs baseline | one seed p | all {a.seeds} seeds p^{a.seeds} | expected seeds of {a.seeds} |")
    print("|---|---|---|---|---|")
    probs = {}
    kth, o3 = "every (N/n)-th", "O3 remove-and-replace"
    for dk, label in ((v_key, "the V design (default)"), ("bound", "a design AT the bound")):
        for b in BASELINES:
            probs[(label, b)] = db.probability_below(draws[dk], draws[b], GAIN_FACTOR)
        both = float(np.mean((draws[dk] <= GAIN_FACTOR * draws[kth]) & (draws[dk] <= GAIN_FACTOR * draws[o3])))
        probs[(label, "both")] = both
        for b in (*BASELINES, "both"):
            pr = probs[(label, b)]
            what = f"{kth} AND {o3} (the acceptance)" if b == "both" else b
            print(f"| {label} | {what} | {pr:.3f} | {pr ** a.seeds:.1e} | {a.seeds * pr:.1f} |")
    q = {k: np.quantile(d, [0.1, 0.9]) * 1e6 for k, d in draws.items()}
    print("realised RMS, 10-90 % of the seeds [µm]: " + ", ".join(f"{k} {v[0]:.1f}..{v[1]:.1f}" for k, v in q.items()))
    ratio = math.sqrt(V[v_key]) / draws[v_key]
    p_ratio = float(np.mean(np.abs(np.log(ratio)) <= math.log(PREDICTION_FACTOR)))
    print(f"predicted/actual of the V design within {PREDICTION_FACTOR} (either way) on one seed: {p_ratio:.3f}, "
          f"on all {a.seeds} seeds: {p_ratio ** a.seeds:.1e} (noise alone, exact linear model)")
    scale = min(db.rms_scale_needed(draws["bound"], draws[b], GAIN_FACTOR, a.seeds) for b in (kth, o3))
    print(f"to pass on all {a.seeds} seeds against both with probability 0.5, a design would need a predicted RMS "
          f"of {scale:.2f} x the bound ({100 * (1 - scale):.0f} % below what any design of the pool can reach)")

    # measurement effort
    print(f"\nmeasurement effort to reach the baseline's {n}-configuration predicted RMS (acceptance: "
          f"<= {100 * EFFORT_SHARE:.0f} % = {math.floor(EFFORT_SHARE * n + 1e-9)} configurations)")
    effort = {}
    for b in ("every (N/n)-th", "O3 remove-and-replace"):
        k_min = db.configurations_to_reach(opt, V[b])
        reach = [k for k, s in sorted(rr_sizes.items()) if db.design_value(G, W, s) <= V[b]]
        k_rr = reach[0] if reach else None
        verdict = ("even the bound needs more: unreachable" if k_min > EFFORT_SHARE * n
                   else "reachable in principle")
        rr_text = (f"the V design needs {k_rr} ({100 * k_rr / n:.0f} %)" if k_rr
                   else f"the V design does not reach it with <= {n}")
        print(f"- {b} ({_um(V[b])} µm): the bound needs >= {k_min} configurations ({100 * k_min / n:.0f} %, "
              f"{verdict}); {rr_text}")
        effort[b] = (k_min, k_rr)
    return {"bound": Vb, "values": V, "probabilities": probs, "effort": effort, "gap": opt.gap}


def _rounding_table(G: np.ndarray, criteria: dict, bounds: dict, figs: dict, sizes: list[int], Y) -> None:
    """Each criterion's own value at a few sizes: remove-and-replace from paper 004's random start,
    the efficient rounding of the optimal approximate design, that start polished by
    remove-and-replace, the default (the better of the two runs) and the bound of the criterion."""
    p = G.shape[2]
    print("\n### rounding the optimal approximate design: each criterion's predicted RMS sqrt(V) [µm] "
          "(in brackets V / bound)")
    print("| criterion | n | bound V*/n | random start | rounded start | rounded + polished "
          "| default (better of both) |")
    print("|---|---|---|---|---|---|---|")
    for cname, spec in criteria.items():
        W = spec.weight_matrix(p)
        bound = (bounds["TCP"] if cname == "TCP (V)" else bounds["reflector"] if cname == "reflector"
                 else db.optimal_approximate_design(G, W, tol=1e-4))
        opt = db.optimal_approximate_design(G, W, tol=dr.START_TOL, max_iterations=dr.START_MAX_ITERATIONS)
        for k in sizes:
            vb = bound.exact_bound(k)
            plain = ds.remove_and_replace(G, spec, k, np.random.default_rng([7, k, 1]), positions=Y).selected
            start = dr.rounded_start(opt.weights, k)
            polished = dr.approximate_remove_and_replace(G, spec, k, np.random.default_rng([7, k, 1]), positions=Y,
                                                         restarts=0, approximate=opt).selected
            default = dr.approximate_remove_and_replace(G, spec, k, np.random.default_rng([7, k, 1]), positions=Y,
                                                        approximate=opt).selected
            cells = [f"{_um(v)} ({v / vb:.3f})" for v in (db.design_value(G, W, s) for s in (plain, start, polished,
                                                                                            default))]
            print(f"| {cname} | {k} | {_um(vb)} | " + " | ".join(cells) + " |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="bench_design_bound")
    ap.add_argument("--robots", nargs="+", default=["rx130l", "staubli_tx40"])
    ap.add_argument("--n", type=int, default=32)
    ap.add_argument("--candidates", type=int, default=1500, help="the calib-design study's --quick pool")
    ap.add_argument("--region-poses", type=int, default=300)
    ap.add_argument("--large-pool", type=int, default=5000,
                    help="also bound on this many random candidates (0: skip; the stage's random default: 20000)")
    ap.add_argument("--large-tol", type=float, default=1e-3, help="certificate gap on the larger pool")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--samples", type=int, default=200_000)
    ap.add_argument("--tol", type=float, default=1e-4, help="equivalence-theorem gap of the certificate")
    ap.add_argument("--compare-sizes", type=int, nargs="+", default=[16, 19, 20, 24, 32],
                    help="sizes of the rounding comparison")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    with single_thread_blas():
        for name in a.robots:
            robot_case(name, a)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
