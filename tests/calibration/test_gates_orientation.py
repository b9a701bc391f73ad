"""The held-out orientation error against its prediction: a warning, not a gate."""

from __future__ import annotations

from pipeline.calibration.gates import orientation_prediction_warning


def _summary(rms: float, predicted: float | None, n: int = 5, rejected: int = 0) -> dict:
    return {"heldout_rms_orientation_error_after_rad": rms, "heldout_predicted_rms_orientation_error_rad": predicted,
            "heldout_n_poses": n, "heldout_n_rejected": rejected}


def test_an_error_three_times_its_prediction_is_warned_one_near_it_is_not():
    assert orientation_prediction_warning(_summary(3e-3, 1e-3), 1.5, 0.99) is not None
    assert orientation_prediction_warning(_summary(1.1e-3, 1e-3), 1.5, 0.99) is None


def test_the_bound_widens_for_few_poses():
    """2.0 times the prediction: chance on two poses (6 dof), not on fifty (150 dof)."""
    assert orientation_prediction_warning(_summary(2e-3, 1e-3, n=2), 1.5, 0.99) is None
    message = orientation_prediction_warning(_summary(2e-3, 1e-3, n=50), 1.5, 0.99)
    assert message is not None and "50 poses" in message and "not gated" in message


def test_no_orientation_no_warning():
    assert orientation_prediction_warning(_summary(None, None), 1.5, 0.99) is None   # type: ignore[arg-type]
    assert orientation_prediction_warning(_summary(2e-3, 1e-3, n=3, rejected=3), 1.5, 0.99) is None
    assert orientation_prediction_warning({}, 1.5, 0.99) is None
