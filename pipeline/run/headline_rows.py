"""The headline's rows: the figures of each stage's ``summary.json``, each against its gate or anchor,
with its ratio, verdict and input (:mod:`.headline` reads a run and prints them; the rules are in its
docstring)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from pipeline.quality import GateCheck
from pipeline.robot.plausibility import placeholder_kind
from pipeline.stage_api import Provenance
from pipeline.summaries import (
    CalibrationSummary,
    ControlSummary,
    CrossValidationSummary,
    IdentificationSummary,
    ModelSummary,
    RecordT,
    StageSummary,
    TrajectorySummary,
)

SIMULATED = "simulated"
#: where the figures of the control and trajectory stages come from: the servo loop simulated on
#: the hidden robot (:func:`read_headline` adds where the identified model's data came from)
SERVO_SIMULATION = "simulated"


PASS, WARN, FAIL = "pass", "warn", "FAIL"


@dataclass(frozen=True)
class Row:
    """One headline figure: ``value`` against ``against``, their ``ratio`` (``×1.23``, or empty) and the
    ``verdict`` (:data:`PASS`, :data:`WARN`, :data:`FAIL`, or empty: nothing to judge by)."""

    stage: str
    figure: str
    value: str
    against: str
    verdict: str
    source: str
    ratio: str = ""


# ------------------------------------------------------------------------------ formatting
def length(m: float) -> str:
    """A length in µm below 1 mm, else in mm."""
    return f"{m * 1e6:.1f} µm" if abs(m) < 1e-3 else f"{m * 1e3:.2f} mm"


def ratio(x: float) -> str:
    """``×`` and three significant digits; four within 1 % of 1, where a verdict turns on the last one
    (a plan 0.45 % longer than its peer reads ``×1.004``, not ``×1``)."""
    return f"×{x:.4g}" if 0.99 < x < 1.01 else f"×{x:.3g}"


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


def _gate_verdict(check: GateCheck | None) -> str:
    if check is None:
        return ""
    return PASS if check.passed else FAIL


def _anchor_verdict(x: float, at_most_one: bool) -> str:
    """``pass`` when ratio ``x`` is on the good side of 1 (at most 1, or at least 1), else ``warn``."""
    return PASS if (x <= 1.0 if at_most_one else x >= 1.0) else WARN


# ------------------------------------------------------------------------------ rows per stage
def _model_rows(s: ModelSummary, gates: StageSummary) -> list[Row]:
    if s.reach_m is None or s.moving_mass_kg is None:
        return []
    warnings = s.plausibility_warnings
    assumed = "robot files" + (", with assumed facts" if s.assumptions else "")
    placeholders = placeholder_kinds(s.assumptions)
    # a placeholder is sized by the scaling rule it would be judged by: never called plausible
    notes = ([f"{len(warnings)} warning(s)"] if warnings else []) + (
        [f"placeholder: {', '.join(placeholders)}"] if placeholders else [])
    against = "data-sheet scaling of serial arms" + (f" ({'; '.join(notes)})" if notes else "")
    return [Row("model", f"robot {s.name or ''}".strip(),
                f"{s.dof if s.dof is not None else '?'} DOF, reach {s.reach_m:.2f} m, moving mass "
                f"{s.moving_mass_kg:.3g} kg, payload {s.payload_kg or 0:g} kg", against, WARN if notes else PASS,
                assumed)]


def placeholder_kinds(assumptions: Iterable[str]) -> list[str]:
    """What the robot's placeholders stand for (``inertials``, ``effort limits`` ...), from its
    assumptions (:func:`pipeline.robot.plausibility.placeholder_kind`)."""
    return list(dict.fromkeys(k for k in map(placeholder_kind, map(str, assumptions)) if k))


def _calibration_rows(s: CalibrationSummary, gates: StageSummary) -> list[Row]:
    """Held-out error (simulated validation poses), else the k-fold cross-validated error of a
    recorded file, against the tracker noise and the predicted error."""
    after, label = s.heldout_rms_position_error_after_m, "held-out TCP error RMS"
    predicted = s.predicted_rms_position_error_m
    over = s.actual_over_predicted
    every = ""
    cv = s.cross_validation or CrossValidationSummary()
    if after is None:
        after = cv.rms_position_error_m
        label = f"{cv.folds}-fold cross-validated TCP error RMS"
        # the same held-out poses' prediction (the summary's is over random poses of the whole workspace)
        predicted = cv.predicted_rms_position_error_m or predicted
        over = cv.actual_over_predicted
        # the figure over every pose beside the screened one (gross errors left out)
        if cv.rms_position_error_all_poses_m is not None and cv.n_rejected:
            every = f"; all {cv.n_poses_all} poses {length(cv.rms_position_error_all_poses_m)}"
    if after is None:
        return []
    before = s.heldout_rms_position_error_before_m
    value = length(after) + every + (f" (before {length(before)})" if before is not None else "")
    source = provenance(s.validation_source or s.measurement_source)
    rows = []
    # the readings' total noise (sensor + repeatability + remainder); runs saved before it had its own
    # key held the total as tracker_noise_sigma_m
    sigma = s.noise_total_sigma_m if s.noise_total_sigma_m is not None else s.tracker_noise_sigma_m
    if sigma:
        rows.append(Row("calibration", f"{label} / noise", value, f"noise σ {length(sigma)}", "", source,
                        ratio(after / sigma)))
    if predicted:
        actual_over = over if over is not None else after / predicted
        check = gates.gate("actual_over_predicted")
        verdict = _gate_verdict(check)
        threshold = check.threshold if check is not None else None
        # the pessimistic bound: the held-out test's (its spread over the scored poses), else 1 / gate
        test = s.actual_over_predicted_test if s.heldout_rms_position_error_after_m is not None else None
        lower = (test.lower_threshold if test is not None and test.lower_threshold is not None
                 else 1.0 / threshold if threshold else None)
        if verdict == PASS and lower is not None and actual_over < lower:
            verdict = WARN                 # a pessimistic prediction: its gate passes, the stage warns
        rows.append(Row("calibration", f"{label}, actual / predicted", length(after) + every,
                        f"predicted {length(predicted)}", verdict, source, ratio(actual_over)))
    return rows


def _identification_rows(s: IdentificationSummary, gates: StageSummary) -> list[Row]:
    values = list(s.validation_rms_over_noise)
    measured = [j for j, r in enumerate(values) if r is not None]   # unmeasured joints: null
    if not measured:
        return []
    worst = max(measured, key=lambda j: values[j] or 0.0)
    check = gates.gate("validation_rms_over_noise")
    against = (f"gate ≤ {check.threshold:g}" if check is not None and check.threshold is not None
               else "torque noise σ")
    path = s.validation_trajectory
    figure = "validation torque RMS / σ, worst joint" + (f" ({path} path)" if path else "")
    return [Row("identification", figure, f"{values[worst]:.3g} (joint {worst + 1})", against,
                _gate_verdict(check), provenance(s.data_source), ratio(values[worst] or 0.0))]


def _control_rows(s: ControlSummary, gates: StageSummary) -> list[Row]:
    errors = s.tcp_error_max_m
    without = errors.get("none")
    if without is None:
        return []
    variants = {k: v for k, v in errors.items() if k != "none" and not k.endswith("_nominal") and v is not None}
    if not variants:
        return []
    best = min(variants, key=lambda k: variants[k])
    gain = without / variants[best] if variants[best] > 0 else math.inf
    return [Row("control", "feedforward gain (ISO path max TCP error)",
                f"{length(variants[best])} with {best}", f"{length(without)} without",
                _anchor_verdict(gain, at_most_one=False), SERVO_SIMULATION, ratio(gain))]


def _duration_row(figure: str, a: float | None, b: float | None, name: str) -> Row | None:
    if a is None or b is None or b <= 0:
        return None
    return Row("trajectory", figure, f"{a:.3f} s", f"{name} {b:.3f} s", _anchor_verdict(a / b, True),
               SERVO_SIMULATION, ratio(a / b))


def _feasible_toppra(s: TrajectorySummary) -> str:
    """How toppra's peer was made to keep its limits: a denser grid, a uniform slow-down, or both."""
    how = []
    if s.cp_toppra_feasible_n_grid is not None and s.cp_n_grid and s.cp_toppra_feasible_n_grid != s.cp_n_grid:
        how.append(f"on {s.cp_toppra_feasible_n_grid} intervals")
    if s.cp_toppra_feasible_time_scale is not None and s.cp_toppra_feasible_time_scale > 1.0:
        how.append(f"slowed ×{s.cp_toppra_feasible_time_scale:.4g}")
    return f"toppra {', '.join(how)}" if how else "toppra within its limits"


