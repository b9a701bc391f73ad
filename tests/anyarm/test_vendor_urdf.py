"""URDFs as vendors ship them load with stated placeholders: each quirk is reproduced by editing a
public arm's URDF (no ``<inertial>``, ``effort="0"``, a rail under the arm, a bad inertia, a tool0
flange beyond the wrist centre, mesh packages that are not installed)."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from pipeline.cli import main
from pipeline.core.errors import RobotFileError
from pipeline.robot.assumed_values import value_digest
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.robot.plausibility import placeholder_warnings, robot_warnings
from pipeline.robot.reflector_check import capsules_holding
from pipeline.robot.urdf_import import absolute_mesh_paths, missing_collision_meshes
from pipeline.robot.vendor_urdf import BASE_MASS_SHARE, datasheet_mass_kg

ARM_LINKS = ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link")


def _source() -> str:
    path = example_arm_urdf("ur5")
    if path is None:
        pytest.skip("example-robot-data not installed")
    return path.read_text()


def _write(tmp_path: Path, text: str, name: str = "arm.urdf") -> Path:
    """The edited URDF in a folder of its own: its ``package://`` meshes are not found there."""
    folder = tmp_path / name.removesuffix(".urdf")
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_text(text)
    return folder / name


def _vendor_text() -> str:
    """No inertials anywhere, zero effort and velocity limits on every joint."""
    text = re.sub(r"<inertial>.*?</inertial>", "", _source(), flags=re.S)
    text = re.sub(r'effort="[^"]*"', 'effort="0"', text)
    return re.sub(r'velocity="[^"]*"', 'velocity="0"', text)


def _principal_moments_ok(model: pin.Model) -> bool:
    for j in range(1, model.njoints):
        a, b, c = np.sort(np.linalg.eigvalsh(model.inertias[j].inertia))
        if not (a > 0 and a + b >= c * (1 - 1e-9)):
            return False
    return True


def test_vendor_urdf_loads_with_every_placeholder_listed(tmp_path):
    robot = RobotModel.load(_write(tmp_path, _vendor_text()))
    stated = "\n".join(robot.assumptions)
    inertials = next(a for a in robot.assumptions if a.startswith("PLACEHOLDER inertials"))
    assert all(link in inertials for link in ARM_LINKS)
    assert "PLACEHOLDER effort limits" in stated and "PLACEHOLDER velocity limits" in stated
    assert "package example-robot-data" in stated            # the capsules say why no mesh was used
    masses = np.array([robot.model.inertias[j].mass for j in range(1, robot.model.njoints)])
    assert np.all(masses > 0)
    reach = float(robot.summary()["reach_m"])
    assert masses.sum() == pytest.approx((1 - BASE_MASS_SHARE) * datasheet_mass_kg(reach), rel=0.05)
    assert _principal_moments_ok(robot.model)
    assert np.all(robot.limits.velocity_rad_s > 0)
    data = robot.model.createData()
    for q in np.random.default_rng(1).uniform(robot.limits.lower_rad, robot.limits.upper_rad, (50, robot.nq)):
        assert np.all(np.abs(pin.computeGeneralizedGravity(robot.model, data, q)) <= robot.limits.effort_Nm)


def test_robot_init_marks_placeholders_and_reloads_them(tmp_path):
    urdf = _write(tmp_path, _vendor_text())
    assert main(["robot", "init", str(urdf)]) == 0
    text = (urdf.parent / "robot.yaml").read_text()
    assert re.search(r"effort_Nm: \[.*\]  # ASSUMED: PLACEHOLDER", text)
    robot = RobotModel.load(urdf.parent)
    assert any(a.startswith("limits.effort_Nm: PLACEHOLDER") for a in robot.assumptions)
    assert any(a.startswith("PLACEHOLDER inertials") for a in robot.assumptions)   # from the URDF, every load
    assert not any(a.startswith("PLACEHOLDER effort limits") for a in robot.assumptions)  # robot.yaml sets them


def _with_rail(text: str) -> str:
    """A linear track under the arm: world -(prismatic rail along x, 0..2 m)-> carriage -> base_link."""
    rail = ('<link name="carriage"/><joint name="rail" type="prismatic"><parent link="world"/>'
            '<child link="carriage"/><axis xyz="1 0 0"/><limit lower="0" upper="2" effort="1000" velocity="1"/>'
            '</joint>')
    return text.replace('<parent link="world"/>\n    <child link="base_link"/>',
                        '<parent link="carriage"/>\n    <child link="base_link"/>').replace(
        '<link name="world"/>', '<link name="world"/>' + rail)


