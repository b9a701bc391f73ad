"""Held-out figures of a recorded calibration through the runner, under the splits a reader may
choose, each run with the defaults as a user makes it: the split's training poses as
``calibration.measurements_csv``, its held-out poses as ``calibration.validation_csv``,
``python -m pipeline run --stages calibration`` in a fresh interpreter (the model chosen on the
training poses alone, ``parameters: auto``).

Run: ``.venv/bin/python benchmarks/bench_heldout_protocols.py [ur10 | ROBOT_DIR RECORD.csv]
[--protocols loo,contiguous,interleaved,spatial] [--folds 5] [--jobs 2]`` (default ``ur10``:
FIGAROH's UR10 6-D record, ``data/figaroh_ur10_mocap``, its URDF through ``robot init``).

Splits: ``loo`` leaves out one pose per run; ``contiguous`` ``--folds`` blocks of consecutive
poses (the order of the file); ``interleaved`` every ``--folds``-th pose; ``spatial`` the k-means
groups in joint space of the model selection (:func:`pipeline.calibration.crossval.spatial_folds`).
Printed per split: the runs and their exit codes, the models chosen, the RMS position (and
orientation) error over every held-out pose (each run's ``heldout_rms_*_all_poses_after_*``, the
readings the held-out screen left out included) and the run of the largest actual/predicted
against its bound (its split and RMS error). On the UR10 record FIGAROH 1.0.2's fits of the same
splits (the ``bench`` extra) are printed beside, measured in the same run, with the ratios and
FIGAROH's errors on the poses of that run.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from bench_calibration import HAVE_FIGAROH, figaroh_ur10_folds, ur10_robot
from bench_help import exit_on_help

from pipeline.calibration import measure as ms
from pipeline.calibration.crossval import spatial_folds
from pipeline.core.config import REPO_ROOT
from pipeline.robot.model import RobotModel

PROTOCOLS = ("loo", "contiguous", "interleaved", "spatial")


@dataclass
class HeldOutRun:
    """One runner run of a split: exit code, held-out poses, their RMS errors and the gate's figures."""

    code: int
    n_poses: int
    rms_position_m: float | None
    rms_orientation_rad: float | None
    parameters: str | None
    ratio: float | None
    ratio_bound: float | None


