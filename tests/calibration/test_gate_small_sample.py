"""The actual/predicted gate as a one-sided test: the sum of squared held-out errors against its
quantile under "the true ratio is at most m" (pipeline.calibration.validate)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from pipeline.calibration import candidates as cd
from pipeline.calibration import error_model as em
from pipeline.calibration import gates as cg
from pipeline.calibration import measure as ms
from pipeline.calibration import stage as st
from pipeline.calibration import validate as va
from pipeline.calibration.estimate import estimate
from pipeline.calibration.gravity_uncertainty import GravityCovariance, GravityPrior
from pipeline.calibration.residual_map import fit_residual_map
from pipeline.calibration.robust import robust_estimate
from pipeline.quality import QualityGates
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot
from tests.calibration.simulated_readings import SIGMA_M, rx130l_readings

M = 1.5
LEVEL = 0.99


def _moments(C: np.ndarray, exact: bool = True) -> dict:
    """The stacked-covariance entries :func:`cg.ratio_test` reads, of a given covariance."""
    return {"stacked_components": len(C), "stacked_trace_m2": float(np.trace(C)),
            "stacked_square_trace_m4": float(np.sum(C * C)),
            "stacked_eigenvalues_m2": np.linalg.eigvalsh(C) if exact else None}


def _dominated(rng: np.random.Generator, n_poses: int, rank: int = 2, model_over_noise: float = 6.0) -> np.ndarray:
    """Stacked covariance of ``n_poses`` poses: a parameter part of ``rank`` directions shared by every
    pose (``model_over_noise`` times the noise's per-axis std) plus independent reading noise."""
    F = model_over_noise * SIGMA_M * rng.standard_normal((3 * n_poses, rank))
    return F @ F.T + SIGMA_M ** 2 * np.eye(3 * n_poses)


def test_threshold_of_a_large_isotropic_sample_approaches_m():
    """Noise alone (isotropic, independent poses): nu = 3N; the bound is m sqrt(chi2_nu(a)/nu),
    shrinking towards m as the poses grow, never reaching it."""
    bounds = []
    for n_poses in (3, 30, 200, 1000):
        C = np.eye(3 * n_poses) * SIGMA_M ** 2
        test = cg.ratio_test(_moments(C, exact=3 * n_poses <= va.EXACT_QUANTILE_MAX_COMPONENTS), M, LEVEL)
        assert test["effective_dof"] == pytest.approx(3 * n_poses)
        assert test["threshold"] == pytest.approx(M * np.sqrt(chi2.ppf(LEVEL, 3 * n_poses) / (3 * n_poses)), rel=1e-6)
        bounds.append(test["threshold"] / M)
    assert bounds == sorted(bounds, reverse=True) and bounds[-1] > 1.0
    assert bounds[-1] < 1.05 and bounds[-2] < 1.10 and bounds[0] > 1.5
    big = cg.ratio_test(_moments(np.eye(3000) * SIGMA_M ** 2, exact=False), M, LEVEL)
    assert big["method"] == "Satterthwaite-Welch"


def test_three_poses_of_a_dominated_covariance_widen_the_bound():
    """Three poses whose prediction is mostly the shared parameter error: few effective degrees of
    freedom, so a sample ratio well above m is still within the spread of an RMS over them."""
    C = _dominated(np.random.default_rng(0), 3)
    test = cg.ratio_test(_moments(C), M, LEVEL)
    iso = cg.ratio_test(_moments(np.eye(9) * np.trace(C) / 9), M, LEVEL)
    assert test["method"] == "Imhof" and test["n_scored_poses"] == 3
    assert test["effective_dof"] < 3
    assert test["threshold"] > 1.3 * iso["threshold"] > 1.3 * M
    assert test["lower_threshold"] < iso["lower_threshold"] < 1 / M


@pytest.mark.parametrize("n_poses", [3, 40])
def test_the_test_holds_its_level_and_rejects_a_doubled_error(n_poses):
    """Errors drawn from N(0, (k m)^2 C): k = 1 (the hypothesis' edge) fails the gate at about
    1 - a of the seeded draws, k = 2 with many poses fails always; the pessimistic warning at the
    mirror edge k = 1/m^2 (ratio 1/m) fires at about 1 - a too."""
    rng = np.random.default_rng(11 + n_poses)
    C = _dominated(rng, n_poses)
    test = cg.ratio_test(_moments(C), M, LEVEL)
    L = np.linalg.cholesky(C)
    draws = 4000
    z = rng.standard_normal((draws, len(C))) @ L.T

    def ratio(k: float) -> np.ndarray:
        e = k * z
        return np.sqrt(np.sum(e ** 2, axis=1) / np.trace(C))

    # binomial 99.9 % band around 1 % of 4000 draws: 40 +- 20
    assert 20 <= np.sum(ratio(M) > test["threshold"]) <= 62
    assert 20 <= np.sum(ratio(1 / M) < test["lower_threshold"]) <= 62
    if n_poses >= 40:
        big = np.eye(3 * 400) * SIGMA_M ** 2       # many poses, noise-dominated
        t_big = cg.ratio_test(_moments(big, exact=False), M, LEVEL)
        e = 2 * M * SIGMA_M * rng.standard_normal((200, len(big)))
        assert np.all(np.sqrt(np.sum(e ** 2, axis=1) / np.trace(big)) > t_big["threshold"])


@pytest.fixture(scope="module")
def fitted():
    robot, mm, basis, meas, rng = rx130l_readings(60, "simulated")
    est = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis)
    return robot, mm, basis, meas, est, rng