def test_rail_under_the_arm_is_locked_at_a_stated_value(tmp_path):
    urdf = _write(tmp_path, _with_rail(_source()))
    free = RobotModel.load(urdf)
    assert free.nq == 6 and "rail" not in list(free.model.names)
    assert any("rail = 0" in a for a in free.assumptions)
    moved = RobotModel.load(urdf, lock={"rail": 1.5})
    assert any("rail = 1.5" in a for a in moved.assumptions)
    q = np.zeros(6)
    shift = moved.fk(q).translation - free.fk(q).translation
    assert np.allclose(shift, [1.5, 0.0, 0.0], atol=1e-12)
    with pytest.raises(RobotFileError, match="lock rail: 3 is outside"):
        RobotModel.load(urdf, lock={"rail": 3.0})
    with pytest.raises(RobotFileError, match="lock: no joint 'nope'"):
        RobotModel.load(urdf, lock={"nope": 0.0})
    out = tmp_path / "init" / "robot.yaml"
    out.parent.mkdir()
    assert main(["robot", "init", str(urdf), "--lock", "rail=1.5", "--out", str(out)]) == 0
    again = RobotModel.load(out.parent)
    assert np.allclose(again.fk(q).homogeneous, moved.fk(q).homogeneous, atol=1e-12)


def _load_with_forearm_inertia(folder: Path, inertia_xml: str) -> tuple[RobotModel, list[str]]:
    """The source URDF with the forearm link's ``<inertia>`` replaced, loaded: the robot and the warnings."""
    text = _source()
    start = text.index('<link name="forearm_link">')
    block = re.search(r"<inertia [^>]*/>", text[start:])
    text = text[:start + block.start()] + inertia_xml + text[start + block.end():]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        robot = RobotModel.load(_write(folder, text))
    return robot, [str(w.message) for w in caught]


def test_inertia_violating_the_triangle_inequality_is_repaired_by_the_smallest_change(tmp_path):
    robot, caught = _load_with_forearm_inertia(
        tmp_path, '<inertia ixx="0.001" ixy="0.0" ixz="0.0" iyy="0.002" iyz="0.0" izz="0.5"/>')
    assert any("forearm_link" in w for w in caught)
    assert any("forearm_link" in a and "repaired" in a for a in robot.assumptions)
    assert _principal_moments_ok(robot.model)
    body = robot.model.inertias[robot.model.getJointId("elbow_joint")]
    moments = np.sort(np.linalg.eigvalsh(body.inertia))
    # the smallest moment raised exactly to the bound 0.5 - 0.002, the other two unchanged
    assert moments == pytest.approx((0.002, 0.498, 0.5), rel=1e-9)


def test_a_link_without_inertia_is_raised_to_the_floor_and_the_note_gives_four_digits(tmp_path):
    robot, caught = _load_with_forearm_inertia(
        tmp_path, '<inertia ixx="0" ixy="0.0" ixz="0.0" iyy="2.5e-07" iyz="0.0" izz="0"/>')
    assert any("forearm_link" in w for w in caught)
    (note,) = [a for a in robot.assumptions if "forearm_link" in a and "repaired" in a]
    assert "2.5e-07" in note and "1e-06" in note          # not rounded to six decimals (0.0)


def test_a_product_of_inertia_copied_from_a_moment_becomes_a_labelled_placeholder(tmp_path):
    """A public WAM URDF states ixz = iyy on one link (a copied number): a negative principal moment.
    The link keeps its stated mass, centre of mass and moments; the products are dropped and the
    placeholder is listed for the stages that rest on inertials."""
    text = _source()
    start = text.index('<link name="forearm_link">')
    block = re.search(r"<inertia [^>]*/>", text[start:])
    bad = '<inertia ixx="0.00005" ixy="0.0000002" ixz="0.000076" iyy="0.000076" iyz="-0.0000036" izz="0.000063"/>'
    text = text[:start + block.start()] + bad + text[start + block.end():]
    urdf = _write(tmp_path, text)
    robot = RobotModel.load(urdf)
    stated = next(a for a in robot.assumptions if a.startswith("PLACEHOLDER inertials"))
    assert "forearm_link" in stated and "products dropped" in stated
    body = robot.model.inertias[robot.model.getJointId("elbow_joint")]
    assert np.diag(body.inertia) == pytest.approx((0.00005, 0.000076, 0.000063), rel=1e-12)
    assert np.count_nonzero(body.inertia - np.diag(np.diag(body.inertia))) == 0
    nominal = RobotModel.load(_write(tmp_path / "stated", _source()))
    elbow = nominal.model.getJointId("elbow_joint")
    assert body.mass == nominal.model.inertias[elbow].mass
    assert np.array_equal(body.lever, nominal.model.inertias[elbow].lever)
    assert any(w.startswith("placeholder inertials") for w in placeholder_warnings(robot, ["identification"]))
    assert main(["robot", "init", str(urdf)]) == 0


