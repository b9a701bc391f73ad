"""Viewer for real URDFs: package:// meshes resolved from the file, capsules when meshes are missing."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from pipeline.robot.defaults import ready_pose_rad
from pipeline.robot.model import RobotModel
from pipeline.viewer import Viewer, visual_model
from tests.anyarm.test_urdf_only import _erd
from tests.test_viewer import CHROMIUM, assert_framed, changed_fraction, framed_screenshots, screenshot


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
# the mesh scene (several MB of UR5 triangles) does not always reach headless Chromium within its
# virtual time budget on a loaded machine: that case runs with the slow tests
@pytest.mark.parametrize("meshes", [pytest.param(True, marks=pytest.mark.slow), False])
def test_real_urdf_is_drawn(meshes, tmp_path):
    import meshcat

    robot = RobotModel.load(_erd("ur_description/urdf/ur5_robot.urdf")) if meshes else _ur5_without_meshes(tmp_path)
    vis = meshcat.Visualizer()
    proc = vis.window.server_proc
    try:
        empty = screenshot(vis.url(), tmp_path / "empty.png", tmp_path)
        viewer = Viewer(robot, viewer=vis)
        viewer.show(ready_pose_rad(robot))
        assert viewer.drawn_as == ("meshes" if meshes else "capsules")
        # a heavy mesh scene may not have arrived within headless Chromium's virtual time budget:
        # look up to three times (a robot that is never drawn fails all three)
        for attempt in range(3):
            drawn = screenshot(vis.url(), tmp_path / f"robot{attempt}.png", tmp_path)
            if changed_fraction(empty, drawn) > 0.01:
                break
    finally:
        proc.kill()
        proc.wait(timeout=10)
    assert changed_fraction(empty, drawn) > 0.01
    assert np.isfinite(drawn).all()


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (make test installs it via apt)")
# the UR5's meshes are several MB (see test_real_urdf_is_drawn): that case runs with the slow tests
@pytest.mark.parametrize("meshes", [pytest.param(True, marks=pytest.mark.slow), False])
def test_urdf_arm_is_framed(meshes, tmp_path):
    robot = RobotModel.load(_erd("ur_description/urdf/ur5_robot.urdf")) if meshes else _ur5_without_meshes(tmp_path)
    with_robot, without, viewer = framed_screenshots(robot, ready_pose_rad(robot), tmp_path)
    assert viewer.drawn_as == ("meshes" if meshes else "capsules")
    assert_framed(with_robot, without)
