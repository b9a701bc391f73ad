"""The summary records: the keys of a stage's ``summary.json`` that another module reads, one typed
definition each.

A stage writes its summary as a plain mapping (``StageResult.summary``, saved as ``summary.json``:
the report and ``benchmarks/bench_run.py --compare`` read the files); the run layer (headline,
report, second pass) reads the figures it needs through these records, never by a key spelled by
hand: a record's field name is the key, and :meth:`SummaryRecord.read` takes a summary (a missing
key, or a value of the wrong kind from an older run, reads as None). ``tests/run/test_summary_records.py``
checks that the run layer spells no summary key and that the stage packages write every key a
record names.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

from pipeline.quality import GateCheck

RecordT = TypeVar("RecordT", bound="SummaryRecord")


def _number(value: object) -> float | None:
    """A finite number, else None (a NaN, null, or a value of another kind)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value) if math.isfinite(value) else None


def _read(value: object, tp: object) -> object:
    """``value`` read as annotation ``tp`` of a record field (leniently: None when it does not fit)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is typing.Union or origin is types.UnionType:
        arms = [a for a in args if a is not type(None)]
        return _read(value, arms[0]) if value is not None and len(arms) == 1 else None
    if tp is float:
        return _number(value)
    if tp is int:
        return value if isinstance(value, int) and not isinstance(value, bool) else None
    if tp is str:
        return value if isinstance(value, str) else None
    if tp is bool:
        return bool(value) if isinstance(value, bool) else None
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            return ()
        return tuple(_read(v, args[0]) for v in value)
    if origin is dict:
        if not isinstance(value, Mapping):
            return {}
        return {str(k): _read(v, args[1]) for k, v in value.items()}
    if isinstance(tp, type) and issubclass(tp, SummaryRecord):
        return tp.read(value) if isinstance(value, Mapping) else None
    return value


class SummaryRecord:
    """Base of the records: :meth:`read` and :meth:`keys`."""

    #: the stage whose summary this is ("" for the entries every stage has)
    STAGE: ClassVar[str] = ""

    @classmethod
    def read(cls: type[RecordT], summary: Mapping[str, Any]) -> RecordT:  # Any: a summary.json value
        """The record of ``summary`` (a stage's ``summary.json`` mapping)."""
        hints = typing.get_type_hints(cls)
        values = {f.name: _read(summary.get(f.name), hints[f.name])
                  for f in dataclasses.fields(cls)}  # type: ignore[arg-type]  # every record is a dataclass
        return cls(**values)

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The summary keys this record reads (its field names)."""
        return tuple(f.name for f in dataclasses.fields(cls))  # type: ignore[arg-type]


@dataclass(frozen=True)
class StageSummary(SummaryRecord):
    """What every stage's summary may hold: its quality gates (:class:`pipeline.quality.QualityGates`),
    whether a failed gate was accepted (``--accept-poor``), its provenance record (the runner's,
    :class:`pipeline.stage_api.Provenance`) and warnings for the headline."""

    quality_gates: dict[str, object] | None = None
    accepted_poor: bool | None = None
    provenance: dict[str, object] | None = None
    warnings: tuple[str, ...] = ()

    def gate_checks(self) -> tuple[GateCheck, ...]:
        """The stage's gate checks (``quality_gates.checks``; an entry that is not one is left out)."""
        checks = (self.quality_gates or {}).get("checks")
        out = []
        for c in checks if isinstance(checks, list) else []:
            if isinstance(c, Mapping) and "name" in c:
                value, threshold = c.get("value"), _number(c.get("threshold"))
                out.append(GateCheck(str(c["name"]), bool(c.get("passed")),
                                     value if isinstance(value, (int, float, str)) else None, str(c.get("op") or ""),
                                     threshold, str(c.get("message") or "")))
        return tuple(out)

    def gate(self, name: str) -> GateCheck | None:
        """The gate check called ``name``, or None."""
        return next((c for c in self.gate_checks() if c.name == name), None)


@dataclass(frozen=True)
class ModelSummary(SummaryRecord):
    STAGE: ClassVar[str] = "model"

    name: str | None = None
    dof: int | None = None
    reach_m: float | None = None
    moving_mass_kg: float | None = None
    payload_kg: float | None = None
    assumptions: tuple[str, ...] = ()
    plausibility_warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class CrossValidationSummary(SummaryRecord):
    """``calibration.cross_validation``: k-fold cross-validation of a recorded measurement file."""

    folds: int | None = None
    rms_position_error_m: float | None = None
    predicted_rms_position_error_m: float | None = None
    actual_over_predicted: float | None = None
    rms_position_error_all_poses_m: float | None = None
    n_rejected: int | None = None
    n_poses_all: int | None = None


@dataclass(frozen=True)
class RatioTestSummary(SummaryRecord):
    """``calibration.actual_over_predicted_test``: the one-sided tests on the held-out actual/predicted
    ratio (:func:`pipeline.calibration.gates.ratio_test`): optimistic above ``threshold`` (the
    gate), pessimistic below ``lower_threshold`` (a warning), at ``confidence``."""

    threshold: float | None = None
    lower_threshold: float | None = None
    effective_dof: float | None = None
    n_scored_poses: int | None = None
    confidence: float | None = None


@dataclass(frozen=True)
class CalibrationSummary(SummaryRecord):
    STAGE: ClassVar[str] = "calibration"

    heldout_rms_position_error_after_m: float | None = None
    heldout_rms_position_error_before_m: float | None = None
    predicted_rms_position_error_m: float | None = None
    actual_over_predicted: float | None = None
    actual_over_predicted_test: RatioTestSummary | None = None
    cross_validation: CrossValidationSummary | None = None
    validation_source: str | None = None
    measurement_source: str | None = None
    #: the readings' total noise (sensor + repeatability + remainder)
    noise_total_sigma_m: float | None = None
    #: runs saved before ``noise_total_sigma_m`` held the total here
    tracker_noise_sigma_m: float | None = None
    #: the gravity model's share of the predicted error (the second pass's decision)
    gravity_model_share: float | None = None


@dataclass(frozen=True)
class IdentificationSummary(SummaryRecord):
    STAGE: ClassVar[str] = "identification"

    #: per joint; None for a joint whose torque was not measured
    validation_rms_over_noise: tuple[float | None, ...] = ()
    validation_trajectory: str | None = None
    data_source: str | None = None


@dataclass(frozen=True)
class ControlSummary(SummaryRecord):
    STAGE: ClassVar[str] = "control"

    #: feedforward variant -> largest TCP error on the ISO path (m); ``none``: without feedforward
    tcp_error_max_m: dict[str, float | None] = field(default_factory=dict)


@dataclass(frozen=True)
class TrajectorySummary(SummaryRecord):
    STAGE: ClassVar[str] = "trajectory"
    #: keys the stage writes as ``f"{plan}_move_and_settle_s"`` / ``f"{plan}_elastic_ff_{figure}"``
    #: (:func:`pipeline.trajectory.settling.settle_study`), not spelled out in its source
    COMPOSED: ClassVar[tuple[str, ...]] = (
        "ptp_move_and_settle_s", "ptp_smooth_move_and_settle_s", "ptp_ruckig_move_and_settle_s",
        "ptp_elastic_ff_move_and_settle_s", "ptp_smooth_elastic_ff_move_and_settle_s",
        "ptp_ruckig_elastic_ff_move_and_settle_s")

    cp_segment: str | None = None
    cp_duration_s: float | None = None
    cp_toppra_duration_s: float | None = None
    #: whose profile the CP is (``ours``, or ``toppra`` when toppra's is shorter and keeps every limit on
    #: the fine grid, :func:`pipeline.trajectory.solve.shorter_cp`), and our solver's duration
    cp_source: str | None = None
    cp_ours_duration_s: float | None = None
    #: toppra's profile keeps every limit on the fine grid (full friction); else the peer that does
    #: (:func:`pipeline.trajectory.baselines.toppra_within_limits`): toppra on ``cp_toppra_feasible_n_grid``
    #: intervals (the CP's own: ``cp_n_grid``), slowed by ``cp_toppra_feasible_time_scale``, and its
    #: duration (None: none does); toppra's worst joint acceleration and speed there over their limits
    cp_toppra_within_limits: bool | None = None
    cp_toppra_feasible_duration_s: float | None = None
    cp_toppra_feasible_n_grid: int | None = None
    cp_toppra_feasible_time_scale: float | None = None
    cp_n_grid: int | None = None
    cp_toppra_fine_violation_full_friction: float | None = None
    cp_toppra_fine_max_acceleration_ratio: float | None = None
    cp_toppra_fine_max_velocity_ratio: float | None = None
    #: the CP the elastic arm executes (``time_optimal`` or a remedy, :mod:`pipeline.trajectory.executable`)
    cp_executed: str | None = None
    cp_executed_duration_s: float | None = None
    ptp_duration_s: float | None = None
    ptp_ruckig_duration_s: float | None = None
    ptp_energy_at_ruckig_duration: float | None = None
    ptp_ruckig_energy: float | None = None
    ptp_energy_measure: str | None = None
    ptp_move_and_settle_s: float | None = None
    ptp_smooth_move_and_settle_s: float | None = None
    ptp_ruckig_move_and_settle_s: float | None = None
    ptp_elastic_ff_move_and_settle_s: float | None = None
    ptp_smooth_elastic_ff_move_and_settle_s: float | None = None
    ptp_ruckig_elastic_ff_move_and_settle_s: float | None = None
    ptp_settle_elastic_feedforward: str | None = None

    def move_and_settle_s(self, plan: str, elastic_feedforward: bool) -> float | None:
        """Move + settle time of ``plan`` (``ptp``, ``ptp_smooth``, ``ptp_ruckig``), with the rigid
        or the elastic-joint feedforward."""
        value = getattr(self, f"{plan}{'_elastic_ff' if elastic_feedforward else ''}_move_and_settle_s")
        return value if isinstance(value, float) else None


#: stage -> its summary record
RECORDS: dict[str, type[SummaryRecord]] = {
    r.STAGE: r for r in (ModelSummary, CalibrationSummary, IdentificationSummary, ControlSummary, TrajectorySummary)
}

