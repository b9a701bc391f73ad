"""The headline of a run: the figures that matter per stage, each against its gate or anchor.

Read from the stages' ``summary.json`` (nothing is recomputed), one row per figure:

* model: the robot (reach, moving mass, payload) against data-sheet scaling of serial arms
  (:mod:`pipeline.robot.plausibility`: the number of warnings);
* calibration: held-out TCP error (RMS) against the tracker noise and against the error the
  design predicted (actual / predicted);
* identification: validation torque RMS over the torque noise, worst joint, against its gate;
* control: the feedforward's gain, the largest TCP error on the ISO 9283 path without feedforward
  over that of the best feedforward variant;
* trajectory: CP duration against toppra, PtP duration and energy against ruckig, and the PtP
  move-and-settle time (rigid and elastic-joint feedforward) against ruckig's;
* every stage with quality gates: how many pass.

Each row states the ratio of its figure to its anchor (its own column), its verdict and the provenance
of its input (simulated, or the recorded file: the stage's typed record, ``summary.json``
``provenance``). The verdict is ``pass``/``FAIL`` of the figure's quality gate where it has one, else
``pass`` when the ratio is on the good side of its anchor (a feedforward gain above 1, a plan no
slower than its baseline) and ``warn`` when not; a row without an anchor to judge by (the held-out
error over the noise) leaves it empty. The run's ``provenance.json`` adds whether the second
calibration pass ran and why, and whether two different arms are combined (a recorded measurement
with a simulated one: a warning).
:func:`headline_markdown` opens ``report.md``
followed by the assumptions still in force and the warnings; :func:`print_headline` prints the
same table on the console. The rows each stage's summary gives: :mod:`.headline_rows`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from pipeline.core import artefacts
from pipeline.run import stage_io
from pipeline.run.headline_rows import (
    FAIL,
    PASS,
    SIMULATED,
    WARN,
    Row,
    provenance,
    stage_rows,
    typed_label,
)
from pipeline.stage_api import PROVENANCE_FILE, Provenance
from pipeline.summaries import IdentificationSummary, ModelSummary, StageSummary


@dataclass
class Headline:
    """The headline rows of a run, the assumptions still in force and the warnings."""

    run: str
    rows: list[Row] = field(default_factory=list)
    inputs: list[str] = field(default_factory=list)        # each stage's provenance, one sentence
    assumptions: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    @property
    def failed(self) -> bool:
        return any(r.verdict == FAIL for r in self.rows)


SIMULATED_ON_THE_MODEL = ("control", "trajectory")


def recorded_model_on_simulated_arm(stages: Sequence[str], model_data: str) -> str:
    """The input line of the stages simulated on the model a record identified: their arm is the run's
    hidden robot, drawn around robot.yaml's model, not the arm recorded (unless the record was made on
    that simulated arm, ``arm play``)."""
    return (f"{', '.join(stages)}: the simulated arm is the run's hidden robot, drawn around robot.yaml's model, "
            f"and the feedforward is the model from {model_data}; unless that record was made on this simulated "
            "arm (`arm play`), the two differ by what robot.yaml assumes, and these figures grade the recorded "
            "model on a robot.yaml arm")


def _read_summary(stage_dir: Path) -> dict:
    try:
        data = artefacts.read_json(stage_dir / stage_io.SUMMARY)
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _arms_combined(run_dir: Path) -> str:
    """The run's sentence on two different arms combined (``provenance.json``), or ""."""
    try:
        record = artefacts.read_json(run_dir / PROVENANCE_FILE)
    except (OSError, ValueError):
        return ""
    return str(record.get("arms_combined") or "") if isinstance(record, dict) else ""


def _second_pass_row(run_dir: Path, stages: Sequence[str]) -> Row | None:
    """Whether the second calibration pass ran, and why (``provenance.json`` of the run)."""
    try:
        record = artefacts.read_json(run_dir / PROVENANCE_FILE)
    except (OSError, ValueError):
        return None
    note = record.get("second_pass") if isinstance(record, dict) else None
    if not note or "calibration" not in stages:
        return None
    ran = not str(note).startswith("no ")
    return Row("calibration", "second calibration pass", "ran" if ran else "not run", str(note), "", "")


