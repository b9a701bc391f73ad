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

Each row states its verdict (pass/FAIL of a gate, or the ratio to its anchor) and the provenance
of its input (simulated, or the recorded file: the stage's typed record, ``summary.json``
``provenance``); the run's ``provenance.json`` adds whether the second calibration pass ran and why.
:func:`headline_markdown` opens ``report.md``
followed by the assumptions still in force and the warnings; :func:`print_headline` prints the
same table on the console.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from pipeline.core import artefacts
from pipeline.core.typed_config import dotted_get
from pipeline.run import stage_io
from pipeline.stage_api import PROVENANCE_FILE, Provenance

SIMULATED = "simulated"
#: where the figures of the control and trajectory stages come from: the servo loop simulated on
#: the hidden robot (:func:`read_headline` adds where the identified model's data came from)
SERVO_SIMULATION = "simulated"


@dataclass(frozen=True)
class Row:
    """One headline figure: ``value`` against ``against``, ``verdict`` (pass/FAIL or a ratio)."""

    stage: str
    figure: str
    value: str
    against: str
    verdict: str
    source: str


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
        return any(r.verdict.startswith("FAIL") for r in self.rows)


# ------------------------------------------------------------------------------ formatting
def _finite(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value) if math.isfinite(value) else None


def _get(summary: dict, dotted: str) -> Any:  # Any: a summary.json value
    return dotted_get(summary, dotted)


def length(m: float) -> str:
    """A length in µm below 1 mm, else in mm."""
    return f"{m * 1e6:.1f} µm" if abs(m) < 1e-3 else f"{m * 1e3:.2f} mm"


def ratio(x: float) -> str:
    return f"×{x:.3g}"


def provenance(source: object) -> str:
    """``simulated`` for a simulated input, else ``recorded (<file name>)``."""
    if not source:
        return SIMULATED
    text = str(source)
    if "simulat" in text.lower():
        return SIMULATED
    return f"recorded ({Path(text).name or text})"


def typed_label(record: Provenance) -> str:
    """The input column of a stage with a typed provenance record: recorded inputs say which
    robot they start from when a simulated upstream stage was left out."""
    label = record.label()
    if record.recorded and "calibration" in record.left_out:
        label += ", nominal kinematics"
    return label


def _gate(summary: dict, name: str) -> dict | None:
    checks = _get(summary, "quality_gates.checks") or []
    return next((c for c in checks if isinstance(c, dict) and c.get("name") == name), None)


def _gate_verdict(check: dict | None) -> str:
    if check is None:
        return ""
    return "pass" if check.get("passed") else "FAIL"


# ------------------------------------------------------------------------------ rows per stage
def _model_rows(s: dict) -> list[Row]:
    reach, mass = _finite(s.get("reach_m")), _finite(s.get("moving_mass_kg"))
    if reach is None or mass is None:
        return []
    warnings = s.get("plausibility_warnings") or []
    assumed = "robot files" + (", with assumed facts" if s.get("assumptions") else "")
    return [Row("model", f"robot {s.get('name', '')}".strip(),
                f"{s.get('dof', '?')} DOF, reach {reach:.2f} m, moving mass {mass:.3g} kg, payload "
                f"{_finite(s.get('payload_kg')) or 0:g} kg", "data-sheet scaling of serial arms",
                f"WARN: {len(warnings)} warning(s)" if warnings else "plausible", assumed)]


def _calibration_rows(s: dict) -> list[Row]:
    """Held-out error (simulated validation poses), else the k-fold cross-validated error of a
    recorded file, against the tracker noise and the predicted error."""
    after, label = _finite(s.get("heldout_rms_position_error_after_m")), "held-out TCP error RMS"
    predicted = _finite(s.get("predicted_rms_position_error_m"))
    if after is None:
        after = _finite(_get(s, "cross_validation.rms_position_error_m"))
        label = f"{_get(s, 'cross_validation.folds')}-fold cross-validated TCP error RMS"
        # the same held-out poses' prediction (the summary's is over random poses of the whole workspace)
        predicted = _finite(_get(s, "cross_validation.predicted_rms_position_error_m")) or predicted
    if after is None:
        return []
    before = _finite(s.get("heldout_rms_position_error_before_m"))
    value = length(after) + (f" (before {length(before)})" if before is not None else "")
    source = provenance(s.get("validation_source") or s.get("measurement_source"))
    rows = []
    # the readings' total noise (sensor + repeatability + remainder); runs saved before it had its own
    # key held the total as tracker_noise_sigma_m
    sigma = _finite(s.get("noise_total_sigma_m", s.get("tracker_noise_sigma_m")))
    if sigma:
        rows.append(Row("calibration", f"{label} / noise", value, f"noise σ {length(sigma)}",
                        ratio(after / sigma), source))
    if predicted:
        rows.append(Row("calibration", f"{label}, actual / predicted", length(after),
                        f"predicted {length(predicted)}", ratio(after / predicted), source))
    return rows


