"""Names derived from a URDF made legal for CasADi everywhere they name a function or solver."""

from __future__ import annotations

import casadi as ca
import pytest

from pipeline.core.identifiers import casadi_identifier
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.run.preflight import _build_ptp_nlp
from pipeline.trajectory.config import TrajectoryConfig


@pytest.mark.parametrize("parts", [("ptp", "gen3_", 25), ("ptp", "", 3), ("ptp", "my arm-2 (v1)", 7), ("1st",),
                                   ("__",), ("ptp", "Stäubli", 1)])
def test_every_name_is_a_legal_casadi_function_name(parts):
    name = casadi_identifier(*parts)
    x = ca.SX.sym("x")
    ca.Function(name, [x], [2 * x])    # raises on an illegal name
    assert "__" not in name and not name.startswith("_")


def test_a_urdf_named_gen3_underscore_builds_its_point_to_point_nlp(tmp_path):
    urdf = example_arm_urdf("ur5")
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    text = urdf.read_text()
    start = text.index("<robot name=")
    end = text.index(">", start)
    (tmp_path / "arm.urdf").write_text(text[:start] + '<robot name="gen3_"' + text[end:])
    robot = RobotModel.load(tmp_path / "arm.urdf")
    assert robot.model.name == "gen3_"
    _build_ptp_nlp(robot, TrajectoryConfig())        # what check does: the NLP as the stage builds it
