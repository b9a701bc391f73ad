"""RobotModel: loading, validation errors, kinematics, IK, collision, save/load."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from pipeline.core.errors import RobotFileError
from pipeline.robot.collision import coal_capsule_distance, segment_distances
from pipeline.robot.model import ROBOTS_DIR, RobotModel
from pipeline.robot.yaml_init import write_robot_yaml

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def tx40() -> RobotModel:
    return RobotModel.load("staubli_tx40")


def test_rx130l_flange_positions_from_the_dh_table(rx130l: RobotModel) -> None:
    q = np.zeros(6)
    assert np.allclose(rx130l.fk(q, "flange").translation, [0.0, 0.0, 2.21], atol=1e-9, rtol=0)
    q[1] = np.pi / 2
    assert np.allclose(rx130l.fk(q, "flange").translation, [1.66, 0.0, 0.55], atol=1e-9, rtol=0)


def test_tool_frames_follow_robot_yaml(rx130l: RobotModel) -> None:
    q = np.random.default_rng(0).uniform(-1, 1, 6)
    flange = rx130l.fk(q, "flange")
    assert np.allclose(rx130l.fk(q, "tcp").homogeneous,
                       (flange * rx130l.transform_tcp_to_flange).homogeneous, atol=1e-12)
    assert np.allclose(rx130l.fk(q, "reflector").translation, flange.act(rx130l.reflector_offset_m), atol=1e-12)


def test_both_robots_load_with_rotor_inertia_in_the_model(rx130l: RobotModel, tx40: RobotModel) -> None:
    for robot in (rx130l, tx40):
        assert robot.nq == 6
        assert np.array_equal(robot.model.armature, robot.actuation.rotor_inertia_kgm2)
    assert tx40.actuation.gear_matrix[5, 4] == 32.0
    assert 1.6 < rx130l.summary()["reach_m"] < 1.7


def test_batched_positions_and_jacobian_agree_with_pinocchio(rx130l: RobotModel) -> None:
    rng = np.random.default_rng(3)
    Q = rng.uniform(rx130l.limits.lower_rad, rx130l.limits.upper_rad, (20, 6))
    positions = rx130l.positions(Q, "reflector")
    for q, p in zip(Q, positions, strict=True):
        assert np.allclose(rx130l.fk(q, "reflector").translation, p, atol=1e-12)
        jac = rx130l.jacobian(q, "reflector")
        eps = 1e-7
        numeric = np.column_stack([
            (rx130l.fk(q + eps * e, "reflector").translation - rx130l.fk(q - eps * e, "reflector").translation)
            / (2 * eps) for e in np.eye(6)
        ])
        assert np.allclose(jac[:3], numeric, atol=1e-7)


def test_ik_recovers_reachable_poses_inside_limits(rx130l: RobotModel) -> None:
    rng = np.random.default_rng(4)
    lim = rx130l.limits
    for _ in range(20):
        q = rng.uniform(lim.lower_rad * 0.8, lim.upper_rad * 0.8)
        target = rx130l.fk(q)
        result = rx130l.ik(target, q + rng.normal(0, 0.2, 6), rng=rng)
        assert result.success, result.message
        assert rx130l.within_limits(result.q)
        reached = rx130l.fk(result.q)
        assert np.linalg.norm(reached.translation - target.translation) < 1e-8
        assert np.linalg.norm(pin.log3(reached.rotation.T @ target.rotation)) < 1e-8


def test_ik_reports_failure_for_an_unreachable_pose(rx130l: RobotModel) -> None:
    target = pin.SE3(np.eye(3), np.array([3.0, 0.0, 1.0]))  # beyond the 1.66 m reach
    result = rx130l.ik(target, np.zeros(6), restarts=2)
    assert not result.success
    assert result.position_error_m > 0.5
    assert "did not reach" in result.message


def test_numpy_capsule_distance_matches_coal() -> None:
    rng = np.random.default_rng(5)
    for _ in range(200):
        a0, a1, b0, b1 = rng.normal(0, 0.5, (4, 3))
        ra, rb = rng.uniform(0.01, 0.2, 2)
        ours = segment_distances(a0, a1, b0, b1) - ra - rb
        reference = coal_capsule_distance(a0, a1, ra, b0, b1, rb)
        if reference > 0:  # coal reports a penetration depth differently; compare separated pairs
            assert ours == pytest.approx(reference, abs=1e-9)
        else:
            assert ours <= 1e-9


def test_capsules_detect_floor_and_self_collision(rx130l: RobotModel) -> None:
    assert not rx130l.in_collision(np.zeros(6))
    folded = np.array([0.0, 0.0, np.deg2rad(-142.0), 0.0, 0.0, 0.0])  # forearm folded on the upper arm
    assert rx130l.capsule_distances(folded).self_min_m < 0
    down = np.array([0.0, np.deg2rad(120.0), np.deg2rad(60.0), 0.0, 0.0, 0.0])  # tool into the floor
    assert rx130l.capsule_distances(down).floor_min_m < 0


def _calibrated_looking(robot: RobotModel) -> RobotModel:
    """``robot`` with a joint placement, an inertia, the armature and both tool frames changed."""
    changed = robot.copy()
    changed.model.jointPlacements[3] = changed.model.jointPlacements[3] * pin.exp6(np.full(6, 1e-3))
    changed.model.inertias[2] = pin.Inertia(40.0, np.array([0.3, 0.01, 0.0]), np.diag([0.2, 1.0, 1.1]))
    changed.model.armature = changed.model.armature * 1.1
    for name in ("tcp", "reflector"):  # a calibrated tool: frames moved and turned on the flange
        fid = changed.model.getFrameId(name)
        changed.model.frames[fid].placement = changed.model.frames[fid].placement * pin.exp6(np.full(6, 2e-3))
    return changed


def _assert_same_arm(loaded: RobotModel, changed: RobotModel) -> None:
    rng = np.random.default_rng(6)
    for _ in range(10):
        q, v, a = rng.normal(size=(3, changed.nq))
        assert np.allclose(loaded.fk(q).homogeneous, changed.fk(q).homogeneous, atol=1e-12)
        r_loaded, r_changed = loaded.fk(q, "reflector"), changed.fk(q, "reflector")
        assert np.allclose(r_loaded.translation, r_changed.translation, atol=1e-12)
        # the opening axis in the base frame: the axis turns with the reflector frame
        assert np.allclose(r_loaded.rotation @ loaded.reflector_axis, r_changed.rotation @ changed.reflector_axis,
                           atol=1e-12)
        assert np.allclose(loaded.inverse_dynamics(q, v, a), changed.inverse_dynamics(q, v, a), atol=1e-9)


def test_save_and_load_round_trip(tmp_path: Path, rx130l: RobotModel) -> None:
    changed = _calibrated_looking(rx130l)
    _assert_same_arm(RobotModel.load(changed.save(tmp_path / "saved")), changed)


def test_coulomb_smoothing_per_joint_round_trips_and_one_width_stays_one_number(tmp_path: Path,
                                                                                rx130l: RobotModel) -> None:
    """robot.yaml states the Coulomb smoothing width as one number or one per joint (an identified record's):
    either is read back exactly, and the friction of each joint switches with its own width."""
    widths = np.array([0.15, 0.05, 0.07, 0.007, 0.01, 0.3])
    changed = rx130l.copy()
    changed.spec.actuation.coulomb_smoothing_rad_s = widths.copy()
    loaded = RobotModel.load(changed.save(tmp_path / "per_joint"))
    assert np.array_equal(loaded.actuation.coulomb_smoothing_rad_s, widths)
    assert yaml.safe_load((tmp_path / "per_joint" / "robot.yaml").read_text())["actuation"][
        "coulomb_smoothing_rad_s"] == widths.tolist()
    v = np.full(rx130l.nq, 0.01)
    expected = rx130l.actuation.viscous_Nms_rad * v + rx130l.actuation.coulomb_Nm * np.tanh(v / widths)
    assert np.allclose(loaded.friction_torque(v), expected, rtol=1e-12)
    rx130l.save(tmp_path / "one")
    assert yaml.safe_load((tmp_path / "one" / "robot.yaml").read_text())["actuation"]["coulomb_smoothing_rad_s"] == 0.01
    assert np.array_equal(RobotModel.load(tmp_path / "one").actuation.coulomb_smoothing_rad_s, np.full(rx130l.nq, 0.01))


def test_tool_facts_are_saved_in_the_stated_flange_frame_when_the_urdf_has_a_flange_of_its_own(
        tmp_path: Path) -> None:
    """FIGAROH's UR10 URDF has a ``flange`` link turned against ``tool0`` (x forward, REP 199), and
    ``robot init`` states the tool in ``tool0``: the saved robot.yaml states the TCP and reflector
    there, and the reloaded arm is the same arm; the assumed reflector opens along tool0's z axis."""
    shutil.copy(REPO / "data" / "figaroh_ur10_mocap" / "robot.urdf", tmp_path / "robot.urdf")
    write_robot_yaml(tmp_path / "robot.urdf")
    ur10 = RobotModel.load(tmp_path)
    assert ur10.spec.flange_frame == "tool0" and ur10.frame_flange == "flange"
    q = np.full(ur10.nq, 0.3)
    assert not np.allclose(ur10.fk(q, "flange").rotation, ur10.fk(q, "tool0").rotation)
    reflector = ur10.fk(q, "reflector")
    assert np.allclose(reflector.rotation @ ur10.reflector_axis, ur10.fk(q, "tool0").rotation[:, 2], atol=1e-12)
    changed = _calibrated_looking(ur10)
    _assert_same_arm(RobotModel.load(changed.save(tmp_path / "saved")), changed)


# ------------------------------------------------------------------ validation errors
def _copy_robot(tmp_path: Path, name: str = "rx130l") -> Path:
    folder = tmp_path / name
    shutil.copytree(ROBOTS_DIR / name, folder)
    return folder


def _edit_yaml(folder: Path, edit) -> None:  # noqa: ANN001
    data = yaml.safe_load((folder / "robot.yaml").read_text())
    edit(data)
    (folder / "robot.yaml").write_text(yaml.safe_dump(data))


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d.update(unknown_key=1), "unknown_key"),
        (lambda d: d["actuation"].update(viscous_Nms_rad=[1.0, 2.0]), "actuation.viscous_Nms_rad"),
        (lambda d: d["actuation"].update(coulomb_smoothing_rad_s=[0.01, 0.02]), "actuation.coulomb_smoothing_rad_s"),
        (lambda d: d["actuation"].update(coulomb_smoothing_rad_s=[0.01] * 5 + [0.0]),
         "actuation.coulomb_smoothing_rad_s"),
        (lambda d: d["actuation"].update(rotor_inertia_kgm2=[-1.0, 1, 1, 1, 1, 1]), "actuation.rotor_inertia_kgm2"),
        (lambda d: d.update(flange_frame="no_such_frame"), "flange_frame"),
        (lambda d: d["capsules"][0].update(frame="nowhere"), "capsules[0].frame"),
        (lambda d: d["capsules"][1].update(radius_m=-0.1), "capsules[1].radius_m"),
        (lambda d: d["tool"].pop("reflector_offset_m"), "tool.reflector_offset_m"),
    ],
)
def test_bad_robot_yaml_names_file_and_field(tmp_path: Path, edit, field: str) -> None:  # noqa: ANN001
    folder = _copy_robot(tmp_path)
    _edit_yaml(folder, edit)
    with pytest.raises(RobotFileError) as info:
        RobotModel.load(folder)
    message = str(info.value)
    assert "robot.yaml" in message and field in message