def _identification_rows(s: dict) -> list[Row]:
    ratios = s.get("validation_rms_over_noise")
    values = [_finite(r) for r in ratios] if isinstance(ratios, list) else []
    measured = [j for j, r in enumerate(ratios or []) if r is not None]   # unmeasured joints: null
    if not measured or any(values[j] is None for j in measured):
        return []
    worst = max(measured, key=lambda j: values[j] or 0.0)
    check = _gate(s, "validation_rms_over_noise")
    against = (f"gate ≤ {check['threshold']:g}" if check and check.get("threshold") is not None
               else "torque noise σ")
    path = s.get("validation_trajectory")
    figure = "validation torque RMS / σ, worst joint" + (f" ({path} path)" if path else "")
    return [Row("identification", figure, f"{values[worst]:.3g} (joint {worst + 1})", against,
                _gate_verdict(check) or ratio(values[worst] or 0.0), provenance(s.get("data_source")))]


def _control_rows(s: dict) -> list[Row]:
    errors = s.get("tcp_error_max_m")
    if not isinstance(errors, dict) or _finite(errors.get("none")) is None:
        return []
    without = float(errors["none"])
    variants = {k: float(v) for k, v in errors.items()
                if k != "none" and not k.endswith("_nominal") and _finite(v) is not None}
    if not variants:
        return []
    best = min(variants, key=lambda k: variants[k])
    gain = without / variants[best] if variants[best] > 0 else math.inf
    return [Row("control", "feedforward gain (ISO path max TCP error)",
                f"{length(variants[best])} with {best}", f"{length(without)} without",
                ratio(gain), SERVO_SIMULATION)]


def _duration_row(s: dict, figure: str, ours: str, theirs: str, name: str, note: str = "") -> Row | None:
    a, b = _finite(s.get(ours)), _finite(s.get(theirs))
    if a is None or b is None or b <= 0:
        return None
    return Row("trajectory", figure, f"{a:.3f} s", f"{name} {b:.3f} s{note}", ratio(a / b), SERVO_SIMULATION)


def _settle_row(s: dict, infix: str, label: str) -> Row | None:
    opt = _finite(s.get(f"ptp{infix}_move_and_settle_s"))
    smooth = _finite(s.get(f"ptp_smooth{infix}_move_and_settle_s"))
    ruckig = _finite(s.get(f"ptp_ruckig{infix}_move_and_settle_s"))
    if opt is None or ruckig is None or ruckig <= 0:
        return None
    best = opt if smooth is None else min(opt, smooth)
    value = f"time-optimal {opt:.3f} s" + (f", smooth {smooth:.3f} s" if smooth is not None else "")
    return Row("trajectory", f"PtP move + settle ({label})", value, f"ruckig {ruckig:.3f} s",
               ratio(best / ruckig), SERVO_SIMULATION)


def _trajectory_rows(s: dict) -> list[Row]:
    rows: list[Row | None] = [
        _duration_row(s, f"CP duration ({s.get('cp_segment', 'ISO')} path)", "cp_duration_s", "cp_toppra_duration_s",
                      "toppra"),
        _duration_row(s, "PtP duration", "ptp_duration_s", "ptp_ruckig_duration_s", "ruckig"),
    ]
    energy, ruckig_energy = _finite(s.get("ptp_energy_at_ruckig_duration")), _finite(s.get("ptp_ruckig_energy"))
    if energy is not None and ruckig_energy:
        rows.append(Row("trajectory", f"PtP energy at ruckig's duration ({s.get('ptp_energy_measure', '')})",
                        f"{energy:.4g}", f"ruckig {ruckig_energy:.4g}", ratio(energy / ruckig_energy),
                        SERVO_SIMULATION))
    rows.append(_settle_row(s, "", "rigid feedforward"))
    if s.get("ptp_settle_elastic_feedforward"):
        rows.append(_settle_row(s, "_elastic_ff", f"{s['ptp_settle_elastic_feedforward']} feedforward"))
    return [r for r in rows if r is not None]


#: stage -> its headline rows from its summary
STAGE_ROWS: dict[str, Callable[[dict], list[Row]]] = {
    "model": _model_rows,
    "calibration": _calibration_rows,
    "identification": _identification_rows,
    "control": _control_rows,
    "trajectory": _trajectory_rows,
}