def _cp_row(s: TrajectorySummary) -> Row | None:
    """The CP's duration against toppra's, or, when toppra's profile is over a limit on the fine grid
    (it enforces them at its grid points alone), against toppra made to keep them (a denser grid, a
    uniform slow-down: :func:`_feasible_toppra`);
    when toppra's profile is the CP handed on (it was shorter), our solver's duration is the one judged
    (the CP handed on against its own source would pass by construction);
    when a remedy of the time-optimal plan is executed (its servo run over the gate on the elastic
    arm), the executed plan's duration is the one judged."""
    figure = f"CP duration ({s.cp_segment or 'ISO'} path)"
    toppra, feasible = s.cp_toppra_duration_s, s.cp_toppra_feasible_duration_s
    if toppra is None or toppra <= 0 or s.cp_duration_s is None:
        return None
    if s.cp_source == "toppra" and s.cp_ours_duration_s is not None:
        made_feasible = s.cp_toppra_within_limits is False and feasible is not None
        peer = feasible if made_feasible and feasible is not None else toppra
        ours = s.cp_ours_duration_s
        against = (f"{_feasible_toppra(s)} {peer:.3f} s (as planned {toppra:.3f} s, over a limit)"
                   if made_feasible else f"toppra {toppra:.3f} s")
        return Row("trajectory", figure + ", our solver", f"{ours:.3f} s (toppra's {s.cp_duration_s:.3f} s handed "
                   "on, shorter)", against, _anchor_verdict(ours / peer, True), SERVO_SIMULATION, ratio(ours / peer))
    peer, against = toppra, f"toppra {toppra:.3f} s"
    if s.cp_toppra_within_limits is False:
        if feasible is None:
            return Row("trajectory", figure, f"{s.cp_duration_s:.3f} s", f"{against}, over a limit on the fine "
                       "grid at any speed", "", SERVO_SIMULATION, ratio(s.cp_duration_s / toppra))
        peer, against = feasible, f"{_feasible_toppra(s)} {feasible:.3f} s (as planned {toppra:.3f} s, over a limit)"
    executed = s.cp_executed_duration_s
    if s.cp_executed in (None, "time_optimal") or executed is None:
        return Row("trajectory", figure, f"{s.cp_duration_s:.3f} s", against,
                   _anchor_verdict(s.cp_duration_s / peer, True), SERVO_SIMULATION, ratio(s.cp_duration_s / peer))
    return Row("trajectory", figure, f"time-optimal {s.cp_duration_s:.3f} s, executed ({s.cp_executed}) "
               f"{executed:.3f} s", against, _anchor_verdict(executed / peer, True),
               SERVO_SIMULATION, ratio(executed / peer))


