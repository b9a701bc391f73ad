"""Sweep on a Dask cluster against the local run: same table, and the wall times.

Run: ``.venv/bin/python benchmarks/bench_sweep.py [--seeds 0-19] [--stages calibration] [--workers 2]``
(needs ``dask[distributed]``, the ``cluster`` extra).

Runs the quick profile (``configs/quick.yaml``) over the seeds twice into two fresh directories:
locally with joblib (``--workers`` processes) and on a ``distributed.LocalCluster`` with as many
single-threaded worker processes. Prints whether the two tables are equal (every column except
wall-clock timings), the calibration held-out RMS spread (median, 95th percentile) and the wall
time of each route with their ratio.
"""

from __future__ import annotations

import argparse
import csv
import io
import tempfile
import time
from pathlib import Path

import distributed

from pipeline.core.config import REPO_ROOT
from pipeline.run.sweep import SweepSpec, parse_seeds, run_sweep
from pipeline.run.sweep_table import is_timing_column, numeric_values, spread

FIGURE = "calibration.heldout_rms_position_error_after_m"


def _table(path: Path) -> list[dict[str, str]]:
    rows = list(csv.DictReader(io.StringIO(path.read_text())))
    return [{k: v for k, v in r.items() if not is_timing_column(k)} for r in rows]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="0-19")
    ap.add_argument("--stages", default="calibration")
    ap.add_argument("--workers", type=int, default=2)
    ns = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        def spec(sub: str) -> SweepSpec:
            return SweepSpec(seeds=parse_seeds(ns.seeds), robots=[None], out_dir=Path(tmp) / sub,
                             config_path=str(REPO_ROOT / "configs" / "quick.yaml"), stages=ns.stages)

        t0 = time.perf_counter()
        rows_local, paths_local = run_sweep(spec("local"), jobs=ns.workers)
        t_local = time.perf_counter() - t0
        with distributed.LocalCluster(n_workers=ns.workers, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cluster, distributed.Client(cluster) as client:
            t0 = time.perf_counter()
            _rows, paths_dask = run_sweep(spec("dask"), scheduler=client)
            t_dask = time.perf_counter() - t0
        same = _table(paths_local["csv"]) == _table(paths_dask["csv"])
        n_ok = sum(r.get("status") == "ok" for r in rows_local)
        print(f"{len(rows_local)} runs ({n_ok} ok), stages {ns.stages}: tables equal (timings excluded): {same}")
        s = spread(numeric_values(rows_local, FIGURE))
        if s["n"]:
            print(f"{FIGURE}: median {s['median'] * 1e6:.1f} um, 95th percentile {s['p95'] * 1e6:.1f} um, "
                  f"max {s['max'] * 1e6:.1f} um over {int(s['n'])} hidden robots")
        print(f"wall time: joblib ({ns.workers} processes) {t_local:.1f} s, LocalCluster ({ns.workers} workers) "
              f"{t_dask:.1f} s, ratio dask / joblib {t_dask / t_local:.2f}")


if __name__ == "__main__":
    main()
