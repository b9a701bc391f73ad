"""Speed of paper 003's searches with incremental updates, as ratios against baselines run here.

Run: ``.venv/bin/python benchmarks/bench_paper_003.py [n_select] [pool]`` (defaults 150, 175: the
paper's 500 of 583 scaled down so that the baselines finish in a minute on a shared machine).

Baseline: :func:`pipeline.calibration.design.bsaa` / :func:`~pipeline.calibration.design.detmax`
(index from the information matrix after each move; Od recomputed from the selected points for
every candidate) on the same Jacobian blocks and points. Ours:
:mod:`pipeline.papers.calib_003_search` (rank-3 updates of M, log-determinants for O1, pruned
eigenvalues for O3, K-nearest-neighbour rows updated in O(n) per move). Both run the paper's
schedule (T 1e20 -> 1e-50, cooling 0.98: 7979 moves) or Mitchell's excursions; the O3 values reached
are printed as a check (same index definition in both).
"""

from __future__ import annotations

import sys
import time

import numpy as np
from bench_help import exit_on_help

from pipeline.calibration import design as ds
from pipeline.calibration import indices as ix
from pipeline.papers import calib_003_search as ps


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 150
    N = int(sys.argv[2]) if len(sys.argv) > 2 else 175
    rng = np.random.default_rng(0)
    p = 33
    J = rng.normal(size=(N, 3, p)) * np.geomspace(0.05, 20.0, p)
    P = rng.uniform(0.0, 1500.0, (N, 3))
    print(f"paper 003 searches, {n} of {N} poses, {p} parameters")
    print("| search | index | baseline [s] | ours [s] | speed-up | O3 baseline | O3 ours |")
    print("|---|---|---|---|---|---|---|")
    for method, base_fn, our_fn in (("bsaa", ds.bsaa, ps.bsaa), ("detmax", ds.detmax, ps.detmax)):
        for name in ("O3", "Oc"):
            spec = ix.IndexSpec(name, knn=3)
            t0 = time.perf_counter()
            base = base_fn(J, spec, n, np.random.default_rng(1), positions=P)
            t_base = time.perf_counter() - t0
            t0 = time.perf_counter()
            ours = our_fn(J, P, name, n, np.random.default_rng(1), ps.OcScale.literal())
            t_ours = time.perf_counter() - t0
            o3_base = ps.index_values(J, P, base.selected)["O3"]
            o3_ours = ps.index_values(J, P, ours.selected)["O3"]
            print(f"| {method} | {name} | {t_base:.2f} | {t_ours:.2f} | {t_base / max(t_ours, 1e-9):.1f} | "
                  f"{o3_base:.4g} | {o3_ours:.4g} |")


if __name__ == "__main__":
    exit_on_help(__doc__)
    main()