def _edit_urdf(folder: Path, old: str, new: str, count: int = 1) -> None:
    urdf = folder / "rx130l.urdf"
    text = urdf.read_text()
    assert old in text
    urdf.write_text(text.replace(old, new, count))


def test_urdf_that_is_not_xml(tmp_path: Path) -> None:
    folder = _copy_robot(tmp_path)
    (folder / "rx130l.urdf").write_text("this is not <xml")
    with pytest.raises(RobotFileError, match=r"rx130l\.urdf: xml: not valid XML"):
        RobotModel.load(folder)


def test_negative_mass_and_bad_inertia_and_limits(tmp_path: Path) -> None:
    folder = _copy_robot(tmp_path)
    _edit_urdf(folder, '<mass value="35"/>', '<mass value="-35"/>')
    with pytest.raises(RobotFileError, match="joint_2: link inertial.mass: must be positive"):
        RobotModel.load(folder)
    folder = _copy_robot(tmp_path / "b")
    text = (folder / "rx130l.urdf").read_text()
    start = text.index('<link name="link_3">')
    ixx = text.index('ixx="', start)
    end = text.index('"', ixx + 5)
    (folder / "rx130l.urdf").write_text(text[:ixx] + 'ixx="-1' + text[end:])
    robot = RobotModel.load(folder)            # a sign typo: a labelled placeholder, not a refusal
    stated = robot.assumptions[0]
    assert stated.startswith("PLACEHOLDER inertials (a physically impossible inertia") and "link_3" in stated
    assert "solid cylinder" in stated          # the stated diagonal holds the -1: no diagonal to keep
    assert np.linalg.eigvalsh(robot.model.inertias[3].inertia).min() > 0
    folder = _copy_robot(tmp_path / "c")
    _edit_urdf(folder, 'lower="-2.79252680319"', 'lower="2.8"')
    with pytest.raises(RobotFileError, match=r"rx130l\.urdf: joint joint_1: limit: lower 2.8 is above upper"):
        RobotModel.load(folder)


