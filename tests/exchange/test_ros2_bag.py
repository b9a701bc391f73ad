"""ROS 2 bags written and read back: joint trajectories, joint states, tracker points; the readers' inputs."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.core.errors import DataFileError
from pipeline.exchange import ros2_bag
from pipeline.exchange.motion import JointStates, SampledMotion, TrackerPoints

NAMES = ("joint_1", "joint_2", "joint_3")


def _motion(n: int = 40) -> SampledMotion:
    rng = np.random.default_rng(3)
    t = np.arange(n) * 1e-3
    q, qd, qdd, tau = (rng.normal(size=(n, 3)) for _ in range(4))
    return SampledMotion(NAMES, t, q, qd, qdd, 50.0 * tau)


@pytest.mark.parametrize("bag_format", ["sqlite3", "mcap"])
def test_joint_trajectory_round_trip(tmp_path: Path, bag_format: ros2_bag.BagFormat) -> None:
    motion = _motion()
    bag = ros2_bag.write_joint_trajectory(tmp_path / "plan", motion, "/arm/joint_trajectory", bag_format)
    assert (bag / "metadata.yaml").is_file()
    meta = (bag / "metadata.yaml").read_text()
    assert "RIHS01_" in meta and "reliability: 1" in meta
    back = ros2_bag.read_joint_trajectory(bag)
    assert back.joint_names == NAMES
    np.testing.assert_allclose(back.t_s, motion.t_s, atol=1e-9)
    for field in ("q_rad", "qd_rad_s", "qdd_rad_s2", "tau_ff_Nm"):
        np.testing.assert_array_equal(getattr(back, field), getattr(motion, field))


@pytest.mark.parametrize("bag_format", ["sqlite3", "mcap"])
def test_joint_states_bare_storage_file_and_name_matching(tmp_path: Path, bag_format: ros2_bag.BagFormat) -> None:
    """A bag read as its folder and as its bare storage file (no metadata.yaml): joints by name, extras ignored."""
    rng = np.random.default_rng(4)
    n = 25
    recorded = ("fer_finger_joint1", "fer_joint3", "fer_joint1", "fer_joint2")
    states = JointStates(recorded, 0.004 * np.arange(n), rng.normal(size=(n, 4)), rng.normal(size=(n, 4)),
                         rng.normal(size=(n, 4)))
    bag = ros2_bag.write_joint_states(tmp_path / "rec", states, bag_format=bag_format)
    storage = next(p for p in bag.iterdir() if p.suffix in (".db3", ".mcap"))
    bare = tmp_path / f"bare{storage.suffix}"
    shutil.copy(storage, bare)
    model = ("panda_joint1", "panda_joint2", "panda_joint3")
    for source in (bag, bare):
        back = ros2_bag.read_joint_states(source, model)
        assert back.joint_names == model
        np.testing.assert_array_equal(back.q_rad, states.q_rad[:, [2, 3, 1]])
        np.testing.assert_array_equal(back.effort_Nm, states.effort_Nm[:, [2, 3, 1]])
        np.testing.assert_allclose(back.t_s, states.t_s, atol=1e-9)
    mapped = ros2_bag.read_joint_states(bag, ("a", "b"), name_map={"fer_joint2": "a", "fer_finger_joint1": "b"})
    np.testing.assert_array_equal(mapped.qd_rad_s, states.qd_rad_s[:, [3, 0]])
    with pytest.raises(DataFileError, match="joint_names"):
        ros2_bag.read_joint_states(bag, ("shoulder", "elbow"))


@pytest.mark.parametrize("bag_format", ["sqlite3", "mcap"])
def test_split_storage_files_without_metadata_read_as_one_recording(tmp_path: Path,
                                                                    bag_format: ros2_bag.BagFormat) -> None:
    """A recording split by ``ros2 bag record --max-bag-duration`` (``rec_0``, ``rec_1``, ..., ``rec_10``)
    whose metadata.yaml is gone: its storage files read in their split order as one recording."""
    rng = np.random.default_rng(5)
    n, parts = 60, 12
    states = JointStates(NAMES, 0.01 * np.arange(n), rng.normal(size=(n, 3)), rng.normal(size=(n, 3)),
                         rng.normal(size=(n, 3)))
    points = TrackerPoints(np.array([0.105, 0.355]), rng.normal(size=(2, 3)), "tracker")
    folder = tmp_path / "rec"
    folder.mkdir()
    for k, chunk in enumerate(np.array_split(np.arange(n), parts)):
        part = JointStates(NAMES, states.t_s[chunk], states.q_rad[chunk], states.qd_rad_s[chunk],
                           states.effort_Nm[chunk])
        seen = (points.t_s >= part.t_s[0]) & (points.t_s <= part.t_s[-1] + 0.005)
        if seen.any():
            bag = ros2_bag.write_recording(tmp_path / f"part{k}", part, TrackerPoints(
                points.t_s[seen], points.xyz_m[seen], "tracker"), "/tracker", bag_format=bag_format)
        else:
            bag = ros2_bag.write_joint_states(tmp_path / f"part{k}", part, bag_format=bag_format)
        storage = next(p for p in bag.iterdir() if p.suffix in (".db3", ".mcap"))
        shutil.copy(storage, folder / f"rec_{k}{storage.suffix}")
    back = ros2_bag.read_joint_states(folder)
    np.testing.assert_array_equal(back.q_rad, states.q_rad)
    np.testing.assert_allclose(back.t_s, states.t_s, atol=1e-9)
    t0 = ros2_bag.first_stamp_s(folder)
    np.testing.assert_array_equal(ros2_bag.read_points(folder, t0_s=t0).xyz_m, points.xyz_m)
    assert dict(((t, c) for t, _, c in ros2_bag.topics(folder))) == {"/joint_states": n, "/tracker": 2}


@pytest.mark.parametrize("bag_format", ["sqlite3", "mcap"])
def test_first_stamp_is_the_first_time_the_readers_count(tmp_path: Path, bag_format: ros2_bag.BagFormat) -> None:
    """From the header stamps read off the CDR bytes when they increase, else from the log times."""
    states = JointStates(NAMES, 1.7e9 + 0.01 * np.arange(1, 6), np.zeros((5, 3)), np.zeros((5, 3)), np.zeros((5, 3)))
    bag = ros2_bag.write_joint_states(tmp_path / "rec", states, bag_format=bag_format)
    assert ros2_bag.first_stamp_s(bag) == pytest.approx(1.7e9 + 0.01, abs=1e-6)
    points = TrackerPoints(np.array([2.5, 3.25]), np.ones((2, 3)), "tracker")
    tracker = ros2_bag.write_points(tmp_path / "pts", points, "/tracker/reflector", bag_format=bag_format)
    assert ros2_bag.first_stamp_s(tracker, ros2_bag.TRACKER_TYPES, preferred_topic=None) == pytest.approx(2.5)
    _, raw = ros2_bag._raw_messages(bag, [ros2_bag.JOINT_STATE], None)
    _, messages = ros2_bag._messages(bag, [ros2_bag.JOINT_STATE], None)
    assert [ros2_bag._header_stamp_s(data) for _, _, data in raw] == \
        [ros2_bag._stamp_s(m.header.stamp) for _, m in messages]


@pytest.mark.parametrize("msgtype", list(ros2_bag.TRACKER_TYPES))
def test_tracker_points_round_trip(tmp_path: Path, msgtype: str) -> None:
    rng = np.random.default_rng(5)
    points = TrackerPoints(0.01 * np.arange(12), rng.normal(size=(12, 3)), "tracker")
    bag = ros2_bag.write_points(tmp_path / "pts", points, "/tracker/reflector", msgtype)
    back = ros2_bag.read_points(bag)
    assert back.frame_id == "tracker"
    np.testing.assert_array_equal(back.xyz_m, points.xyz_m)
    assert back.rotvec_rad is None                   # identity orientations: a 3-D instrument's placeholder
    if msgtype == ros2_bag.POINT_STAMPED:
        with pytest.raises(DataFileError, match="no orientation"):
            ros2_bag.write_points(tmp_path / "pts6", TrackerPoints(points.t_s, points.xyz_m, "tracker",
                                                                   rng.normal(size=(12, 3))), "/t", msgtype)
        return
    rotvec = rng.normal(size=(12, 3))
    rotvec *= np.minimum(1.0, 3.0 / np.linalg.norm(rotvec, axis=1))[:, None]   # angles below pi
    six_d = ros2_bag.write_points(tmp_path / "pts6", TrackerPoints(points.t_s, points.xyz_m, "tracker", rotvec),
                                  "/mocap/marker", msgtype)
    back = ros2_bag.read_points(six_d)
    assert back.rotvec_rad is not None
    np.testing.assert_allclose(back.rotvec_rad, rotvec, rtol=0, atol=1e-12)


def test_bad_inputs_name_the_file(tmp_path: Path) -> None:
    junk = tmp_path / "junk.db3"
    junk.write_bytes(b"\xde\xad\xbe\xef" * 64)
    with pytest.raises(DataFileError, match="junk.db3"):
        ros2_bag.read_joint_states(junk)
    with pytest.raises(DataFileError, match="not found"):
        ros2_bag.read_joint_states(tmp_path / "missing")
    bag = ros2_bag.write_joint_trajectory(tmp_path / "plan", _motion(3), "/a/joint_trajectory")
    with pytest.raises(DataFileError, match="JointState"):
        ros2_bag.read_joint_states(bag)
    with pytest.raises(DataFileError, match="exists"):
        ros2_bag.write_joint_trajectory(bag, _motion(3), "/a/joint_trajectory")
    compressed = tmp_path / "compressed"          # --compression-mode file, metadata.yaml lost
    compressed.mkdir()
    (compressed / "rec_0.db3.zstd").write_bytes(b"\x28\xb5\x2f\xfd")
    assert ros2_bag.is_bag(compressed)
    with pytest.raises(DataFileError, match="zstd -d"):
        ros2_bag.read_joint_states(compressed)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_topic_names_are_legal_ros_names() -> None:
    assert ros2_bag.joint_trajectory_topic("Stäubli RX130L (2)") == "/St_ubli_RX130L_2/joint_trajectory"
    assert ros2_bag.joint_trajectory_topic("6dof-arm") == "/r_6dof_arm/joint_trajectory"
    assert ros2_bag.joint_trajectory_topic("__") == "/robot/joint_trajectory"
