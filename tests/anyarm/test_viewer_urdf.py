"""Viewer for real URDFs: package:// meshes resolved from the file, capsules when meshes are missing."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from pipeline.robot.defaults import ready_pose_rad
from pipeline.robot.model import RobotModel
from pipeline.view.viewer import visual_model
from tests.anyarm.test_urdf_only import _erd
from tests.view.test_viewer import CHROMIUM, DRAWN_FRACTION, assert_framed, changed_fraction, framed_screenshots


def _ur5_without_meshes(tmp_path):
    urdf = tmp_path / "ur5.urdf"
    shutil.copy(_erd("ur_description/urdf/ur5_robot.urdf"), urdf)     # package://example-robot-data unresolvable
    return RobotModel.load(urdf)


def test_meshes_resolved_from_package_paths_else_capsules(tmp_path):
    ur5 = RobotModel.load(_erd("ur_description/urdf/ur5_robot.urdf"))
    geometry, how = visual_model(ur5)
    assert how == "meshes" and geometry.ngeoms >= ur5.nq
    saved = RobotModel.load(ur5.save(tmp_path / "saved"))            # a stage's copy elsewhere
    assert visual_model(saved)[1] == "meshes"
    bare = _ur5_without_meshes(tmp_path)
    geometry, how = visual_model(bare)
    assert how == "capsules" and geometry.ngeoms == len(bare.capsules) >= bare.nq


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (make test installs it via apt)")
@pytest.mark.parametrize("meshes", [True, False])
def test_real_urdf_is_drawn_and_framed(meshes, tmp_path):
    """The UR5 in meshcat, seen by headless Chromium: drawn (pixels change when it is hidden) as
    meshes or, without them, as capsules, and framed by the camera."""
    robot = RobotModel.load(_erd("ur_description/urdf/ur5_robot.urdf")) if meshes else _ur5_without_meshes(tmp_path)
    with_robot, without, viewer, _ = framed_screenshots(robot, ready_pose_rad(robot), tmp_path)
    assert viewer.drawn_as == ("meshes" if meshes else "capsules")
    assert changed_fraction(without, with_robot) > DRAWN_FRACTION
    assert np.isfinite(with_robot).all()
    assert_framed(with_robot, without)