def test_stacked_covariance_holds_the_per_pose_prediction(fitted):
    """The stacked covariance's trace is N E|e|^2 of the per-pose prediction (with the residual map's
    reading variance in place of the noise); the parameter error every pose shares makes trace C^2 exceed the sum of the
    per-pose blocks' own (off-diagonal blocks), so the effective dof are below those of the blocks."""
    _, mm, _, meas, est, rng = fitted
    Qh = meas.Q[:12] + 0.2
    sigma = np.full(len(Qh), SIGMA_M)
    R_tb = est.transform_tracker_to_base.rotation
    rmap = fit_residual_map(meas.Q, (meas.Y - mm.predict(meas.Q, est.x, est.registration)) @ R_tb.T, rng)
    for residual_map in (None, rmap):
        mom = va.heldout_error_moments(mm, est, Qh, sigma, residual_map=residual_map)
        pred = va.predicted_error(mm, est, Qh, sigma, residual_map=residual_map)
        assert mom["stacked_components"] == 36
        assert mom["stacked_trace_m2"] == pytest.approx(len(Qh) * pred["predicted_rms_m"] ** 2, rel=1e-9)
        assert np.sum(mom["stacked_eigenvalues_m2"]) == pytest.approx(mom["stacked_trace_m2"], rel=1e-9)
        assert np.sum(mom["stacked_eigenvalues_m2"] ** 2) == pytest.approx(mom["stacked_square_trace_m4"], rel=1e-9)
        blocks, _ = va.predicted_covariance(mm, est, Qh, sigma)
        if residual_map is not None:    # the map's reading variance in place of the reading noise
            blocks = blocks + (residual_map.predict_reading(Qh)[1] ** 2 - sigma ** 2)[:, None, None] * np.eye(3)
        assert mom["stacked_square_trace_m4"] > 1.01 * np.sum(blocks * blocks)


def _gated(summary: dict) -> QualityGates:
    gates = QualityGates("calibration")
    cg.check_gates(gates, summary, st.Config())
    return gates