def gate_row(stage: str, s: dict) -> Row | None:
    """How many of the stage's quality gates pass (``--accept-poor`` results count as FAIL)."""
    checks = [c for c in _get(s, "quality_gates.checks") or [] if isinstance(c, dict)]
    if not checks:
        return None
    failed = [str(c.get("name")) for c in checks if not c.get("passed")]
    verdict = "pass" if not failed else "FAIL: " + ", ".join(failed)
    if failed and s.get("accepted_poor"):
        verdict += " (accepted with --accept-poor)"
    return Row(stage, "quality gates", f"{len(checks) - len(failed)} of {len(checks)} pass", "the stage's gates",
               verdict, "")


def stage_rows(stage: str, summary: dict, stale: bool = False) -> list[Row]:
    """The headline rows of one stage (a stale stage's rows say so in their source)."""
    rows = list(STAGE_ROWS.get(stage, lambda s: [])(summary))
    record = Provenance.from_dict(summary.get("provenance"))
    if record is not None:
        rows = [Row(r.stage, r.figure, r.value, r.against, r.verdict, typed_label(record)) for r in rows]
    gates = gate_row(stage, summary)
    if gates is not None:
        rows.append(gates)
    if stale:
        rows = [Row(r.stage, r.figure, r.value, r.against, r.verdict, f"{r.source} (stale: earlier run)".strip())
                for r in rows]
    return rows


#: stages whose figures are simulated on the model identified upstream
SIMULATED_ON_THE_MODEL = ("control", "trajectory")


def _read_summary(stage_dir: Path) -> dict:
    try:
        data = artefacts.read_json(stage_dir / stage_io.SUMMARY)
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


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
    return Row("calibration", "second calibration pass", str(note), "identified inertias of the arm calibrated",
               "ran" if ran else "not run", "")


def read_headline(run_dir: Path, stages: Sequence[str], stale: Iterable[str] = ()) -> Headline:
    """The headline of ``run_dir`` from the ``summary.json`` of ``stages`` (in that order; stages
    without a summary are left out; ``stale``: stages whose results are from an earlier run)."""
    run_dir = Path(run_dir)
    stale = set(stale)
    headline = Headline(run_dir.name)
    model_data = SIMULATED
    for stage in stages:
        summary = _read_summary(run_dir / stage)
        if not summary:
            continue
        rows = stage_rows(stage, summary, stage in stale)
        record = Provenance.from_dict(summary.get("provenance"))
        if stage == "identification":
            model_data = (provenance(summary.get("data_source")) if record is None
                          else typed_label(record) if record.recorded else SIMULATED)
        elif stage in SIMULATED_ON_THE_MODEL and model_data != SIMULATED:
            rows = [Row(r.stage, r.figure, r.value, r.against, r.verdict,
                        f"{r.source}, model from {model_data}" if r.source else r.source) for r in rows]
        headline.rows += rows
        if record is not None:
            headline.inputs.append(f"{stage}: {record.sentence()}")
        if stage == "calibration":
            second = _second_pass_row(run_dir, stages)
            headline.rows += [] if second is None else [second]
        if stage == "model":
            headline.assumptions = [str(a) for a in summary.get("assumptions") or []]
            headline.warnings += [str(w) for w in summary.get("plausibility_warnings") or []]
        headline.warnings += [f"{stage}: {w}" for w in summary.get("warnings") or [] if isinstance(w, str)]
    return headline


# ------------------------------------------------------------------------------ output
COLUMNS = ("stage", "figure", "value", "against", "verdict", "input")


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def headline_markdown(headline: Headline) -> str:
    """The headline table, then the assumptions still in force and the warnings (markdown)."""
    lines = ["## Headline", ""]
    if headline.rows:
        lines += ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
        lines += ["| " + " | ".join(_cell(x) for x in (r.stage, r.figure, r.value, r.against, r.verdict, r.source))
                  + " |" for r in headline.rows]
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


_VERDICT_STYLE = (("FAIL", "bold red"), ("WARN", "yellow"), ("pass", "green"), ("plausible", "green"))


def headline_table(headline: Headline) -> Table:
    """The headline as a rich table."""
    table = Table(title=f"Run {headline.run}: headline", title_justify="left", expand=False)
    for name in COLUMNS:
        table.add_column(name, overflow="fold")
    for r in headline.rows:
        style = next((s for prefix, s in _VERDICT_STYLE if r.verdict.startswith(prefix)), "")
        verdict = escape(r.verdict)
        table.add_row(*(escape(x) for x in (r.stage, r.figure, r.value, r.against)),
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