def _settle_row(s: TrajectorySummary, elastic_feedforward: bool, label: str) -> Row | None:
    opt = s.move_and_settle_s("ptp", elastic_feedforward)
    smooth = s.move_and_settle_s("ptp_smooth", elastic_feedforward)
    ruckig = s.move_and_settle_s("ptp_ruckig", elastic_feedforward)
    if opt is None or ruckig is None or ruckig <= 0:
        return None
    best = opt if smooth is None else min(opt, smooth)
    value = f"time-optimal {opt:.3f} s" + (f", smooth {smooth:.3f} s" if smooth is not None else "")
    return Row("trajectory", f"PtP move + settle ({label})", value, f"ruckig {ruckig:.3f} s",
               _anchor_verdict(best / ruckig, True), SERVO_SIMULATION, ratio(best / ruckig))


def _trajectory_rows(s: TrajectorySummary, gates: StageSummary) -> list[Row]:
    rows: list[Row | None] = [
        _cp_row(s),
        _duration_row("PtP duration", s.ptp_duration_s, s.ptp_ruckig_duration_s, "ruckig"),
    ]
    energy, ruckig_energy = s.ptp_energy_at_ruckig_duration, s.ptp_ruckig_energy
    if energy is not None and ruckig_energy:
        rows.append(Row("trajectory", f"PtP energy at ruckig's duration ({s.ptp_energy_measure or ''})",
                        f"{energy:.4g}", f"ruckig {ruckig_energy:.4g}", _anchor_verdict(energy / ruckig_energy, True),
                        SERVO_SIMULATION, ratio(energy / ruckig_energy)))
    rows.append(_settle_row(s, False, "rigid feedforward"))
    if s.ptp_settle_elastic_feedforward:
        rows.append(_settle_row(s, True, f"{s.ptp_settle_elastic_feedforward} feedforward"))
    return [r for r in rows if r is not None]


