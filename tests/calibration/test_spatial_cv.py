"""Model selection off the training region: spatial folds, the capped gross-error screen, figures
over every pose with one value each, the residual map's noise floor and support, and the
repeatability a recorded calibration takes as known."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.calibration import report
from pipeline.calibration.crossval import heldout_figures, screen_capped, spatial_folds
from pipeline.calibration.noise_model import NoiseModel, noise_of_robot
from pipeline.calibration.residual_map import fit_residual_map, support_radius_rad
from pipeline.calibration.selection_scores import Candidate, CandidateScore, ModelSelection
from pipeline.robot.repeatability import REPEATABILITY_KEY, repeatability_for_calibration, repeatability_sigma_m
from pipeline.robot.residual_map import ResidualMap
from pipeline.run import headline_rows as hr


def _blobs(rng: np.random.Generator, n_blobs: int, per_blob: int, spread: float = 0.05
           ) -> tuple[np.ndarray, np.ndarray]:
    centres = rng.uniform(-2.0, 2.0, (n_blobs, 6))
    label = np.repeat(np.arange(n_blobs), per_blob)
    return centres[label] + spread * rng.standard_normal((len(label), 6)), label


def test_spatial_folds_keep_neighbouring_poses_together_and_balance_the_folds():
    rng = np.random.default_rng(0)
    Q, blob = _blobs(rng, 10, 7)
    order = rng.permutation(len(Q))                  # file order says nothing about the place
    Q, blob = Q[order], blob[order]
    fold = spatial_folds(Q, 5)
    assert set(fold.tolist()) == set(range(5))
    for b in range(10):                              # a neighbourhood is never split between folds
        assert len(set(fold[blob == b].tolist())) == 1
    sizes = np.bincount(fold)
    assert sizes.max() - sizes.min() <= 7
    assert np.array_equal(fold, spatial_folds(Q, 5))  # a function of the poses
    # file order modulo k would put every neighbourhood in every fold
    assert all(len(set((np.arange(len(Q)) % 5)[blob == b].tolist())) > 1 for b in range(10))


def _parts(errors: np.ndarray, bad: np.ndarray, var: np.ndarray, folds: int = 4):
    fold = np.arange(len(errors)) % folds
    return [(f, errors[fold == f], 2 * errors[fold == f], var[fold == f], bad[fold == f]) for f in range(folds)]


def test_a_screen_that_would_leave_out_more_than_the_allowed_fraction_leaves_out_none():
    """12 clean readings, 3 flagged (25 % against 10 %): every pose counts, and it says so."""
    rng = np.random.default_rng(1)
    e = np.abs(1e-4 * (1 + 0.3 * rng.standard_normal(12)))
    bad = np.zeros(12, bool)
    bad[[2, 5, 9]] = True
    e[bad] *= 5
    var = np.full(12, (1.2e-4) ** 2)
    assert screen_capped(bad, 0.1) and not screen_capped(bad, 0.25)
    out = heldout_figures(_parts(e, bad, var), 4, 0.1)
    assert out["screen_capped"] and out["n_rejected"] == 0 and out["n_poses"] == 12
    assert out["rms_position_error_m"] == out["rms_position_error_all_poses_m"] == pytest.approx(
        np.sqrt(np.mean(e ** 2)), rel=1e-12)
    # within the allowed fraction the flagged reading is left out, the all-poses figure stands beside
    one = np.zeros(12, bool)
    one[5] = True
    out = heldout_figures(_parts(e, one, var), 4, 0.1)
    assert not out["screen_capped"] and out["n_rejected"] == 1 and out["n_poses_all"] == 12
    assert out["rms_position_error_m"] < out["rms_position_error_all_poses_m"]


def test_every_ratio_is_the_ratio_of_the_figures_beside_it():
    rng = np.random.default_rng(2)
    n = 20
    e = np.abs(1e-4 * (1 + 0.3 * rng.standard_normal(n)))
    e[3] = 5e-3
    var = (1e-4 * (1 + 0.1 * rng.random(n))) ** 2
    gross = np.zeros(n, bool)
    gross[3] = True
    fold = np.arange(n) % 5
    score = CandidateScore(Candidate("joint_offsets", False), 9, fold, e, None, ~gross, var, 3 * e)
    sel = ModelSelection(5, [score], score.candidate, gross=gross, max_fraction=0.1)
    cv = sel.cross_validation()
    assert cv["n_poses"] == n - 1 and cv["n_gross_left_out"] == 1
    assert cv["actual_over_predicted"] == cv["rms_position_error_m"] / cv["predicted_rms_position_error_m"]
    assert cv["actual_over_predicted_all_poses"] == (cv["rms_position_error_all_poses_m"]
                                                     / cv["predicted_rms_position_error_all_poses_m"])
    assert cv["rms_position_error_m"] == pytest.approx(np.sqrt(np.mean(e[~gross] ** 2)), rel=1e-12)
    assert cv["rms_position_error_before_m"] == pytest.approx(3 * cv["rms_position_error_m"], rel=1e-12)
    assert "joint space" in sel.markdown()


@pytest.fixture(scope="module")
def noisy_field():
    rng = np.random.default_rng(3)
    Q = rng.uniform(-0.6, 0.6, (60, 6))
    field = 3e-4 * np.column_stack([np.sin(2 * Q[:, 0]), np.cos(Q[:, 1] + Q[:, 2]), np.sin(Q[:, 3])])
    return Q, field + 10e-6 * rng.standard_normal(field.shape), rng


def test_residual_map_noise_floors_at_the_known_noise(noisy_field):
    Q, D, _ = noisy_field
    floor = 25e-6                                   # the sensor says more than the 10 µm the field was read with
    rmap = fit_residual_map(Q, D, 5, noise_floor_m=floor)
    assert rmap.noise_std_m >= floor * (1 - 1e-6)
    _, std = rmap.predict(Q)
    assert np.sqrt(np.mean(std ** 2) + rmap.noise_std_m ** 2) >= floor
    # without the floor the likelihood takes the field's own 10 µm, below the sensor's
    assert fit_residual_map(Q, D, 5).noise_std_m < floor


def test_residual_map_falls_back_outside_its_support_and_widens(noisy_field):
    Q, D, _ = noisy_field
    rmap = fit_residual_map(Q, D, 5, noise_floor_m=10e-6)
    r = rmap.support_radius_rad
    assert r == pytest.approx(support_radius_rad(Q))
    assert np.all(rmap.support_weight(Q) > 0.9)
    direction = np.ones(6) / np.sqrt(6)
    far = Q.mean(0) + (np.abs(Q).max() * np.sqrt(6) + 6 * r) * direction
    mean, std = rmap.predict(far[None])
    assert rmap.support_weight(far[None])[0] < 1e-3
    assert np.all(np.abs(mean) < 1e-3 * np.abs(D).max())
    assert std[0] == pytest.approx(rmap.signal_std_m, rel=1e-3)
    # the untapered map (same posterior) would carry its mean there and claim less uncertainty
    plain = ResidualMap(rmap.inputs_rad, rmap.alpha_m, rmap.cholesky, rmap.length_scale_rad, rmap.signal_std_m,
                        rmap.noise_std_m, None)
    near = Q.mean(0) + (np.abs(Q).max() * np.sqrt(6) + r) * direction
    assert rmap.predict(near[None])[1][0] >= plain.predict(near[None])[1][0]


def test_tapered_map_derivatives_match_finite_differences(noisy_field):
    Q, D, rng = noisy_field
    rmap = fit_residual_map(Q, D, 5, noise_floor_m=10e-6)
    ray = Q.mean(0) + np.outer(np.linspace(0.0, 20.0, 401), np.ones(6) / np.sqrt(6))
    q = ray[np.argmax(rmap.support_weight(ray) < 0.6)]      # on the taper's slope
    assert 0.2 < rmap.support_weight(q[None])[0] < 0.6
    v = rng.standard_normal(6)
    h = 1e-5
    fd = np.column_stack([(rmap.mean(q + h * e) - rmap.mean(q - h * e)) / (2 * h) for e in np.eye(6)])
    assert np.allclose(rmap.jacobian(q), fd, rtol=1e-5, atol=1e-9 * np.abs(fd).max())
    h = 1e-4
    fd2 = (rmap.mean(q + h * v) - 2 * rmap.mean(q) + rmap.mean(q - h * v)) / h ** 2
    assert np.allclose(rmap.drift(q, v), fd2, rtol=1e-3, atol=1e-6 * np.abs(fd2).max())


def test_map_saved_without_a_support_radius_loads_untapered(noisy_field):
    Q, D, _ = noisy_field
    rmap = fit_residual_map(Q, D, 5)
    arrays = rmap.to_arrays()
    back = ResidualMap.from_arrays(arrays)
    assert back is not None and back.support_radius_rad == pytest.approx(rmap.support_radius_rad)
    arrays["residual_map_hyperparameters"] = arrays["residual_map_hyperparameters"][:3]
    old = ResidualMap.from_arrays(arrays)
    assert old is not None and old.support_radius_rad is None and np.all(old.support_weight(Q[:3] + 50.0) == 1.0)


def _robot(rp_m: float | None, assumed: bool) -> SimpleNamespace:
    entry = {REPEATABILITY_KEY: {"rule": "reach class", "sha256": "x"}} if assumed else {}
    return SimpleNamespace(spec=SimpleNamespace(repeatability_m=rp_m, assumed=entry))


def test_a_recorded_file_decides_the_repeatability_robot_init_assumed():
    assert repeatability_for_calibration(0.05e-3, assumed=True, recorded=True) == (0.0, "data")
    assert repeatability_for_calibration(0.05e-3, assumed=True, recorded=False) == (
        repeatability_sigma_m(0.05e-3), "assumed")
    assert repeatability_for_calibration(2e-3, assumed=False, recorded=True) == (repeatability_sigma_m(2e-3), "stated")
    assert repeatability_for_calibration(None, assumed=False, recorded=True) == (0.0, "none")
    data = noise_of_robot(_robot(0.05e-3, True), recorded=True)
    assert data.repeatability_sigma_m == 0.0 and data.repeatability_not_used_m == 0.05e-3
    assert "from the data" in report.repeatability_source_text(data) and "0.05 mm" in report.repeatability_source_text(
        data)
    stated = noise_of_robot(_robot(2e-3, False), recorded=True)
    assert stated.repeatability_sigma_m == repeatability_sigma_m(2e-3)
    assert "as stated" in report.repeatability_source_text(stated)
    assert stated.as_dict()["repeatability_source"] == "stated"
    # the remainder the data give is then the whole scatter beyond the sensor
    assert np.allclose(NoiseModel(0.0, (1.68e-3, 0.0)).total(np.full(3, 13.5e-6)),
                       np.hypot(13.5e-6, 1.68e-3))


def test_headline_shows_the_all_poses_figure_and_the_summarys_ratio():
    """The cross-validated headline of a record whose screen left a pose out: the figure over every
    pose beside the screened one, and actual/predicted as summary.json holds it."""
    n = 12
    e = np.full(n, 1e-4)
    e[4] = 4e-3
    gross = np.zeros(n, bool)
    gross[4] = True
    fold = np.arange(n) % 5
    score = CandidateScore(Candidate("joint_offsets", False), 9, fold, e, None, ~gross, np.full(n, 1.5e-8), 2 * e)
    cv = ModelSelection(5, [score], score.candidate, gross=gross, max_fraction=0.1).cross_validation()
    assert cv["n_rejected"] == 1
    summary = {"cross_validation": cv, "noise_total_sigma_m": 5e-5, "measurement_source": "poses.csv"}
    (row,) = [r for r in hr.stage_rows("calibration", summary) if "actual / predicted" in r.figure]
    assert f"all {n} poses" in row.value
    assert row.ratio == hr.ratio(cv["actual_over_predicted"])


@pytest.mark.slow
def test_a_twelve_reading_calibration_counts_its_clean_poses(tmp_path):
    """12 clean readings with the defaults (parameters auto, 5 spatial folds): the screen leaves out
    at most max_outlier_fraction of them, and summary.json and the headline carry one
    actual/predicted."""
    from pipeline.calibration import candidates as cd
    from pipeline.calibration import measure as ms
    from pipeline.calibration import stage as st
    from pipeline.robot.model import RobotModel
    from pipeline.sim.truth import RealRobot

    robot = RobotModel.load("rx130l")
    real = RealRobot.create(robot, 2)
    rng = np.random.default_rng(2)
    Q, _ = cd.random_candidates(cd.chain_from_robot(robot), 20, rng)
    meas = ms.measure_simulated(real, Q, rng)
    path = ms.write_csv(tmp_path / "twelve.csv", ms.Measurements(meas.Q[:12], meas.Y[:12], meas.sigma_m[:12], "sim"))
    cfg = st.Config(measurements_csv=str(path), figures=False, design_table=False)
    out = st.calibrate(robot, None, cfg, np.random.default_rng(0))
    summary = st.summary_of(out, cfg)
    cv = summary["cross_validation"]
    assert cv["n_poses_all"] == 12 and cv["n_rejected"] <= int(0.1 * 12)
    assert cv["actual_over_predicted"] == cv["rms_position_error_m"] / cv["predicted_rms_position_error_m"]
    (row,) = [r for r in hr.stage_rows("calibration", summary) if "actual / predicted" in r.figure]
    assert row.ratio == hr.ratio(cv["actual_over_predicted"])