def read_headline(run_dir: Path, stages: Sequence[str], stale: Iterable[str] = ()) -> Headline:
    """The headline of ``run_dir`` from the ``summary.json`` of ``stages`` (in that order; stages
    without a summary are left out; ``stale``: stages whose results are from an earlier run)."""
    run_dir = Path(run_dir)
    stale = set(stale)
    headline = Headline(run_dir.name)
    model_data = SIMULATED
    on_recorded_model: list[str] = []
    for stage in stages:
        summary = _read_summary(run_dir / stage)
        if not summary:
            continue
        rows = stage_rows(stage, summary, stage in stale)
        common = StageSummary.read(summary)
        record = Provenance.from_dict(common.provenance)
        if stage == "identification":
            model_data = (provenance(IdentificationSummary.read(summary).data_source) if record is None
                          else typed_label(record) if record.recorded else SIMULATED)
        elif stage in SIMULATED_ON_THE_MODEL and model_data != SIMULATED:
            rows = [replace(r, source=f"{r.source}, model from {model_data}" if r.source else r.source)
                    for r in rows]
        headline.rows += rows
        if record is not None:
            headline.inputs.append(f"{stage}: {record.sentence()}")
            if stage in SIMULATED_ON_THE_MODEL and model_data != SIMULATED and record.simulated:
                on_recorded_model.append(stage)
        if stage == "calibration":
            second = _second_pass_row(run_dir, stages)
            headline.rows += [] if second is None else [second]
        if stage == "model":
            model = ModelSummary.read(summary)
            headline.assumptions = [a for a in model.assumptions if isinstance(a, str)]
            headline.warnings += [w for w in model.plausibility_warnings if isinstance(w, str)]
        headline.warnings += [f"{stage}: {w}" for w in common.warnings if isinstance(w, str)]
    if on_recorded_model:
        headline.inputs.append(recorded_model_on_simulated_arm(on_recorded_model, model_data))
    arms = _arms_combined(run_dir)
    if arms:
        headline.warnings.insert(0, arms)
    return headline


# ------------------------------------------------------------------------------ output
COLUMNS = ("stage", "figure", "value", "against", "ratio", "verdict", "input")


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def headline_markdown(headline: Headline) -> str:
    """The headline table, then the assumptions still in force and the warnings (markdown)."""
    lines = ["## Headline", ""]
    if headline.rows:
        lines += ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
        lines += ["| " + " | ".join(_cell(x) for x in (r.stage, r.figure, r.value, r.against, r.ratio, r.verdict,
                                                        r.source)) + " |" for r in headline.rows]
    else:
        lines.append("_no finished stage yet_")
    if headline.inputs:
        lines += ["", "**Inputs** (recorded or simulated):", "", *[f"* {x}" for x in headline.inputs]]
    lines += ["", "**Assumptions still in force**" + (":" if headline.assumptions else ": none (every robot "
              "fact comes from the robot files)")]
    lines += ["", *[f"* {a}" for a in headline.assumptions]] if headline.assumptions else []
    lines += ["", "**Warnings**" + (":" if headline.warnings else ": none")]
    lines += ["", *[f"* {w}" for w in headline.warnings]] if headline.warnings else []
    return "\n".join(lines).rstrip() + "\n"


_VERDICT_STYLE = {FAIL: "bold red", WARN: "yellow", PASS: "green"}


def headline_table(headline: Headline) -> Table:
    """The headline as a rich table."""
    table = Table(title=f"Run {headline.run}: headline", title_justify="left", expand=False)
    for name in COLUMNS:
        table.add_column(name, overflow="fold")
    for r in headline.rows:
        style = _VERDICT_STYLE.get(r.verdict, "")
        verdict = escape(r.verdict)
        table.add_row(*(escape(x) for x in (r.stage, r.figure, r.value, r.against, r.ratio)),
                      f"[{style}]{verdict}[/]" if style else verdict, escape(r.source))
    return table


#: console width when the output is not a terminal (a log file): the table is not wrapped
LOG_WIDTH = 200


def print_headline(headline: Headline, console: Console | None = None) -> None:
    """Print the table, the assumptions still in force and the warnings on the console."""
    if console is None:
        console = Console(highlight=False)
        if not console.is_terminal:
            console.width = LOG_WIDTH
    if headline.rows:
        console.print(headline_table(headline))
    for line in headline.inputs:
        console.print(f"input: {line}", markup=False)
    if headline.assumptions:
        console.print(f"assumptions still in force ({len(headline.assumptions)}):", markup=False)
        for a in headline.assumptions:
            console.print(f"  * {a}", markup=False)
    for w in headline.warnings:
        console.print(f"[yellow]warning:[/] {escape(w)}")