# ------------------------------------------------------------------ joint limits: who said it
def _load_error(folder: Path) -> RobotFileError:
    with pytest.raises(RobotFileError) as info:
        RobotModel.load(folder)
    return info.value


@pytest.mark.parametrize(
    ("limits", "field", "problem"),
    [
        # the review's case: both bounds overridden in robot.yaml, lower above upper
        ({"lower_rad": [1, 0, 0, 0, 0, 0], "upper_rad": [0, 1, 1, 1, 1, 1]}, "limits.lower_rad",
         "joint joint_1 (entry 0): 1.0 is above limits.upper_rad 0.0"),
        ({"lower_rad": [-1, -1, 0.5, -1, -1, -1], "upper_rad": [1, 1, 0.5, 1, 1, 1]}, "limits.lower_rad",
         "joint joint_3 (entry 2): 0.5 equals limits.upper_rad 0.5"),
        # one bound from robot.yaml, the other from the URDF (tx40 joint_1 is +-3.14)
        ({"lower_rad": [5, -1, -1, -1, -1, -1]}, "limits.lower_rad",
         "joint joint_1 (entry 0): 5.0 is above the upper limit 3.14 in tx40.urdf"),
        ({"upper_rad": [-3.14, 1, 1, 1, 1, 1]}, "limits.upper_rad",
         "joint joint_1 (entry 0): -3.14 equals the lower limit -3.14 in tx40.urdf"),
    ],
)
def test_bad_limit_override_names_robot_yaml(tmp_path: Path, limits: dict, field: str, problem: str) -> None:
    folder = _copy_robot(tmp_path, "staubli_tx40")
    _edit_yaml(folder, lambda d: d["limits"].update(limits))
    error = _load_error(folder)
    assert Path(error.file).name == "robot.yaml"
    assert error.field == field
    assert problem in error.problem
    assert "urdf" not in (error.field or "")


