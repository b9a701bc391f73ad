"""Wall and CPU time of the default run (``python -m pipeline run``), per stage and in total, and
whether its figures match another run's.

Run: ``.venv/bin/python benchmarks/bench_run.py [--out DIR] [--baseline] [--compare RUN_DIR]
[--set key=value ...]`` (default: the default profile, RX130L, seed 0, into a fresh temporary
folder, with an empty compiled-code cache ``$PIPELINE_CACHE_DIR``, as a fresh clone has).

The run is made in this process (:func:`pipeline.run.runner.run_pipeline` with ``warm_up=True``, as the
CLI makes it: the background build of the stages' compiled code); the per-stage wall time is
each stage's ``manifest.json`` ``duration_s`` (first pass under ``first_pass/``, then the run's
own stages), the total is the wall and CPU time of the call (CPU: user + system of this process).
``--baseline`` makes the same run without the reuse of the filtered candidate grid
(:mod:`pipeline.calibration.grid_cache`): every pass filters it again, as before that cache existed.
``--compare RUN_DIR``: every stage's ``summary.json`` (both passes) against ``RUN_DIR``'s, except the
keys that are times (``*time_s``, ``timings_s``, ``runtime_s``, ``realtime_factor*``, ``speedup*``,
``*per_s``), with the runs folder of a path written as ``<runs>``: prints each differing figure, exit
code 1 when any differs; ``--compare RUN_DIR --existing MINE`` compares two finished runs only.
The target of the default run: at most 2.5 min on 2 cores (plus the install).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from pipeline.calibration import candidates as cd
from pipeline.calibration import grid_cache
from pipeline.core.config import load_config
from pipeline.run.runner import run_pipeline

TARGET_S = 150.0
_TIME_WORDS = ("time_s", "runtime_s", "realtime_factor", "speedup", "per_s", "duration_s", "cpu_ratio")


def _cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime + children.ru_utime + children.ru_stime


def _is_time(key: str) -> bool:
    """A summary key holding a time (or a rate measured in time), not a figure of the result."""
    parts = key.replace("[", ".").split(".")
    return any(part.startswith("timings") or any(w in part for w in _TIME_WORDS) for part in parts)


def _flatten(value: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(value, dict):
        out: dict[str, Any] = {}
        for k, v in value.items():
            out.update(_flatten(v, f"{prefix}.{k}" if prefix else str(k)))
        return out
    if isinstance(value, list):
        out = {}
        for i, v in enumerate(value):
            out.update(_flatten(v, f"{prefix}[{i}]"))
        return out
    return {prefix: value}


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def summaries(run_dir: Path) -> dict[str, Path]:
    """``pass/stage -> summary.json`` of a run folder (``first_pass/<name>/<stage>`` and ``<stage>``)."""
    found = {}
    for path in sorted(run_dir.rglob("summary.json")):
        rel = path.parent.relative_to(run_dir)
        if any(part.startswith(".") for part in rel.parts):
            continue
        found[str(rel)] = path
    return found


def compare(run_dir: Path, other: Path) -> int:
    """Print the figures (non-time summary values) that differ; return how many."""
    mine, theirs = summaries(run_dir), summaries(other)
    n_diff = 0
    for stage in sorted(set(mine) | set(theirs)):
        if stage not in mine or stage not in theirs:
            print(f"  {stage}: only in {'this run' if stage in mine else other}")
            n_diff += 1
            continue
        # paths inside the runs folder (the gravity model's copy) are compared relative to it
        a = _flatten(json.loads(mine[stage].read_text().replace(str(run_dir.parent.resolve()), "<runs>")))
        b = _flatten(json.loads(theirs[stage].read_text().replace(str(other.parent.resolve()), "<runs>")))
        keys = [k for k in sorted(set(a) | set(b)) if not _is_time(k)]
        diff = [k for k in keys if not _same(a.get(k), b.get(k))]
        print(f"  {stage}: {len(keys) - len(diff)} of {len(keys)} figures equal")
        for k in diff:
            print(f"    {k}: {a.get(k)!r} vs {b.get(k)!r}")
        n_diff += len(diff)
    return n_diff


def stage_times(run_dir: Path) -> list[tuple[str, float]]:
    """(pass/stage, duration_s) of every stage folder written, in the order they finished."""
    rows = []
    for manifest in run_dir.rglob("manifest.json"):
        rel = manifest.parent.relative_to(run_dir)
        if any(part.startswith(".") for part in rel.parts):
            continue
        data = json.loads(manifest.read_text())
        rows.append((data.get("finished_utc", ""), str(rel), float(data.get("duration_s", 0.0))))
    return [(name, duration) for _, name, duration in sorted(rows)]


def _without_grid_reuse(chain: cd.Chain, n_per_axis: Any = 13, margins: Any = None, chunk: int = 20_000,
                        progress: Any = None, cache_dir: Any = None) -> Any:
    return cd.filter_grid(chain, n_per_axis, margins, chunk=chunk, progress=progress)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=None, help="runs folder (default: a fresh temporary one)")
    parser.add_argument("--baseline", action="store_true", help="without the reuse of the filtered grid")
    parser.add_argument("--compare", type=Path, default=None, help="a run folder to compare the figures with")
    parser.add_argument("--existing", type=Path, default=None, help="with --compare: a finished run, no new run")
    parser.add_argument("--keep-cache", action="store_true", help="use $PIPELINE_CACHE_DIR as it is")
    parser.add_argument("--set", dest="overrides", action="append", default=[], help="config key=value")
    ns = parser.parse_args(argv)
    if ns.existing is not None:
        n_diff = compare(ns.existing, ns.compare)
        print(f"figures differing from {ns.compare}: {n_diff}")
        return 1 if n_diff else 0
    if not ns.keep_cache:
        os.environ["PIPELINE_CACHE_DIR"] = tempfile.mkdtemp(prefix="bench-run-cache-")
    if ns.baseline:
        grid_cache.filter_grid = _without_grid_reuse  # type: ignore[assignment]
    out = ns.out if ns.out is not None else Path(tempfile.mkdtemp(prefix="bench-run-"))
    cfg = load_config(None, ns.overrides)
    wall0, cpu0 = time.perf_counter(), _cpu_s()
    result = run_pipeline(cfg, out_root=out, warm_up=True, log=lambda line: print(f"  | {line}", file=sys.stderr))
    wall, cpu = time.perf_counter() - wall0, _cpu_s() - cpu0
    print(f"default run ({'baseline: grid filtered in every pass' if ns.baseline else 'as shipped'}), "
          f"{os.cpu_count()} cores, cache {os.environ.get('PIPELINE_CACHE_DIR')}")
    for name, duration in stage_times(result.run_dir):
        print(f"  {name:40s} {duration:8.1f} s")
    verdict = "within" if wall <= TARGET_S else "over"
    print(f"  {'total (wall)':40s} {wall:8.1f} s  ({verdict} the {TARGET_S:.0f} s target)")
    print(f"  {'total (CPU, user + system)':40s} {cpu:8.1f} s")
    print(f"run folder: {result.run_dir}")
    if ns.compare is not None:
        n_diff = compare(result.run_dir, ns.compare)
        print(f"figures differing from {ns.compare}: {n_diff}")
        return 1 if n_diff else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
