"""The residual map's uncertainty in the calibration's predicted errors, and its hand-on only when
the model selection chose it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.calibration import measure as ms
from pipeline.calibration import model_selection as msel
from pipeline.calibration import stage as st
from pipeline.calibration import validate as va
from pipeline.calibration.crossval import cross_validate
from pipeline.calibration.estimate import estimate
from pipeline.calibration.residual_map import fit_residual_map
from tests.calibration.simulated_readings import SIGMA_M, rx130l_readings


def _field_m(Q: np.ndarray) -> np.ndarray:
    """A smooth non-geometric error of the arm (base frame), 0.2 mm: what no kinematic parameter fits."""
    return 2e-4 * np.column_stack([np.sin(2 * Q[:, 0]) * np.cos(Q[:, 1]), np.cos(2 * Q[:, 2]),
                                   np.sin(Q[:, 1] + 2 * Q[:, 3])])


@pytest.fixture(scope="session")
def setting():
    return rx130l_readings(120, "simulated (field)", _field_m)


def test_predicted_error_with_the_map_takes_the_maps_reading_variance(setting):
    """With the map applied, a reading's part of the predicted error is the map's: its posterior
    variance and the noise it did not explain, ``3 (s_map^2 + s_n^2)``, in place of ``3 sigma^2``
    (a sigma whose remainder also held the field the map explains); the model part is unchanged."""
    robot, mm, basis, meas, rng = setting
    est = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis)
    R_tb = est.transform_tracker_to_base.rotation
    residual = (meas.Y - mm.predict(meas.Q, est.x, est.registration)) @ R_tb.T
    rmap = fit_residual_map(meas.Q, residual, rng)
    Qh = meas.Q[:10] + 0.3
    sigma = np.full(10, 3e-4)       # a remainder the size of the field, as the rigid fit's REML states it
    plain = va.predicted_error(mm, est, Qh, sigma)
    mapped = va.predicted_error(mm, est, Qh, sigma, residual_map=rmap)
    var_post = 3 * np.mean(rmap.predict(Qh)[1] ** 2)
    var_reading = var_post + 3 * rmap.noise_std_m ** 2
    assert var_post > 0 and rmap.noise_std_m < 3e-4
    assert mapped["predicted_rms_m"] ** 2 == pytest.approx(plain["predicted_rms_m"] ** 2 - 3 * 3e-4 ** 2
                                                           + var_reading, rel=1e-9)
    assert mapped["predicted_residual_map_rms_m"] ** 2 == pytest.approx(var_post, rel=1e-9)
    assert mapped["predicted_model_rms_m"] == pytest.approx(plain["predicted_model_rms_m"], rel=1e-9)


def test_cross_validation_with_the_map_scores_model_plus_map_and_predicts_its_uncertainty(setting):
    robot, mm, basis, meas, _ = setting
    sigma = np.full(len(meas), SIGMA_M)
    plain = cross_validate(mm, meas, basis, sigma, 5, 50)
    mapped = cross_validate(mm, meas, basis, sigma, 5, 50, map_rng=np.random.default_rng(1))
    assert mapped["n_poses"] == plain["n_poses"] == len(meas)
    assert mapped["rms_position_error_m"] < plain["rms_position_error_m"]
    assert mapped["predicted_rms_position_error_m"] > plain["predicted_rms_position_error_m"]
    # with its own uncertainty the map's prediction stays honest
    assert 1 / 1.5 <= mapped["actual_over_predicted"] <= 1.5
    # interleaved folds (file order modulo 5) hold out poses among the training ones: the map only
    # interpolates there and looks better than where it must extrapolate (the spatial folds)
    interleaved = np.arange(len(meas)) % 5
    plain_i = cross_validate(mm, meas, basis, sigma, 5, 50, fold_of_pose=interleaved)
    mapped_i = cross_validate(mm, meas, basis, sigma, 5, 50, map_rng=np.random.default_rng(1), fold_of_pose=interleaved)
    gain_spatial = mapped["rms_position_error_m"] / plain["rms_position_error_m"]
    gain_interleaved = mapped_i["rms_position_error_m"] / plain_i["rms_position_error_m"]
    assert gain_interleaved < 0.9 and gain_interleaved < gain_spatial


def test_the_map_is_handed_on_only_when_chosen(setting):
    robot, mm, basis, meas, rng = setting
    est = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis)
    rejected = np.zeros(0, int)

    def selection(with_map: bool):
        return SimpleNamespace(chosen=msel.Candidate("geometric", with_map))

    assert msel.final_residual_map(selection(False), mm, est, meas, meas, rejected, rng) is None
    assert msel.final_residual_map(None, mm, est, meas, meas, rejected, rng) is None
    rmap = msel.final_residual_map(selection(True), mm, est, meas, meas, rejected, rng)
    assert rmap is not None and len(rmap.inputs_rad) == len(meas)


def test_a_chosen_map_predicts_its_heldout_error(tmp_path):
    """A 0.5 mm field no parameter fits, 140 readings to calibrate and 60 held out, every default:
    the selection chooses the map, and the held-out and cross-validated errors match their
    predictions (the reading's part the map's own, not the rigid fit's remainder beside it, which
    counted the field twice and predicted 1.6-2.3 times the error)."""
    robot, mm, basis, meas, rng = rx130l_readings(200, "simulated (field)", lambda Q: 2.5 * _field_m(Q), seed=7)
    parts = {name: ms.write_csv(tmp_path / f"{name}.csv", ms.Measurements(meas.Q[rows], meas.Y[rows],
                                                                           meas.sigma_m[rows], name))
             for name, rows in (("fit", slice(0, 140)), ("val", slice(140, 200)))}
    cfg = st.Config(measurements_csv=str(parts["fit"]), validation_csv=str(parts["val"]), figures=False)
    cfg.validate()
    out = st.calibrate(robot, None, cfg, np.random.default_rng(0))
    s = st.summary_of(out, cfg)
    assert out.notes.model_selection.chosen.residual_map
    assert 0.8 <= s["actual_over_predicted"] <= 1.25
    assert 0.8 <= s["cross_validation"]["actual_over_predicted"] <= 1.25