def test_urdf_lower_equal_upper_is_an_error_naming_the_urdf(tmp_path: Path) -> None:
    folder = _copy_robot(tmp_path, "staubli_tx40")
    urdf = folder / "tx40.urdf"
    old = '<limit effort="103.49" lower="-2.40" upper="2.40"'
    assert old in urdf.read_text()
    urdf.write_text(urdf.read_text().replace(old, '<limit effort="103.49" lower="0.3" upper="0.3"'))
    error = _load_error(folder)
    assert Path(error.file).name == "tx40.urdf"
    assert error.field == "joint joint_3: limit"
    assert "lower 0.3 equals upper 0.3" in error.problem and "could not move" in error.problem


def test_robot_yaml_overrides_can_repair_urdf_limits(tmp_path: Path) -> None:
    folder = _copy_robot(tmp_path, "staubli_tx40")
    urdf = folder / "tx40.urdf"
    old = '<limit effort="103.49" lower="-2.40" upper="2.40"'
    urdf.write_text(urdf.read_text().replace(old, '<limit effort="103.49" lower="0.3" upper="0.3"'))
    _edit_yaml(folder, lambda d: d["limits"].update(lower_rad=[-1.0] * 6, upper_rad=[1.0] * 6))
    robot = RobotModel.load(folder)
    assert np.array_equal(robot.limits.lower_rad, [-1.0] * 6)


