"""parameters auto: the one-standard-error rule, the orientation weight (nested per fold) and the
Gaussian-process residual map."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.calibration import marker_frame as mf
from pipeline.calibration import measure as ms
from pipeline.calibration import subsets
from pipeline.calibration.config import Config
from pipeline.calibration.crossval import spatial_folds
from pipeline.calibration.model_selection import (
    ORIENTATION_SCALES,
    Candidate,
    CandidateScore,
    nested_orientation_weights,
    one_standard_error,
    orientation_weight,
    standard_errors_above_best,
)
from pipeline.calibration.noise_model import NoiseModel
from pipeline.calibration.residual_map import fit_residual_map
from pipeline.robot.residual_map import ResidualMap

FOLDS = np.arange(40) % 5
#: pose-to-pose spread of held-out errors, common to all candidates (the same poses are held out)
SPREAD = np.abs(1.0 + 0.4 * np.random.default_rng(0).standard_normal(40))


def _score(parameters: str, n: int, rms_m: float, rng: np.random.Generator, residual_map: bool = False
           ) -> CandidateScore:
    e = rms_m * SPREAD * (1.0 + 0.02 * rng.standard_normal(40))
    return CandidateScore(Candidate(parameters, residual_map), n, FOLDS, e, None)


def test_one_standard_error_prefers_the_simpler_model_unless_the_richer_is_clearly_better():
    rng = np.random.default_rng(1)
    simple = _score("joint_offsets", 10, 1.00e-3, rng)
    close = _score("geometric", 30, 0.97e-3, rng)
    assert one_standard_error([simple, close]).parameters == "joint_offsets"
    far = _score("geometric", 30, 0.40e-3, rng)
    assert one_standard_error([simple, far]).parameters == "geometric"


def test_one_standard_error_needs_orientation_too_for_six_d_readings():
    rng = np.random.default_rng(2)
    simple = _score("joint_offsets", 10, 1.0e-3, rng)
    rich = _score("geometric", 30, 1.0e-3, rng)
    simple.orientation_error_rad = np.full(40, 0.02) * (1 + 0.1 * rng.standard_normal(40))
    rich.orientation_error_rad = np.full(40, 0.005) * (1 + 0.1 * rng.standard_normal(40))
    assert one_standard_error([simple, rich]).parameters == "geometric"


def test_a_six_d_candidate_far_off_in_orientation_does_not_win_on_position_alone():
    rng = np.random.default_rng(4)
    simple = _score("joint_offsets", 10, 1.00e-3, rng)     # best in position, far off in orientation
    axes = _score("joint_axes", 20, 1.25e-3, rng)          # a little beyond one SE in position, best in orientation
    rich = _score("geometric", 30, 1.60e-3, rng)           # far off in position, as good in orientation
    for score, rms in ((simple, 0.02), (axes, 0.005), (rich, 0.005)):
        score.orientation_error_rad = rms * SPREAD * (1 + 0.02 * rng.standard_normal(40))
    excess = standard_errors_above_best([simple, axes, rich])
    assert 1.0 < excess[id(axes)] < min(excess[id(simple)], excess[id(rich)])
    assert one_standard_error([simple, axes, rich]).parameters == "joint_axes"
    # without the orientation errors the position error alone decides, and the simplest wins
    for score in (simple, axes, rich):
        score.orientation_error_rad = None
    assert one_standard_error([simple, axes, rich]).parameters == "joint_offsets"


def test_a_failed_fold_disqualifies_a_candidate():
    rng = np.random.default_rng(3)
    broken = _score("geometric", 30, 0.1e-3, rng)
    broken.position_error_m[:8] = np.nan
    assert one_standard_error([_score("joint_offsets", 10, 1e-3, rng), broken]).parameters == "joint_offsets"


def test_auto_is_the_default_and_means_all_without_a_measurement_file():
    assert Config().parameters == "auto"
    names = ["j2.dq", "j2.dx", "j2.c", "tracker.dx", "tool.rx"]
    assert subsets.select("auto", names) == subsets.select("all", names)
    assert subsets.wants_compliance("auto")
    # the marker's rotation on the flange is part of the set-up in every subset
    assert "tool.rx" in [names[i] for i in subsets.select("joint_offsets", names)]


@pytest.fixture(scope="session")
def smooth_field():
    """A smooth millimetre-size field over 6 joint angles, read with 30 µm noise."""
    rng = np.random.default_rng(4)

    def field(Q: np.ndarray) -> np.ndarray:
        return 1e-3 * np.column_stack([np.sin(Q[:, 1]) * np.cos(Q[:, 2]), np.cos(Q[:, 1] + Q[:, 0]),
                                       0.5 * np.sin(Q[:, 2] - Q[:, 3])])

    Q = rng.uniform(-1.0, 1.0, (150, 6))
    D = field(Q) + 30e-6 * rng.standard_normal((150, 3))
    return field, Q, D, fit_residual_map(Q, D, rng)


def test_residual_map_learns_a_smooth_field_and_knows_where_it_does_not(smooth_field):
    field, _, _, rmap = smooth_field
    rng = np.random.default_rng(5)
    Q_new = rng.uniform(-0.8, 0.8, (200, 6))
    truth = field(Q_new)
    mean, std = rmap.predict(Q_new)
    rms_before = np.sqrt(np.mean(np.sum(truth ** 2, axis=1)))
    rms_after = np.sqrt(np.mean(np.sum((truth - mean) ** 2, axis=1)))
    assert rms_after < 0.2 * rms_before
    # its stated uncertainty is honest inside the data (per-axis error against per-axis std)
    assert 0.5 < np.sqrt(np.mean((truth - mean) ** 2)) / np.sqrt(np.mean(std ** 2)) < 2.0
    # far from every calibration pose: no correction, the prior's full uncertainty
    far_mean, far_std = rmap.predict(np.full((1, 6), 40.0))
    assert np.all(np.abs(far_mean) < 1e-9) and far_std[0] == pytest.approx(rmap.signal_std_m, rel=1e-6)
    positions = np.zeros((len(Q_new), 3))
    assert np.allclose(rmap.correct(positions, Q_new), mean)


def test_residual_map_hand_off_round_trip(smooth_field):
    _, Q, _, rmap = smooth_field
    back = ResidualMap.from_arrays(rmap.to_arrays())
    assert back is not None
    for a, b in zip(rmap.predict(Q[:10]), back.predict(Q[:10]), strict=True):
        assert np.array_equal(a, b)
    assert ResidualMap.from_arrays({}) is None


def test_project_to_rotation_returns_the_rotation_of_a_perturbed_one():
    rng = np.random.default_rng(6)
    R = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    R *= np.sign(np.linalg.det(R))
    P = mf.project_to_rotation(R + 1e-3 * rng.standard_normal((3, 3)))
    assert np.allclose(P @ P.T, np.eye(3), atol=1e-12) and np.linalg.det(P) > 0
    assert np.abs(P - R).max() < 5e-3


def _weighted_scores(best_kappa: float):
    """(plain, mapped) scores whose position and orientation errors grow with |log(kappa / best)|."""
    calls: list[float] = []

    def scored(kappa: float):
        calls.append(kappa)
        grow = 1.0 + 0.2 * abs(np.log2(kappa / best_kappa))
        s = CandidateScore(Candidate("geometric", False), 30, FOLDS, 1e-3 * grow * SPREAD, 5e-3 * grow * SPREAD)
        return s, s

    return scored, calls


@pytest.mark.parametrize("best", [0.25, 1.0, 4.0])
def test_orientation_weight_walks_to_the_best_factor(best):
    scored, calls = _weighted_scores(best)
    kappa, done = orientation_weight(scored)
    assert kappa == best and set(done) == set(calls) and len(calls) == len(set(calls))
    # the walk stops one step past the optimum: it never scores the whole grid
    assert len(calls) <= len(ORIENTATION_SCALES) - 1


def _six_d_record(n: int = 25) -> ms.Measurements:
    rng = np.random.default_rng(7)
    return ms.Measurements(rng.uniform(-2.0, 2.0, (n, 6)), rng.uniform(-1.0, 1.0, (n, 3)), np.full(n, 1e-4),
                           "synthetic", rng.normal(0.0, 0.3, (n, 3)))


def test_nested_weights_are_chosen_on_each_folds_training_poses_alone():
    """Each outer fold's weight comes from a cross-validation of its training poses: readings of a
    held-out fold, however changed, leave that fold's weight as it was and move the others'."""
    meas = _six_d_record()
    fold = spatial_folds(meas.Q, 5)
    seen: list[np.ndarray] = []

    def scored(sub: ms.Measurements, inner: np.ndarray, kappa: float) -> CandidateScore:
        # a score whose best factor is 2 ** (5 x mean x reading of the training poses): a function of them
        seen.append(sub.Q)
        assert len(inner) == len(sub) and inner.max() + 1 == 5 and sub.rotvec is not None
        best = np.clip(5.0 * float(np.mean(sub.Y[:, 0])), -2.0, 2.0)
        grow = np.sqrt(1.0 + 0.3 * (np.log2(kappa) - best) ** 2) * np.ones(len(sub))
        return CandidateScore(Candidate("geometric", False), 30, inner, 1e-3 * grow, 5e-3 * grow)

    scales = nested_orientation_weights(meas, fold, 5, scored)
    assert scales.shape == (5,) and np.all((scales >= 0.25) & (scales <= 4.0))
    for Q in seen:      # no inner cross-validation saw a pose of the fold it chose the weight for
        held = [f for f in range(5) if not any((Q == q).all(axis=1).any() for q in meas.Q[fold == f])]
        assert len(held) == 1
    moved = ms.Measurements(meas.Q, meas.Y + np.where(fold == 0, 0.8, 0.0)[:, None], meas.sigma_m, "moved",
                            meas.rotvec)
    again = nested_orientation_weights(moved, fold, 5, scored)
    assert again[0] == scales[0]
    assert np.all(again[1:] > scales[1:])


def test_orientation_scale_weights_only_the_marker_point_rows():
    noise = NoiseModel(1e-5, (2e-3, 3e-3), orientation_scale=0.5)
    sensor = np.full(4, 1e-5)
    groups = np.array([0, 0, 1, 1])
    total = noise.total(sensor, groups)
    plain = NoiseModel(1e-5, (2e-3, 3e-3)).total(sensor, groups)
    assert np.allclose(total[:2], plain[:2]) and np.allclose(total[2:], 0.5 * plain[2:])


def test_joint_axes_lies_between_the_offsets_and_the_geometric_set():
    names = ["j2.dx", "j2.dz", "j2.rx", "j2.ry", "j2.rz", "j2.dq", "j3.da", "j3.dalpha", "j3.dtheta", "j3.beta",
             "j3.dd", "j2.c", "tracker.dx", "reflector.dz", "tool.ry", "tool.dx"]
    axes = {names[i] for i in subsets.select("joint_axes", names)}
    assert axes == {"j2.rx", "j2.ry", "j2.rz", "j2.dq", "j3.dalpha", "j3.dtheta", "j3.beta",
                    "tracker.dx", "reflector.dz", "tool.ry"}
    offsets = {names[i] for i in subsets.select("joint_offsets", names)}
    geometric = {names[i] for i in subsets.select("geometric", names)}
    assert offsets < axes < geometric
    assert not subsets.wants_compliance("joint_axes")
    subsets.check_parameters("joint_axes")
