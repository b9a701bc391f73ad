"""The optical 6-D tracker sensor kind (pipeline/sim/optical_tracker.py, robot.yaml optical_tracker)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
import yaml

from pipeline.calibration import candidates as cd
from pipeline.core.errors import RobotFileError
from pipeline.papers import calib_004_optical as op
from pipeline.robot import instruments
from pipeline.robot.model import RobotModel
from pipeline.robot.spec import load_robot_spec
from pipeline.sim import optical_tracker as ot
from pipeline.sim.truth import RealRobot, TruthConfig


@pytest.fixture(scope="module")
def robot() -> RobotModel:
    return RobotModel.load("rx130l")


def _visible_configurations(robot: RobotModel, n: int, seed: int = 0) -> np.ndarray:
    """``n`` configurations of the 7^6 grid the nominal cameras see (fast: the batched grid filter)."""
    Q, _, _ = op.visible_grid(robot, 7)
    return np.random.default_rng(seed).permutation(Q)[:n]


def test_readings_scatter_as_stated(robot):
    """The 6-D readings of the ideal hidden robot scatter about the true marker pose with the
    stated sigmas (first-order fit covariance), and the truth is hidden only by noise."""
    real = RealRobot.create(robot, 3, TruthConfig.ideal())
    Q = _visible_configurations(robot, 40)
    assert len(Q) == 40
    rng = np.random.default_rng(1)
    reps = [real.optical_tracker.measure(Q, rng) for _ in range(15)]
    T = real.transform_camera_to_base.inverse()
    p, R = real.truth.poses(Q, robot.frame_reflector)
    vis = np.all([r.visible for r in reps], axis=0)
    assert vis.sum() >= 10
    e_pos = np.concatenate([(r.position_m - (p @ T.rotation.T + T.translation))[vis] for r in reps])
    R_true = np.einsum("ij,njk->nik", T.rotation, R)
    e_rot = np.concatenate([pin_log_batch(np.einsum("nji,njk->nik", R_true[vis], rotvecs_to_R(r.rotvec[vis])))
                            for r in reps])
    s_pos = np.mean([r.sigma_m[vis] for r in reps])
    s_rot = np.mean([r.sigma_rad[vis] for r in reps])
    assert 0.7 < e_pos.std() / s_pos < 1.3
    assert 0.6 < e_rot.std() / s_rot < 1.4
    assert abs(e_pos.mean()) < 0.2 * s_pos


def rotvecs_to_R(rv: np.ndarray) -> np.ndarray:
    return np.array([pin.exp3(v) for v in rv])


def pin_log_batch(R: np.ndarray) -> np.ndarray:
    return np.array([pin.log3(r) for r in R])


def test_invisible_rows_are_nan_and_margins_are_conservative(robot):
    """Rows the cameras cannot see are NaN; a configuration predicted visible with margins is
    visible without them; the numpy filter and the Pinocchio model agree."""
    rng = np.random.default_rng(2)
    chain = cd.chain_from_robot(robot)
    Q, _ = cd.random_candidates(chain, 400, rng, visibility=False)
    Q = np.concatenate([Q, _visible_configurations(robot, 40, 5)])
    T = robot.spec.optical_tracker.transform_camera_to_base
    exact = instruments.optical_visibility(robot, T, Q).visible
    fast = op.visible_mask(robot, Q, collision_margin_m=-1.0)   # no extra collision margin
    assert np.array_equal(exact, fast)
    margin = op.visible_mask(robot, Q, margins=instruments.OpticalMargins(np.radians(2.0), 0.05, 0.02))
    assert np.all(exact[margin]) and margin.sum() < exact.sum()
    reading = ot.OpticalTracker(robot, T).measure(Q, rng)
    assert np.array_equal(reading.visible, exact)
    assert np.all(np.isnan(reading.position_m[~exact])) and np.all(np.isfinite(reading.rotvec[exact]))


def test_a_diode_outside_the_field_of_view_or_emission_cone_is_not_seen(robot):
    spec = robot.spec.optical_tracker
    Q = _visible_configurations(robot, 5)
    T = spec.transform_camera_to_base
    narrow = dataclasses.replace(spec, field_of_view_half_angle_rad=np.radians(0.5))
    assert not instruments.optical_visibility(robot, T, Q, spec=narrow).visible.any()
    blind = dataclasses.replace(spec, emission_half_angle_rad=np.radians(0.5))
    assert not instruments.optical_visibility(robot, T, Q, spec=blind).visible.any()
    assert instruments.optical_visibility(robot, T, Q).visible.all()


def test_robot_yaml_section_round_trips_and_is_checked(robot, tmp_path):
    folder = robot.save(tmp_path / "saved")
    again = RobotModel.load(folder).spec.optical_tracker
    ref = robot.spec.optical_tracker
    assert np.allclose(again.probe_diodes_m, ref.probe_diodes_m)
    assert np.isclose(again.emission_half_angle_rad, ref.emission_half_angle_rad)
    assert np.allclose(again.transform_camera_to_base.homogeneous, ref.transform_camera_to_base.homogeneous)
    data = yaml.safe_load((folder / "robot.yaml").read_text())
    data["optical_tracker"]["probe_diodes_m"] = [[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]]
    bad = folder / "robot.yaml"
    bad.write_text(yaml.safe_dump(data))
    with pytest.raises(RobotFileError, match="collinear"):
        load_robot_spec(bad)


def test_robot_without_optical_tracker_has_none():
    robot = RobotModel.load("staubli_tx40")
    assert robot.spec.optical_tracker is None
    assert RealRobot.create(robot, 0, TruthConfig.ideal()).optical_tracker is None