@pytest.mark.parametrize("kind", ["prismatic", "planar", "floating", "revolut"])
def test_non_revolute_movable_joint_is_rejected(tmp_path: Path, kind: str) -> None:
    folder = _copy_robot(tmp_path, "staubli_tx40")
    urdf = folder / "tx40.urdf"
    old = '<joint name="joint_3" type="revolute">'
    assert old in urdf.read_text()
    urdf.write_text(urdf.read_text().replace(old, f'<joint name="joint_3" type="{kind}">'))
    error = _load_error(folder)
    assert Path(error.file).name == "tx40.urdf"
    assert error.field == "joint joint_3: type"
    assert f"'{kind}'" in error.problem
    assert "\n" not in str(error)


def test_a_continuous_arm_joint_is_loaded_as_revolute_with_one_turn_each_way(tmp_path: Path) -> None:
    folder = _copy_robot(tmp_path, "staubli_tx40")
    urdf = folder / "tx40.urdf"
    old = '<joint name="joint_3" type="revolute">'
    urdf.write_text(urdf.read_text().replace(old, '<joint name="joint_3" type="continuous">'))
    robot = RobotModel.load(folder)
    assert robot.nq == robot.model.nv == 6
    assert robot.limits.lower_rad[2] == pytest.approx(-2 * np.pi)
    assert robot.limits.upper_rad[2] == pytest.approx(2 * np.pi)
    assert any("continuous joints loaded as revolute" in a and "joint_3" in a for a in robot.assumptions)
    back = RobotModel.load(robot.save(tmp_path / "saved"))   # the artefact keeps the revolute joint
    assert back.limits.upper_rad[2] == pytest.approx(2 * np.pi)


def test_urdf_limit_must_be_finite(tmp_path: Path) -> None:
    folder = _copy_robot(tmp_path, "staubli_tx40")
    urdf = folder / "tx40.urdf"
    old = 'lower="-2.40"'
    urdf.write_text(urdf.read_text().replace(old, 'lower="nan"'))
    error = _load_error(folder)
    assert Path(error.file).name == "tx40.urdf" and error.field == "joint joint_3: <limit lower>"


def test_unknown_robot_name() -> None:
    with pytest.raises(RobotFileError, match="'does_not_exist' is neither"):
        RobotModel.load("does_not_exist")
