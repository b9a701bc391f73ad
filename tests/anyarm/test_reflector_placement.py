"""The reflector assumed for a URDF alone faces away from the arm and the tracker can see it.

A reflector placed inside or behind the wrist is hidden in every pose and calibration finds no
candidate (Kinova's Jaco, whose last link frame points back into the wrist, is such a URDF).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.calibration.candidates import chain_from_robot, filter_configurations
from pipeline.robot.example_robots import EXAMPLE_ARMS, example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.robot.spec import Capsule
from pipeline.robot.urdf_import import REFLECTOR_BEAM_CLEARANCE_M, REFLECTOR_OFFSET_M, reflector_placement

#: public arms whose last link frame points into the wrist or along it, beside the named ones
OTHER_ARMS = ("kinova_description/robots/kinova.urdf",)

#: a 27 deg incidence cone holds (1 - cos 27 deg) / 2 = 5.4 % of random reflector directions; with
#: occlusion by the arm at least a fifth of that must stay visible
MIN_VISIBLE_SHARE = 0.01


def _chain_model(last_origin_z_m: float) -> pin.Model:
    """Two revolute joints about z; the second sits ``last_origin_z_m`` from the first along z, so
    the first joint's origin lies at ``-last_origin_z_m`` on the flange z axis."""
    model = pin.Model()
    j1 = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "j1")
    model.appendBodyToJoint(j1, pin.Inertia.Random(), pin.SE3.Identity())
    j2 = model.addJoint(j1, pin.JointModelRZ(), pin.SE3(np.eye(3), np.array([0.3, 0.0, last_origin_z_m])), "j2")
    model.appendBodyToJoint(j2, pin.Inertia.Random(), pin.SE3.Identity())
    model.addFrame(pin.Frame("tip", j2, 0, pin.SE3.Identity(), pin.FrameType.BODY))
    return model


@pytest.mark.parametrize("z_m", [0.1, -0.1, 0.0])
def test_reflector_faces_away_from_the_previous_joint_and_clears_the_last_body(z_m):
    model = _chain_model(z_m)
    tool = Capsule("link2", "j2", np.array([0.0, 0.0, -0.12]), np.array([0.0, 0.0, 0.12]), 0.04)
    position, axis = reflector_placement(model, "tip", [tool])
    previous_on_axis = -z_m                               # the first joint's origin, flange z
    assert axis @ position > 0                            # opening outwards from the flange
    assert previous_on_axis * axis[2] <= 0                # not towards the rest of the arm
    assert np.linalg.norm(position) >= REFLECTOR_OFFSET_M
    assert np.linalg.norm(position) > 0.12 + tool.radius_m  # outside the last body's capsule


@pytest.mark.parametrize("rel", sorted(EXAMPLE_ARMS.values()) + list(OTHER_ARMS))
def test_tracker_sees_the_reflector_in_a_sizeable_share_of_poses(rel):
    urdf = example_arm_urdf(rel)
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    robot = RobotModel.load(urdf)
    chain = chain_from_robot(robot)
    Q = np.random.default_rng(0).uniform(chain.lower, chain.upper, (4000, chain.nq))
    free, _ = filter_configurations(chain, Q, visibility=False)
    seen, _ = filter_configurations(chain, Q[free])
    assert free.sum() > 100
    assert seen.mean() >= MIN_VISIBLE_SHARE, f"reflector visible in {seen.mean():.2%} of collision-free poses"


def test_reflector_goes_to_the_side_the_tool_geometry_lies_on():
    model = _chain_model(0.1)                             # upstream joint on -z: rule 2 alone says +z
    gripper = Capsule("link2", "j2", np.array([0.0, 0.0, -0.05]), np.array([0.0, 0.0, -0.2]), 0.03)
    position, axis = reflector_placement(model, "tip", [gripper])
    assert axis[2] == -1.0
    assert -position[2] > 0.2 + gripper.radius_m        # beyond the gripper's end


def test_reflector_leaves_a_beams_clearance_to_the_other_links():
    """A forearm capsule whose end cap the assumed reflector would touch (1 mm outside it in every
    pose: a wrist that turns about it): moved out by the beam clearance, as the tracker's beam
    must pass clear of that capsule."""
    model = _chain_model(0.0)
    start = reflector_placement(model, "tip", [])[0]
    cap = Capsule("link1", "j1", np.array([0.0, 0.0, 0.0]), np.array([0.3, 0.0, 0.0]),
                  float(np.linalg.norm(start)) - 1e-3)
    position, _ = reflector_placement(model, "tip", [cap])
    assert np.linalg.norm(position) >= cap.radius_m + REFLECTOR_BEAM_CLEARANCE_M