def _rows_of(record: type[RecordT], rows: Callable[[RecordT, StageSummary], list[Row]]
             ) -> Callable[[Mapping[str, Any], StageSummary], list[Row]]:
    return lambda summary, gates: rows(record.read(summary), gates)


#: stage -> its headline rows from its summary (read through the stage's record, :mod:`pipeline.summaries`)
STAGE_ROWS: dict[str, Callable[[Mapping[str, Any], StageSummary], list[Row]]] = {
    "model": _rows_of(ModelSummary, _model_rows),
    "calibration": _rows_of(CalibrationSummary, _calibration_rows),
    "identification": _rows_of(IdentificationSummary, _identification_rows),
    "control": _rows_of(ControlSummary, _control_rows),
    "trajectory": _rows_of(TrajectorySummary, _trajectory_rows),
}


def gate_row(stage: str, s: StageSummary) -> Row | None:
    """How many of the stage's quality gates pass (``--accept-poor`` results count as FAIL)."""
    checks = s.gate_checks()
    if not checks:
        return None
    failed = [str(c.name) for c in checks if not c.passed]
    value = f"{len(checks) - len(failed)} of {len(checks)} pass"
    if failed:
        value += "; failed: " + ", ".join(failed)
        if s.accepted_poor:
            value += " (accepted with --accept-poor)"
    return Row(stage, "quality gates", value, "the stage's gates", FAIL if failed else PASS, "")


def stage_rows(stage: str, summary: Mapping[str, Any], stale: bool = False) -> list[Row]:
    """The headline rows of one stage (a stale stage's rows say so in their source)."""
    common = StageSummary.read(summary)
    rows = list(STAGE_ROWS.get(stage, lambda s, g: [])(summary, common))
    record = Provenance.from_dict(common.provenance)
    if record is not None:
        rows = [replace(r, source=typed_label(record)) for r in rows]
    gates = gate_row(stage, common)
    if gates is not None:
        rows.append(gates)
    if stale:
        rows = [replace(r, source=f"{r.source} (stale: earlier run)".strip()) for r in rows]
    return rows


#: stages whose figures are simulated on the model identified upstream