def test_reflector_goes_on_tool0_outside_every_capsule(tmp_path):
    urdf = _write(tmp_path, _vendor_text())
    robot = RobotModel.load(urdf)
    assert robot.spec.flange_frame == "tool0"
    assert robot.spec.tool.reflector_offset_m[2] > 0           # tool0's z points out of the flange
    assert not capsules_holding(robot.model, "tool0", robot.spec.tool.reflector_offset_m, robot.capsules)
    wrist = RobotModel.load(urdf, tip="wrist_3_link")          # a last link frame chosen by hand
    assert not capsules_holding(wrist.model, "wrist_3_link", wrist.spec.tool.reflector_offset_m, wrist.capsules)


def test_an_assumed_reflector_inside_a_capsule_is_refused_a_given_one_is_warned(tmp_path):
    urdf = _write(tmp_path, _vendor_text())
    assert main(["robot", "init", str(urdf)]) == 0
    robot = RobotModel.load(urdf.parent)
    model, data = robot.model, robot.model.createData()
    flange = model.getFrameId("tool0")
    # the middle of the last body's capsule: it moves with the flange, so it holds the point in every pose
    capsule = next(c for c in robot.capsules
                   if model.frames[model.getFrameId(c.frame)].parentJoint == model.frames[flange].parentJoint)
    pin.framesForwardKinematics(model, data, np.zeros(robot.nq))
    inside = data.oMf[flange].actInv(data.oMf[model.getFrameId(capsule.frame)].act(0.5 * (capsule.p0 + capsule.p1)))
    path = urdf.parent / "robot.yaml"
    edited = yaml.safe_load(path.read_text())
    edited["tool"]["reflector_offset_m"] = [float(v) for v in inside]
    # still marked as robot init's assumption (its digest follows the value): refused
    edited["assumed"]["tool.reflector_offset_m"]["sha256"] = value_digest(edited["tool"]["reflector_offset_m"])
    path.write_text(yaml.safe_dump(edited, sort_keys=False))
    with pytest.raises(RobotFileError, match=rf"tool.reflector_offset_m: the reflector lies inside capsule "
                                             rf"'{capsule.name}' in 100% of configurations"):
        RobotModel.load(urdf.parent)
    # a value the user gives (measured, or a calibration's): loaded, and the capsule is named in a warning
    del edited["assumed"]["tool.reflector_offset_m"]
    path.write_text(yaml.safe_dump(edited, sort_keys=False))
    given = RobotModel.load(urdf.parent)
    assert any(f"capsule '{capsule.name}' in 100% of configurations" in w for w in robot_warnings(given))


def test_assumed_marks_go_only_with_an_edit_and_init_respects_its_options(tmp_path):
    urdf = _write(tmp_path, _source())
    assert main(["robot", "init", str(urdf)]) == 0
    path = urdf.parent / "robot.yaml"
    before = RobotModel.load(urdf.parent).assumptions
    assert any(a.startswith("actuation.gear_ratio:") for a in before)
    assert any(a.startswith("tracker:") for a in before)
    text = path.read_text()
    line = next(x for x in text.splitlines() if x.startswith("  gear_ratio:"))
    path.write_text(text.replace(line, "  gear_ratio: [120, 120, 120, 80, 80, 80]"))
    after = RobotModel.load(urdf.parent).assumptions
    assert not any(a.startswith("actuation.gear_ratio:") for a in after)
    assert len(after) == len(before) - 1
    # re-saving the same values (100 vs 100.0, other layout) keeps them assumed
    data = yaml.safe_load(path.read_text())
    data["actuation"]["coulomb_smoothing_rad_s"] = float(data["actuation"]["coulomb_smoothing_rad_s"])
    path.write_text(yaml.safe_dump(data, sort_keys=True))
    assert sorted(RobotModel.load(urdf.parent).assumptions) == sorted(after)
    # beside the edited robot.yaml: --out with --tip loads the URDF alone and follows --tip
    out = tmp_path / "other" / "robot.yaml"
    out.parent.mkdir()
    assert main(["robot", "init", str(urdf), "--tip", "wrist_3_link", "--out", str(out)]) == 0
    written = yaml.safe_load(out.read_text())
    assert written["flange_frame"] == "wrist_3_link" and "flange_frame" not in written["assumed"]
    assert written["actuation"]["gear_ratio"][0] == 100.0
    assert main(["robot", "init", str(urdf), "--out", str(out)]) == 2
    assert yaml.safe_load(out.read_text())["flange_frame"] == "wrist_3_link"
    assert main(["robot", "init", str(urdf), "--out", str(out), "--force"]) == 0
    assert yaml.safe_load(out.read_text())["flange_frame"] == "tool0"


