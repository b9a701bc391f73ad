"""6-D (motion-capture) records: the simulator's convention and what a small record can give."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.calibration import candidates as cd
from pipeline.calibration import stage as st
from pipeline.papers.calib_six_d import simulate_six_d_record, six_d_trial
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot


@pytest.fixture(scope="session")
def robot() -> RobotModel:
    return RobotModel.load("rx130l")


@pytest.fixture(scope="session")
def real(robot) -> RealRobot:
    return RealRobot.create(robot, 8)


def test_simulated_record_follows_the_csv_rotation_convention(robot, real):
    """``R = exp(r^)`` maps marker axes to tracker axes; the noise is a marker-frame rotation of
    ``sigma_rot`` per axis and the position noise ``sigma_p`` per axis."""
    rng = np.random.default_rng(0)
    Q = cd.random_candidates(cd.chain_from_robot(robot), 400, rng, visibility=False)[0]
    exact = simulate_six_d_record(real, Q, rng, 0.0, 0.0)
    P, R = real.truth.poses(real.link_angles(Q), "reflector")
    T = real.transform_tracker_to_base
    R_meas = Rotation.from_rotvec(exact.rotvec).as_matrix()
    assert np.allclose(np.einsum("ij,njk->nik", T.rotation, R_meas), R, atol=1e-12)   # base = T tracker
    assert np.allclose(exact.Y @ T.rotation.T + T.translation, P, atol=1e-12)
    noisy = simulate_six_d_record(real, Q, rng, 1e-4, 1e-3)
    w = (Rotation.from_rotvec(exact.rotvec).inv() * Rotation.from_rotvec(noisy.rotvec)).as_rotvec()
    assert np.allclose(w.std(axis=0), 1e-3, rtol=0.15)
    assert np.allclose((noisy.Y - exact.Y).std(axis=0), 1e-4, rtol=0.15)


def test_orientation_gain_is_limited_by_the_orientation_noise(robot, real, tmp_path):
    """23 mocap poses: the position gains >= 5x; the orientation error left after the fit is
    estimation noise: it shrinks with the orientation noise and with more poses, and the
    covariance prediction of the validation (exact held-out poses) matches it within 1.5."""
    after = {}
    for n, sigma_rad in ((23, 1e-3), (23, 3e-4), (92, 1e-3)):
        trial = six_d_trial(robot, real, n, np.random.default_rng(8), tmp_path / f"{n}_{sigma_rad}",
                            orientation_sigma_rad=sigma_rad)
        g = trial.gains
        assert g["position_gain"] >= 5
        assert 1 / 1.5 <= g["orientation_predicted_rad"] / g["orientation_after_rad"] <= 1.5
        after[n, sigma_rad] = g["orientation_after_rad"]
        if sigma_rad == 1e-3 and n == 23:
            assert "predicted, model part" in st.report_markdown(trial.outcome, trial.config, robot)
    assert after[23, 3e-4] < 0.75 * after[23, 1e-3]
    assert after[92, 1e-3] < 0.8 * after[23, 1e-3]
