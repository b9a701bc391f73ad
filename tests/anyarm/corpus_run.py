"""One corpus arm through ``robot init`` (no options), ``check`` and ``run`` of every stage, as a
new user would type them, in the corpus profile (``configs/corpus.yaml``) with every quality gate as
shipped (no ``--accept-poor``: a failed gate ends the run with exit 3); the row it gives is written
as JSON for ``tools/corpus_table.py`` (the table in ``docs/robots.md``)."""

from __future__ import annotations

import contextlib
import io
import json
import os
import resource
import time
from pathlib import Path
from typing import Any

from pipeline.cli import main
from pipeline.core.config import CONFIGS_DIR, REPO_ROOT
from pipeline.robot.model import RobotModel
from pipeline.robot.plausibility import placeholder_kind
from pipeline.robot.public_arms import PublicArm, arm_file

#: where the rows go (``tools/corpus_table.py`` reads them): $PIPELINE_CORPUS_DIR, else data/corpus
CORPUS_DIR = Path(os.environ.get("PIPELINE_CORPUS_DIR", REPO_ROOT / "data" / "corpus"))
CORPUS_CONFIG = CONFIGS_DIR / "corpus.yaml"


def _cpu_s() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def run_cli(args: list[str]) -> tuple[int, list[str]]:
    """Exit code and the error/warning lines of ``python -m pipeline ARGS`` (run in this process)."""
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            code = main(args)
        except SystemExit as exc:
            code = int(exc.code or 0)
        except Exception as exc:       # noqa: BLE001 (a crash is a result of the corpus: exit 1, one line)
            print(f"crash: {type(exc).__name__}: {' '.join(str(exc).split())[:300]}", file=err)
            code = 1
    lines = [line for line in (err.getvalue() + out.getvalue()).splitlines()
             if line.startswith(("error:", "warning:", "crash:", "quality gate failed:"))]
    return code, lines


def _summary(run_dir: Path, stage: str) -> dict[str, Any]:
    """A stage's summary: the accepted one, else the one its failed gate set aside (``STAGE.rejected``)."""
    for folder in (stage, f"{stage}.rejected"):
        path = run_dir / folder / "summary.json"
        if path.is_file():
            return json.loads(path.read_text())
    return {}


def _figures(run_dir: Path) -> dict[str, Any]:
    """The headline figures a table row shows (None where a stage did not run)."""
    model, cal, ident, control, traj = (_summary(run_dir, s) for s in ("model", "calibration", "identification",
                                                                       "control", "trajectory"))
    gates = [f"{stage}:{c.get('name')}" for stage in ("calibration", "identification", "control", "trajectory")
             for c in (_summary(run_dir, stage).get("quality_gates", {}) or {}).get("checks", [])
             if isinstance(c, dict) and not c.get("passed")]
    return {
        "reach_m": model.get("reach_m"), "moving_mass_kg": model.get("moving_mass_kg"),
        "placeholders": list(dict.fromkeys(k for k in map(placeholder_kind, map(str, model.get("assumptions", [])))
                                           if k)),
        "heldout_rms_after_m": cal.get("heldout_rms_position_error_after_m"),
        "calibration_dropped": cal.get("design_dropped_parameters"),
        "validation_rms_over_noise_max": max(ident.get("validation_rms_over_noise") or [float("nan")]),
        "path_error_none_over_elastic": (control.get("elastic_improvement") or {}).get(
            "path_error_max_none_over_elastic"),
        "cp_duration_s": traj.get("cp_duration_s"), "ptp_duration_s": traj.get("ptp_duration_s"),
        "failed_gates": gates,
    }


def run_arm(arm: PublicArm, work: Path, run: bool = True, stages: list[str] | None = None) -> dict[str, Any]:
    """Row of ``arm``: exit codes and first lines of ``robot init``, ``check`` and (``run``) ``run``, the
    headline figures and the CPU time; written to :data:`CORPUS_DIR` ``/<name>.json`` after a run of
    every stage (``stages`` None)."""
    source = arm_file(arm)
    if source is None:
        raise FileNotFoundError(f"{arm.source} not installed (the dev extra)")
    folder, runs = work / arm.name, work / "runs"
    cpu0, wall0 = _cpu_s(), time.perf_counter()
    row: dict[str, Any] = {"arm": arm.name, "source": arm.source, "format": arm.fmt, "file": arm.path}
    row["init_exit"], row["init_lines"] = run_cli(["robot", "init", str(source), "--out", str(folder / "robot.yaml")])
    common = ["--config", str(CORPUS_CONFIG), "--set", f"robot={folder}", "--set", f"name={arm.name}",
              "--out", str(runs), *(["--stages", ",".join(stages)] if stages else [])]
    if row["init_exit"] == 0:
        row["axes"] = RobotModel.load(folder).nq
        row["check_exit"], row["check_lines"] = run_cli(["check", *common])
        if run:
            row["run_exit"], row["run_lines"] = run_cli(["run", *common])
            row.update(_figures(runs / arm.name))
    row["cpu_s"], row["wall_s"] = _cpu_s() - cpu0, time.perf_counter() - wall0
    if run and stages is None:
        CORPUS_DIR.mkdir(parents=True, exist_ok=True)
        (CORPUS_DIR / f"{arm.name}.json").write_text(json.dumps(row, indent=1, default=str) + "\n")
    return row