def fold_of_pose(protocol: str, Q: np.ndarray, folds: int) -> np.ndarray:
    """``(n,)`` split index of every pose of the record under ``protocol`` (module docstring)."""
    n = len(Q)
    if protocol == "loo":
        return np.arange(n)
    if protocol == "contiguous":
        return np.minimum(np.arange(n) * folds // n, folds - 1)
    if protocol == "interleaved":
        return np.arange(n) % folds
    if protocol == "spatial":
        return spatial_folds(Q, folds)
    raise SystemExit(f"--protocols: unknown split {protocol!r} (one of {', '.join(PROTOCOLS)})")


def summary_of(run_dir: Path) -> dict | None:
    """The calibration summary of a run folder (kept for inspection when a gate failed)."""
    for name in ("calibration", "calibration.rejected"):
        found = sorted(run_dir.glob(f"*/{name}/summary.json"))
        if found:
            return json.loads(found[0].read_text())
    return None


def run_split(robot_dir: Path, train: Path, held: Path, out: Path) -> HeldOutRun:
    """``python -m pipeline run --stages calibration`` on one split, one BLAS thread."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "pipeline", "run", "--stages", "calibration", "--set", f"robot={robot_dir}",
           "--set", f"calibration.measurements_csv={train}", "--set", f"calibration.validation_csv={held}",
           "--out", str(out)]
    code = subprocess.run(cmd, cwd=REPO_ROOT, env=env, capture_output=True, text=True).returncode
    s = summary_of(out) or {}
    test = s.get("actual_over_predicted_test") or {}
    return HeldOutRun(code, int(s.get("heldout_n_poses") or 0), s.get("heldout_rms_position_error_all_poses_after_m"),
                      s.get("heldout_rms_orientation_error_all_poses_after_rad"), s.get("parameters"),
                      s.get("actual_over_predicted"), test.get("threshold"))


def pooled_rms(values: list[float | None], weights: list[int]) -> float | None:
    """RMS over every pose of per-run RMS figures weighted by their poses; None if any is missing."""
    if not values or any(v is None for v in values):
        return None
    return float(np.sqrt(sum(w * v ** 2 for v, w in zip(values, weights, strict=True)) / sum(weights)))  # type: ignore[operator]


def bench_protocol(protocol: str, robot_dir: Path, header: str, rows: list[str], Q: np.ndarray, folds: int,
                   jobs: int, work: Path) -> tuple[np.ndarray, list[HeldOutRun]]:
    """Every split of ``protocol`` through the runner, ``jobs`` at a time."""
    split = fold_of_pose(protocol, Q, folds)
    tasks = []
    for f in np.unique(split):
        held = set(np.flatnonzero(split == f).tolist())
        train, val = work / f"{protocol}{f}_train.csv", work / f"{protocol}{f}_held.csv"
        train.write_text("\n".join([header] + [r for i, r in enumerate(rows) if i not in held]) + "\n")
        val.write_text("\n".join([header] + [rows[i] for i in sorted(held)]) + "\n")
        tasks.append((robot_dir, train, val, work / f"{protocol}{f}_run"))
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        runs = list(pool.map(lambda t: run_split(*t), tasks))
    return split, runs


def report(protocol: str, runs: list[HeldOutRun], peer: list[tuple[int, float, float, float]] | None) -> None:
    """One line per split: exit codes, models chosen, pooled held-out RMS, the run of the largest
    actual/predicted relative to its bound; with ``peer`` (FIGAROH per split, the runs' order) its
    pooled figures and its errors on that run's poses."""
    codes = collections.Counter(r.code for r in runs)
    chosen = collections.Counter(r.parameters for r in runs)
    weights = [r.n_poses for r in runs]
    pos = pooled_rms([r.rms_position_m for r in runs], weights)
    rot = pooled_rms([r.rms_orientation_rad for r in runs], weights)
    scored = [(r.ratio / (r.ratio_bound or 1.0), i) for i, r in enumerate(runs) if r.ratio is not None]
    worst = max(scored)[1] if scored else None
    line = (f"{protocol}: {len(runs)} runs, exit codes {dict(sorted(codes.items()))}, chose "
            f"{dict(chosen.most_common())}; over all {sum(weights)} held-out poses: position "
            f"{'n/a' if pos is None else f'{pos * 1e3:.3f} mm'}")
    if rot is not None:
        line += f", orientation {np.degrees(rot):.3f} deg"
    if worst is not None:
        w = runs[worst]
        line += (f"; largest actual/predicted {w.ratio:.2f} (its bound {w.ratio_bound or float('nan'):.2f}, "
                 f"split {worst}: {1e3 * (w.rms_position_m or float('nan')):.3f} mm)")
    print(line)
    if peer is not None and pos is not None:
        f_pos = pooled_rms([p for _, p, _, _ in peer], [k for k, *_ in peer])
        f_rot = pooled_rms([r for _, _, r, _ in peer], [k for k, *_ in peer])
        assert f_pos is not None and f_rot is not None
        ratio_rot = f", orientation {rot / f_rot:.3f}" if rot is not None else ""
        print(f"  FIGAROH 1.0.2, the same splits ({sum(s for *_, s in peer):.1f} s): {f_pos * 1e3:.3f} mm / "
              f"{np.degrees(f_rot):.3f} deg; ours / FIGAROH position {pos / f_pos:.3f}{ratio_rot}")
        if worst is not None:
            _, p_w, r_w, _ = peer[worst]
            print(f"  FIGAROH on split {worst}'s poses: {1e3 * p_w:.3f} mm / {np.degrees(r_w):.3f} deg")


def main() -> None:
    exit_on_help(__doc__)
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("record", nargs="*", default=["ur10"])
    parser.add_argument("--protocols", default=",".join(PROTOCOLS))
    parser.add_argument("--folds", type=int, default=5)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        ur10 = args.record == ["ur10"]
        if ur10:
            robot_dir = work / "ur10"
            robot_dir.mkdir()
            robot, csv = ur10_robot(robot_dir)
            figaroh_header, *figaroh_rows = (REPO_ROOT / "data" / "figaroh_ur10_mocap" / "calibration.csv"
                                             ).read_text().splitlines()
        elif len(args.record) == 2:
            robot_dir, csv = Path(args.record[0]).resolve(), Path(args.record[1]).resolve()
            robot = RobotModel.load(robot_dir)
        else:
            raise SystemExit("give ur10, or a robot folder and a record CSV")
        header, *rows = csv.read_text().splitlines()
        Q = ms.read_csv(csv, robot).Q
        print(f"record {csv.name}: {len(rows)} poses, robot {robot_dir.name}, {args.folds} folds, "
              f"{args.jobs} runs at a time")
        for protocol in args.protocols.split(","):
            split, runs = bench_protocol(protocol, robot_dir, header, rows, Q, args.folds, args.jobs, work)
            peer = None
            if ur10 and HAVE_FIGAROH:
                try:
                    peer = figaroh_ur10_folds(work, figaroh_header, figaroh_rows, split)
                except Exception as exc:   # a peer's failure is a result to print, not a crash
                    print(f"  FIGAROH failed: {type(exc).__name__}: {exc}")
            report(protocol, runs, peer)


if __name__ == "__main__":
    main()
