"""``report.md`` of a run: every finished stage directory gathered in stage order.

The headline (:mod:`pipeline.run.headline`: the figures that matter against their gates, the
assumptions still in force, the warnings) opens it. Below it, each stage's own tables
(``report.md`` of the stage) come first, its raw ``summary.json`` folded below them, then its
figures linked relatively; stages that are stale (from an earlier run, or failed in this one) are
marked as such, and a failed run says so at the top.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pipeline
from pipeline.core import artefacts
from pipeline.core import config as config_mod
from pipeline.core.config import RunConfig
from pipeline.core.errors import PipelineError
from pipeline.run import stage_io
from pipeline.run.headline import headline_markdown, read_headline
from pipeline.summaries import StageSummary


def _fmt(value: object) -> str:
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)):
        if len(value) > 12:
            return "[" + ", ".join(_fmt(v) for v in value[:12]) + f", … ({len(value)} items)]"
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_fmt(v)}" for k, v in value.items()) + "}"
    return str(value).replace("|", "\\|").replace("\n", " ")


def _flatten(d: dict, prefix: str = "") -> list[tuple[str, Any]]:
    rows: list[tuple[str, Any]] = []
    for key, value in d.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            rows.extend(_flatten(value, name + "."))
        else:
            rows.append((name, value))
    return rows


def summary_table(summary: dict) -> str:
    """Markdown table ``| key | value |`` of a (nested) summary dict."""
    rows = _flatten(summary)
    if not rows:
        return "_no summary figures_\n"
    lines = ["| quantity | value |", "|---|---|"]
    lines += [f"| {k} | {_fmt(v)} |" for k, v in rows]
    return "\n".join(lines) + "\n"


def _summary(stage_dir: Path) -> dict:
    path = stage_dir / stage_io.SUMMARY
    try:
        data = artefacts.read_json(path) if path.exists() else {}
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _failed_gates(summary: StageSummary) -> str:
    """The messages of the failed gates recorded by :class:`pipeline.quality.QualityGates`."""
    failed = [str(c.message or c.name) for c in summary.gate_checks() if not c.passed]
    return "; ".join(failed) or "see summary.json"


def one_line_error(exc: BaseException) -> str:
    if isinstance(exc, PipelineError):
        return exc.one_line()
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted (Ctrl-C)"
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _stale_note(stage_dir: Path, current: Sequence[str], expected: Mapping[str, str],
                failure: tuple[str, str] | None) -> str | None:
    """Why the results in ``stage_dir`` are not this run's (an italic note), or None."""
    name = stage_dir.name
    if current and name not in current:
        return "_from an earlier run: not part of this run, its inputs may differ_"
    if failure is not None and name == failure[0]:
        return "_stale: this stage FAILED in this run; the results below are from an earlier run_"
    if name in expected and stage_io.read_inputs_hash(stage_dir) != expected[name]:
        return "_stale: from an earlier run with different inputs (not re-run in this run)_"
    return None


def write_report(run_dir: Path, cfg: RunConfig | None = None, current: Sequence[str] = (),
                 expected: Mapping[str, str] | None = None, failure: tuple[str, str] | None = None) -> Path:
    """Gather every finished stage directory of ``run_dir`` into ``report.md``.

    Figures are linked relatively (``<stage>/<name>.png``). Stage directories that were not part
    of this run (``current``) are marked as coming from an earlier run, and so is every stage whose
    saved ``inputs.sha256`` differs from ``expected[stage]`` (this run's inputs hash: the stage
    failed or was not re-run after a failure). ``failure``: ``(stage, one-line error)`` of a
    failed run, stated at the top.
    """
    run_dir = Path(run_dir)
    expected = expected or {}
    lines = [f"# Run `{run_dir.name}`", ""]
    if failure is not None:
        stage, error = failure
        where = f" in stage `{stage}`" if stage else ""
        lines += [f"**FAILED{where}**: {' '.join(error.split())}", ""]
        if stage and (run_dir / f"{stage}.rejected").is_dir():
            lines += [f"The result that failed its quality gate is kept for inspection in `{stage}.rejected/` "
                      "(not handed on to later stages).", ""]
        lines += [
                  "`config.yaml` holds the configuration of this failed run; stages marked "
                  "_stale_ below show results of an earlier run.", ""]
    if cfg is not None:
        lines += [f"robot `{cfg.robot}` · seed {cfg.seed} · profile `{cfg.profile}` · "
                  f"pipeline {pipeline.__version__} · config in `config.yaml`", ""]
    names = [s for s in config_mod.stage_names() if (run_dir / s / stage_io.INPUTS_HASH).exists()]
    poor = [s for s in names if StageSummary.read(_summary(run_dir / s)).accepted_poor]
    if poor:
        lines += [f"**Results accepted with `--accept-poor`** (failed quality gates, handed on knowingly): "
                  f"{', '.join(f'`{s}`' for s in poor)}", ""]
    extra = sorted(p.name for p in run_dir.iterdir()
                   if p.is_dir() and not p.name.startswith(".") and p.name not in names
                   and (p / stage_io.INPUTS_HASH).exists())
    notes = {name: _stale_note(run_dir / name, current, expected, failure) for name in [*names, *extra]}
    lines += [headline_markdown(read_headline(run_dir, list(notes), [n for n, note in notes.items() if note])), ""]
    for name, note in notes.items():
        d = run_dir / name
        manifest = artefacts.read_json(d / stage_io.MANIFEST) if (d / stage_io.MANIFEST).exists() else {}
        lines += [f"## {name}", ""]
        if note:
            lines += [note, ""]
        if manifest.get("finished_utc"):
            lines += [f"finished {manifest['finished_utc']} in {manifest.get('duration_s', 0):.1f} s", ""]
        summary = artefacts.read_json(d / stage_io.SUMMARY) if (d / stage_io.SUMMARY).exists() else {}
        record = StageSummary.read(summary if isinstance(summary, dict) else {})
        if record.accepted_poor:
            lines += [f"**ACCEPTED POOR (`--accept-poor`)**: failed quality gate(s): {_failed_gates(record)}; "
                      "handed on knowingly", ""]
        report_md = d / stage_io.REPORT_MD
        stage_md = report_md.read_text(encoding="utf-8").rstrip() if report_md.exists() else ""
        if stage_md:  # the stage's own tables first; every headline figure folded below them
            lines += [stage_md, "", f"<details><summary>all figures of <code>{name}/summary.json</code></summary>",
                      "", summary_table(summary), "</details>", ""]
        else:
            lines += [summary_table(summary)]
        figures = manifest.get("figures") or sorted(p.name for p in d.glob("*.png"))
        for fig in figures:
            lines += [f"![{name}: {Path(fig).stem}]({name}/{fig})", ""]
    return artefacts.write_text(run_dir / "report.md", "\n".join(lines).rstrip() + "\n")
