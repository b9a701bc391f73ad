"""Quality gates: a failed gate raises with the figure and threshold, unless accept_poor."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from pipeline.core.errors import QualityGateError
from pipeline.quality import QualityGates


@dataclass
class _Result:
    summary: dict = field(default_factory=dict)


def test_passing_gates_hand_on_the_result() -> None:
    gates = QualityGates("identification")
    assert gates.check("cond", 50.0, "<=", 100.0)
    result = gates.finish(_Result())
    assert result.summary["quality_gates"]["passed"] is True
    assert result.summary["accepted_poor"] is False


def test_failed_gate_names_figure_and_threshold() -> None:
    gates = QualityGates("identification")
    gates.check("validation_rms_over_sigma", 4.2, "<=", 1.5, "joint 3")
    gates.require("excitation_status", False, "IPOPT returned Maximum_Iterations_Exceeded")
    with pytest.raises(QualityGateError) as info:
        gates.finish(_Result())
    message = info.value.one_line()
    assert "validation_rms_over_sigma = 4.2" in message and "<= 1.5" in message
    assert "+1 more" in message
    assert info.value.result.summary["quality_gates"]["passed"] is False


def test_nan_fails_and_accept_poor_records_it() -> None:
    gates = QualityGates("trajectory", accept_poor=True)
    assert not gates.check("violation", float("nan"), "<=", 0.01)
    result = gates.finish(_Result())
    assert result.summary["accepted_poor"] is True
    assert result.summary["quality_gates"]["checks"][0]["passed"] is False
