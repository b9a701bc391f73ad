"""Placeholders labelled, not judged by their own rule: a placeholder mass is estimated from the
links' mesh volumes when the meshes are found, `check` names the stages that depend on each
placeholder, and the headline's model row says "placeholder", never "plausible"."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.mesh_volume import LINK_DENSITY_KG_M3
from pipeline.robot.model import RobotModel
from pipeline.robot.plausibility import placeholder_warnings
from pipeline.robot.urdf_import import absolute_mesh_paths
from pipeline.run.headline_rows import PASS, WARN, stage_rows


def _ur5_without_inertials(tmp_path: Path, meshes: bool) -> tuple[Path, float]:
    """The UR5 with every ``<inertial>`` removed (meshes by absolute path, or not found), and the
    moving mass its URDF states."""
    urdf = example_arm_urdf("ur5")
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    stated = float(sum(i.mass for i in RobotModel.load(urdf).model.inertias[1:]))
    text = absolute_mesh_paths(urdf.read_text(), urdf) if meshes else urdf.read_text()
    target = tmp_path / ("meshes" if meshes else "bare") / "ur5.urdf"
    target.parent.mkdir(parents=True)
    target.write_text(re.sub(r"<inertial>.*?</inertial>", "", text, flags=re.S))
    return target, stated


def test_placeholder_mass_from_the_mesh_volumes_stated_beside_the_reach_rule(tmp_path):
    urdf, stated = _ur5_without_inertials(tmp_path, meshes=True)
    robot = RobotModel.load(urdf)
    line = next(a for a in robot.assumptions if a.startswith("PLACEHOLDER inertials"))
    assert "mesh volumes" in line and f"{LINK_DENSITY_KG_M3:g} kg/m³" in line and "reach-class rule" in line
    estimated = float(sum(i.mass for i in robot.model.inertias[1:]))
    assert stated / 3 < estimated < 3 * stated         # the density is that of arms like it
    bare = RobotModel.load(_ur5_without_inertials(tmp_path, meshes=False)[0])
    assert "no meshes found" in next(a for a in bare.assumptions if a.startswith("PLACEHOLDER inertials"))


def test_check_names_the_stages_a_placeholder_feeds_and_the_headline_says_placeholder(tmp_path):
    robot = RobotModel.load(_ur5_without_inertials(tmp_path, meshes=False)[0])
    lines = placeholder_warnings(robot, ["model", "identification", "trajectory"])
    assert len(lines) == 1 and "placeholder inertials" in lines[0]
    assert "identification, trajectory depend on them" in lines[0] and "calibration" not in lines[0]
    summary = {"name": robot.name, "dof": robot.nq, "reach_m": 0.9, "moving_mass_kg": 20.0, "payload_kg": 0.0,
               "assumptions": list(robot.assumptions), "plausibility_warnings": []}
    row = stage_rows("model", summary)[0]
    assert "placeholder: inertials" in row.against and row.verdict == WARN
    real = RobotModel.load(example_arm_urdf("ur5"))
    clean = stage_rows("model", {**summary, "assumptions": list(real.assumptions)})[0]
    assert "placeholder" not in clean.against and clean.verdict == PASS