def test_summary_records_the_test_and_the_gate_uses_its_bound(fitted, tmp_path):
    """A calibration with a validation file: ``actual_over_predicted_test`` in the summary (threshold,
    effective dof, scored poses), the gate's threshold is its bound and its message says so; the
    cross-validated figures keep the fixed bound m."""
    robot, mm, _, meas, _, _ = fitted
    train = ms.write_csv(tmp_path / "train.csv", ms.Measurements(meas.Q[:50], meas.Y[:50], meas.sigma_m[:50], "t"))
    val = ms.write_csv(tmp_path / "val.csv", ms.Measurements(meas.Q[50:], meas.Y[50:], meas.sigma_m[50:], "v"))
    cfg = st.Config(measurements_csv=str(train), validation_csv=str(val), parameters="geometric",
                    identifiability_samples=60, figures=False, position_sigma_m=SIGMA_M,
                    gravity_model_relative_sigma=0.0, gravity_model_com_sigma_m=0.0)
    cfg.validate()
    out = st.calibrate(robot, None, cfg, np.random.default_rng(0))
    s = st.summary_of(out, cfg)
    test = s["actual_over_predicted_test"]
    n = s["heldout_n_poses"] - s["heldout_n_rejected"]
    assert test["n_scored_poses"] == n and test["confidence"] == LEVEL and test["source"] == "held-out"
    assert test["max_actual_over_predicted"] == M and test["method"] == "Imhof"
    assert 1.0 < test["effective_dof"] < 3 * n
    assert test["threshold"] > M and test["lower_threshold"] < 1 / M
    check = next(c for c in _gated(s).checks if c.name == "actual_over_predicted")
    assert check.threshold == pytest.approx(test["threshold"]) and check.value == s["actual_over_predicted"]
    assert f"{n} scored pose(s)" in check.message and "effective dof" in check.message
    # a ratio past the bound fails, one between m and the bound passes
    for ratio, passed in ((0.5 * (M + test["threshold"]), True), (1.01 * test["threshold"], False)):
        probe = s | {"actual_over_predicted": ratio}
        assert next(c for c in _gated(probe).checks if c.name == "actual_over_predicted").passed is passed
    cv = {"chi2_per_dof": 1.0, "actual_over_predicted": None,
          "cross_validation": {"actual_over_predicted": 1.6, "rms_position_error_m": 1e-4,
                               "rms_position_error_before_m": 1e-3}}
    check = next(c for c in _gated(cv).checks if c.name == "actual_over_predicted")
    assert check.threshold == M and not check.passed and "fixed bound" in check.message


def test_confidence_is_checked():
    with pytest.raises(Exception, match="actual_over_predicted_confidence"):
        st.Config(actual_over_predicted_confidence=1.0).validate()
    st.Config(actual_over_predicted_confidence=0.95).validate()


def test_stacked_covariance_with_the_gravity_prior_holds_the_per_pose_blocks():
    """Elastostatic model with the gravity-model prior: the diagonal blocks of the stacked
    covariance are the per-pose prediction (the inertial error's part included)."""
    robot = RobotModel.load("rx130l")
    mm = em.MeasurementModel(robot, compliance=True)
    real = RealRobot.create(robot, 3)
    rng = np.random.default_rng(3)
    Q, _ = cd.random_candidates(cd.chain_from_robot(robot), 60, rng)
    meas = ms.measure_simulated(real, Q, rng)
    rep = em.identifiability(mm.jacobian(em.random_configurations(robot, 100, rng), np.zeros(mm.n),
                                         robot.tracker.transform_tracker_to_base)[1].reshape(-1, mm.n), mm.names)
    basis = em.parameter_basis(rep, mm.n, np.eye(mm.n))
    gravity = GravityCovariance(mm, GravityPrior(0.15, 0.02))
    est, _ = robust_estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis, gravity=gravity)
    Qh, _ = cd.random_candidates(cd.chain_from_robot(robot), 8, rng)
    sigma = np.full(len(Qh), 20e-6)
    blocks, var_gravity = va.predicted_covariance(mm, est, Qh, sigma, gravity)
    assert np.all(var_gravity > 0)
    mom = va.heldout_error_moments(mm, est, Qh, sigma, gravity)
    pred = va.predicted_error(mm, est, Qh, sigma, gravity)
    assert mom["stacked_trace_m2"] == pytest.approx(len(Qh) * pred["predicted_rms_m"] ** 2, rel=1e-9)
    lam = mom["stacked_eigenvalues_m2"]
    assert np.sum(lam ** 2) == pytest.approx(mom["stacked_square_trace_m4"], rel=1e-9)
    assert mom["stacked_square_trace_m4"] > np.sum(blocks * blocks)