def test_bad_lock_option_is_one_line(tmp_path, capsys):
    urdf = _write(tmp_path, _with_rail(_source()))
    assert main(["robot", "init", str(urdf), "--lock", "rail"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: --lock:") and "\n" not in err


def test_one_effort_limit_on_every_joint_that_cannot_hold_the_arm_is_a_placeholder(tmp_path):
    """``effort="5"`` on every joint of the UR5 (shoulder holding torque ~100 N·m): not the arm's."""
    urdf = _write(tmp_path, re.sub(r'effort="[^"]*"', 'effort="5"', _source()))
    robot = RobotModel.load(urdf)
    line = next(a for a in robot.assumptions if a.startswith("PLACEHOLDER effort limits"))
    assert "could not hold itself" in line and "one value on every joint, so replaced on all" in line
    data = robot.model.createData()
    for q in np.random.default_rng(1).uniform(robot.limits.lower_rad, robot.limits.upper_rad, (50, robot.nq)):
        assert np.all(np.abs(pin.computeGeneralizedGravity(robot.model, data, q)) <= robot.limits.effort_Nm)
    assert main(["robot", "init", str(urdf)]) == 0
    assert re.search(r"effort_Nm: \[.*\]  # ASSUMED: PLACEHOLDER", (urdf.parent / "robot.yaml").read_text())


def test_a_stated_effort_limit_the_arm_can_hold_with_is_kept(tmp_path):
    """Only the joints below their gravity torque are replaced; a file's own limits that hold stay."""
    stated = RobotModel.load(example_arm_urdf("ur5") or pytest.skip("example-robot-data not installed"))
    weak = re.sub(r'(<joint name="shoulder_lift_joint".*?effort=")[^"]*"', r'\g<1>5"', _source(), flags=re.S)
    robot = RobotModel.load(_write(tmp_path, weak))
    changed = np.flatnonzero(robot.limits.effort_Nm != stated.limits.effort_Nm)
    assert changed.tolist() == [1] and robot.limits.effort_Nm[1] > 5
    assert not any("PLACEHOLDER effort" in a for a in stated.assumptions)


def test_an_empty_or_lfs_pointer_mesh_counts_as_missing(tmp_path):
    """A mesh file cloned without Git LFS (its pointer) or left empty is named; capsules come from the chain."""
    folder = tmp_path / "arm"
    folder.mkdir()
    text = absolute_mesh_paths(_source(), example_arm_urdf("ur5"))
    first = re.search(r'<collision>.*?filename="([^"]+)"', text, flags=re.S).group(1)
    pointer = folder / "pointer.stl"
    pointer.write_text("version https://git-lfs.github.com/spec/v1\noid sha256:0\nsize 1\n")
    (folder / "empty.stl").write_bytes(b"")
    text = text.replace(first, str(pointer), 1)
    second = re.findall(r'<collision>.*?filename="([^"]+)"', text, flags=re.S)[1]
    urdf = folder / "arm.urdf"
    urdf.write_text(text.replace(second, str(folder / "empty.stl"), 1))
    missing = missing_collision_meshes(urdf)
    assert f"{pointer} (a Git LFS pointer, not the mesh)" in missing and f"{folder / 'empty.stl'} (empty)" in missing
    robot = RobotModel.load(urdf)
    assert any("not found or unreadable" in a and "pointer.stl" in a for a in robot.assumptions)
