"""An exported motion bag has what ``ros2 bag play`` needs, as far as that is checked without ROS:
metadata.yaml with the fields rosbag2 reads (version, storage identifier, the storage file, the topic
with its type, ``cdr`` serialisation, RIHS01 type hash and QoS), the same metadata inside the storage
file (read by rosbag2 when metadata.yaml is absent), the message definition stored with it, and the
messages read back with rosbags' high-level reader and the typestore built from the bag's own
definitions, as a player on another machine would."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest
import yaml
from rosbags.highlevel import AnyReader

from pipeline.exchange import ros2_bag
from pipeline.exchange.motion import SampledMotion

TOPIC = "/arm/joint_trajectory"


def _motion() -> SampledMotion:
    rng = np.random.default_rng(11)
    t = np.arange(30) * 2e-3
    q, qd, qdd, tau = (rng.normal(size=(30, 3)) for _ in range(4))
    return SampledMotion(("joint_1", "joint_2", "joint_3"), t, q, qd, qdd, tau)


@pytest.mark.parametrize("bag_format", ["sqlite3", "mcap"])
def test_an_exported_bag_carries_what_rosbag2_needs_to_play_it(tmp_path: Path, bag_format: ros2_bag.BagFormat):
    motion = _motion()
    bag = ros2_bag.write_joint_trajectory(tmp_path / "plan", motion, TOPIC, bag_format)
    storage = f"plan.{'db3' if bag_format == 'sqlite3' else 'mcap'}"
    assert sorted(p.name for p in bag.iterdir()) == sorted(["metadata.yaml", storage])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan"]          # no staging left behind
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert 5 <= info["version"] <= 9            # the versions rosbag2 reads (Humble writes 5, Jazzy 9)
    assert info["storage_identifier"] == bag_format
    assert info["relative_file_paths"] == [storage] and [f["path"] for f in info["files"]] == [storage]
    assert info["message_count"] == 1 and info["files"][0]["message_count"] == 1
    (entry,) = info["topics_with_message_count"]
    meta = entry["topic_metadata"]
    assert entry["message_count"] == 1
    assert (meta["name"], meta["type"], meta["serialization_format"]) == (TOPIC, ros2_bag.JOINT_TRAJECTORY, "cdr")
    assert meta["type_description_hash"] == ros2_bag.TYPESTORE.hash_rihs01(ros2_bag.JOINT_TRAJECTORY)
    assert meta["type_description_hash"].startswith("RIHS01_") and len(meta["type_description_hash"]) == 71
    (qos,) = yaml.safe_load(meta["offered_qos_profiles"])    # version 8: a YAML list in a string
    assert (qos["reliability"], qos["durability"], qos["history"], qos["depth"]) == (1, 2, 1, 10)

    definition = ros2_bag.TYPESTORE.generate_msgdef(ros2_bag.JOINT_TRAJECTORY, ros_version=2)[0]
    if bag_format == "sqlite3":
        with sqlite3.connect(bag / storage) as db:
            assert db.execute("select schema_version from schema").fetchone()[0] >= 3   # message definitions stored
            embedded = yaml.safe_load(db.execute("select metadata from metadata").fetchone()[0])
            assert embedded["relative_file_paths"] == [storage]
            row = db.execute("select topic_type, encoding, encoded_message_definition, type_description_hash "
                             "from message_definitions").fetchone()
            assert row == (ros2_bag.JOINT_TRAJECTORY, "ros2msg", definition, meta["type_description_hash"])
            (topic_row,) = db.execute("select name, type, serialization_format from topics").fetchall()
            assert topic_row == (TOPIC, ros2_bag.JOINT_TRAJECTORY, "cdr")
    else:
        data = (bag / storage).read_bytes()
        assert data.count(storage.encode()) >= 1 and b".partial" not in data
        assert b"ros2msg" in data and definition.encode() in data

    with AnyReader([bag]) as reader:            # the typestore from the bag's own definitions
        (connection,) = reader.connections
        assert (connection.topic, connection.msgtype) == (TOPIC, ros2_bag.JOINT_TRAJECTORY)
        assert connection.msgdef.data.strip() == definition.strip()
        (message,) = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()]
    assert list(message.joint_names) == list(motion.joint_names) and len(message.points) == len(motion.t_s)
    np.testing.assert_array_equal(np.array([p.positions for p in message.points]), motion.q_rad)
    np.testing.assert_array_equal(np.array([p.effort for p in message.points]), motion.tau_ff_Nm)
    t = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in message.points])
    np.testing.assert_allclose(t, motion.t_s, atol=1e-9)
