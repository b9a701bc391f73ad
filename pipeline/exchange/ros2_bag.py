"""ROS 2 bags (rosbag2, SQLite3 or MCAP) read and written with ``rosbags`` (no ROS installation).

Writers make a bag folder (``metadata.yaml`` + one ``.db3`` or ``.mcap``) that ``ros2 bag play``
replays as it is: message definitions and RIHS01 type hashes from the ROS 2 Jazzy type store (the
messages used here are the same in Humble), and an offered QoS profile per topic (reliable, volatile,
keep last 10). The folder is written beside its target and renamed into place: no half-written bag.

Readers take a bag folder with ``metadata.yaml``, a bare ``.db3`` without one (as many repositories
ship them), a folder of a recording's split storage files without it (``<name>_0.db3``, ``<name>_1.db3``,
...: their messages merged in log order) or a ``.mcap``. Times are the message header stamps when they
increase, else the times the messages were logged, in seconds from the first sample.

Messages: ``trajectory_msgs/msg/JointTrajectory`` (one message, ``effort`` = feedforward torque),
``sensor_msgs/msg/JointState``, ``geometry_msgs/msg/PointStamped``, ``PoseStamped``, ``TransformStamped``.
"""

from __future__ import annotations

import os
import re
import shutil
import struct
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from pipeline.core.errors import DataFileError
from pipeline.exchange.joint_names import match_joint_names
from pipeline.exchange.motion import JointStates, SampledMotion, TrackerPoints

BagFormat = Literal["sqlite3", "mcap"]
JOINT_TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"
JOINT_STATE = "sensor_msgs/msg/JointState"
POINT_STAMPED = "geometry_msgs/msg/PointStamped"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TRANSFORM_STAMPED = "geometry_msgs/msg/TransformStamped"
TRACKER_TYPES = (POINT_STAMPED, POSE_STAMPED, TRANSFORM_STAMPED)

#: the type store bags are written with (Jazzy: definitions + RIHS01 hashes; same messages as Humble)
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
_STORAGE = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
_DEFAULT_DURATION = QosTime(sec=0, nsec=0)
#: the QoS a bag offers on replay: reliable, volatile, keep last 10 (rclcpp's default publisher profile)
DEFAULT_QOS = Qos(history=QosHistory.KEEP_LAST, depth=10, reliability=QosReliability.RELIABLE,
                  durability=QosDurability.VOLATILE, deadline=_DEFAULT_DURATION, lifespan=_DEFAULT_DURATION,
                  liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=_DEFAULT_DURATION,
                  avoid_ros_namespace_conventions=False)


def ros_name_token(text: str) -> str:
    """``text`` as one legal ROS 2 name token: ``[A-Za-z_][A-Za-z0-9_]*``, no ``__``, no trailing ``_``."""
    token = re.sub(r"[^A-Za-z0-9_]", "_", text)
    token = re.sub(r"_+", "_", token).strip("_")
    if not token:
        return "robot"
    return f"r_{token}" if token[0].isdigit() else token


def joint_trajectory_topic(robot_name: str) -> str:
    """``/<robot>/joint_trajectory`` with the robot's name made a legal ROS 2 name token."""
    return f"/{ros_name_token(robot_name)}/joint_trajectory"


# --- writing -------------------------------------------------------------------------------------------

def _stamp(t_s: float) -> Any:   # Any: a generated message class instance
    ns = int(round(float(t_s) * 1e9))
    return TYPESTORE.types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _duration(t_s: float) -> Any:
    ns = int(round(float(t_s) * 1e9))
    return TYPESTORE.types["builtin_interfaces/msg/Duration"](sec=ns // 1_000_000_000,
                                                               nanosec=ns % 1_000_000_000)


def _header(t_s: float, frame_id: str = "") -> Any:
    return TYPESTORE.types["std_msgs/msg/Header"](stamp=_stamp(t_s), frame_id=frame_id)


def _write_bag(path: str | Path, topic: str, msgtype: str, messages: Sequence[tuple[float, Any]],
               bag_format: BagFormat) -> Path:
    """Messages ``(time s, message)`` on one topic into a new bag folder at ``path`` (renamed into place)."""
    return _write_topics(path, [(topic, msgtype, messages)], bag_format)


def _write_topics(path: str | Path, topics: Sequence[tuple[str, str, Sequence[tuple[float, Any]]]],
                  bag_format: BagFormat) -> Path:
    """``(topic, type, messages)`` into a new bag folder at ``path``, messages in time order.

    The bag is written as ``<name>/`` inside a staging folder beside ``path`` and renamed into place, so
    its storage file is ``<name>.db3`` / ``<name>.mcap`` (as ``ros2 bag record`` names it) in
    metadata.yaml and in the metadata the storage file carries itself (read when metadata.yaml is absent).
    """
    target = Path(path)
    if bag_format not in _STORAGE:
        raise DataFileError(target, "bag_format", f"{bag_format!r} is not one of {sorted(_STORAGE)}")
    if target.exists():
        raise DataFileError(target, None, "exists already; a bag is written only to a new path")
    staging_root = target.with_name(f".{target.name}.partial-{os.getpid()}")
    if staging_root.exists():
        shutil.rmtree(staging_root)
    staging_root.mkdir(parents=True)
    try:
        with Writer(staging_root / target.name, version=8, storage_plugin=_STORAGE[bag_format]) as writer:
            queue = []
            for topic, msgtype, messages in topics:
                connection = writer.add_connection(topic, msgtype, typestore=TYPESTORE,
                                                   offered_qos_profiles=[DEFAULT_QOS])
                queue += [(int(round(t_s * 1e9)), k, connection, msgtype, m)
                          for k, (t_s, m) in enumerate(messages)]
            for stamp_ns, _k, connection, msgtype, message in sorted(queue, key=lambda item: item[:2]):
                writer.write(connection, stamp_ns, TYPESTORE.serialize_cdr(message, msgtype))
        (staging_root / target.name).rename(target)
    finally:
        shutil.rmtree(staging_root, ignore_errors=True)
    return target


def write_joint_trajectory(path: str | Path, motion: SampledMotion, topic: str,
                           bag_format: BagFormat = "sqlite3") -> Path:
    """``motion`` as one ``trajectory_msgs/msg/JointTrajectory`` (header stamp 0: start on receipt).

    Each sample is a point: positions rad, velocities rad/s, accelerations rad/s², effort = feedforward
    torque N·m, ``time_from_start`` = ``t_s - t_s[0]``.
    """
    types = TYPESTORE.types
    point_cls = types["trajectory_msgs/msg/JointTrajectoryPoint"]
    t0 = float(motion.t_s[0]) if motion.n_samples else 0.0
    points = [point_cls(positions=motion.q_rad[k].copy(), velocities=motion.qd_rad_s[k].copy(),
                        accelerations=motion.qdd_rad_s2[k].copy(), effort=motion.tau_ff_Nm[k].copy(),
                        time_from_start=_duration(motion.t_s[k] - t0))
              for k in range(motion.n_samples)]
    message = types[JOINT_TRAJECTORY](header=_header(0.0), joint_names=list(motion.joint_names), points=points)
    return _write_bag(path, topic, JOINT_TRAJECTORY, [(0.0, message)], bag_format)


def write_joint_states(path: str | Path, states: JointStates, topic: str = "/joint_states",
                       bag_format: BagFormat = "sqlite3") -> Path:
    """``states`` as one ``sensor_msgs/msg/JointState`` per sample, stamped and logged at ``t_s``."""
    return _write_bag(path, topic, JOINT_STATE, _joint_state_messages(states), bag_format)


def _joint_state_messages(states: JointStates) -> list[tuple[float, Any]]:
    cls = TYPESTORE.types[JOINT_STATE]
    names = list(states.joint_names)
    return [(float(t), cls(header=_header(t), name=names, position=states.q_rad[k].copy(),
                           velocity=states.qd_rad_s[k].copy(), effort=states.effort_Nm[k].copy()))
            for k, t in enumerate(states.t_s)]


def write_recording(path: str | Path, states: JointStates, points: TrackerPoints, tracker_topic: str,
                    msgtype: str = POINT_STAMPED, joint_states_topic: str = "/joint_states",
                    bag_format: BagFormat = "sqlite3") -> Path:
    """One bag of joint states and tracker readings on a common clock (a calibration recording)."""
    return _write_topics(path, [(joint_states_topic, JOINT_STATE, _joint_state_messages(states)),
                                (tracker_topic, msgtype, _point_messages(path, points, msgtype, "reflector"))],
                         bag_format)


def write_points(path: str | Path, points: TrackerPoints, topic: str, msgtype: str = POINT_STAMPED,
                 bag_format: BagFormat = "sqlite3", child_frame_id: str = "reflector") -> Path:
    """Tracker readings as ``PointStamped`` (default), ``PoseStamped`` or ``TransformStamped`` (identity rotation)."""
    return _write_bag(path, topic, msgtype, _point_messages(path, points, msgtype, child_frame_id), bag_format)


def _point_messages(path: str | Path, points: TrackerPoints, msgtype: str,
                    child_frame_id: str) -> list[tuple[float, Any]]:
    types = TYPESTORE.types
    if msgtype not in TRACKER_TYPES:
        raise DataFileError(path, "msgtype", f"{msgtype!r} is not one of {list(TRACKER_TYPES)}")
    if points.rotvec_rad is not None and msgtype == POINT_STAMPED:
        raise DataFileError(path, "msgtype", "a PointStamped carries no orientation: write 6-D readings as "
                                             "PoseStamped or TransformStamped")
    quaternions = (Rotation.from_rotvec(points.rotvec_rad).as_quat() if points.rotvec_rad is not None
                   else np.tile([0.0, 0.0, 0.0, 1.0], (points.n_samples, 1)))
    messages = []
    for t, (x, y, z), (qx, qy, qz, qw) in zip(points.t_s, points.xyz_m, quaternions, strict=True):
        header = _header(t, points.frame_id)
        orientation = types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw)
        if msgtype == POINT_STAMPED:
            message = types[msgtype](header=header, point=types["geometry_msgs/msg/Point"](x=x, y=y, z=z))
        elif msgtype == POSE_STAMPED:
            pose = types["geometry_msgs/msg/Pose"](position=types["geometry_msgs/msg/Point"](x=x, y=y, z=z),
                                                   orientation=orientation)
            message = types[msgtype](header=header, pose=pose)
        else:
            transform = types["geometry_msgs/msg/Transform"](
                translation=types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z), rotation=orientation)
            message = types[msgtype](header=header, child_frame_id=child_frame_id, transform=transform)
        messages.append((float(t), message))
    return messages


# --- reading -------------------------------------------------------------------------------------------

#: storage files of a bag folder: SQLite3, MCAP, and either compressed as a whole (``--compression-mode file``)
_STORAGE_SUFFIXES = (".db3", ".mcap", ".db3.zstd", ".mcap.zstd")


def is_bag(path: str | Path) -> bool:
    """A bag folder (``metadata.yaml`` or a storage file inside), a ``.db3`` or a ``.mcap`` file."""
    p = Path(path)
    if p.is_dir():
        return (p / "metadata.yaml").exists() or any(any(p.glob(f"*{suffix}")) for suffix in _STORAGE_SUFFIXES)
    return p.suffix in (".db3", ".mcap")


def _reader_paths(path: Path) -> list[Path]:
    """What ``rosbags`` opens: the folder when it has metadata.yaml, else its storage files (the splits of
    one recording, ``<name>_0.db3``, ``<name>_1.db3``, ...; the readers merge their messages in log order)."""
    if path.is_dir() and not (path / "metadata.yaml").exists():
        files = sorted([*path.glob("*.db3"), *path.glob("*.mcap")])
        if not files:
            compressed = sorted(f.name for f in path.iterdir() if f.name.endswith(_STORAGE_SUFFIXES[2:]))
            hint = (f" ({', '.join(compressed)} compressed as a whole: decompress with `zstd -d` or keep the "
                    "bag's metadata.yaml)") if compressed else ""
            raise DataFileError(path, None, f"a bag folder without metadata.yaml holds no storage file "
                                            f"(.db3/.mcap){hint}")
        if len({f.suffix for f in files}) > 1:
            raise DataFileError(path, None, "a bag folder without metadata.yaml holds both .db3 and .mcap files; "
                                            "name one of them")
        return files
    return [path]


def _raw_messages(path: str | Path, msgtypes: Sequence[str], topic: str | None,
                  preferred_topic: str | None = None) -> tuple[str, list[tuple[int, str, bytes]]]:
    """The chosen topic and its ``(log time ns, message type, CDR bytes)`` in log order.

    The topic is ``topic`` when given, else ``preferred_topic`` when it holds one of ``msgtypes``, else
    the one topic of those types.
    """
    source = Path(path)
    if not source.exists():
        raise DataFileError(source, None, "not found")
    try:
        parts = _reader_paths(source)
        typed: dict[str, str] = {}
        all_topics: set[str] = set()
        for part in parts:
            with Reader(part) as reader:
                typed.update({c.topic: c.msgtype for c in reader.connections if c.msgtype in msgtypes})
                all_topics.update(reader.topics)
        if topic is not None:
            if topic not in typed:
                raise DataFileError(source, "topic", f"{topic!r} with a message of {list(msgtypes)} is not "
                                                     f"in the bag (topics: {sorted(all_topics)})")
            chosen = topic
        elif preferred_topic in typed:
            chosen = preferred_topic
        elif len(typed) == 1:
            chosen = next(iter(typed))
        elif not typed:
            raise DataFileError(source, "topic", f"no topic holds {' / '.join(msgtypes)} (topics: "
                                                 f"{sorted(all_topics)})")
        else:
            raise DataFileError(source, "topic", f"{len(typed)} topics hold {' / '.join(msgtypes)} "
                                                 f"({sorted(typed)}); name one")
        out: list[tuple[int, str, bytes]] = []
        for part in parts:
            with Reader(part) as reader:
                connections = [c for c in reader.connections if c.topic == chosen]
                if connections:
                    out += [(int(t), c.msgtype, bytes(data)) for c, t, data in reader.messages(connections=connections)]
    except DataFileError:
        raise
    except Exception as exc:   # rosbags / sqlite3 / mcap errors: one message naming the file
        raise DataFileError(source, None, f"cannot read as a ROS 2 bag: {exc}") from exc
    out.sort(key=lambda item: item[0])
    return chosen, out


def _messages(path: str | Path, msgtypes: Sequence[str], topic: str | None,
              preferred_topic: str | None = None) -> tuple[str, list[tuple[int, Any]]]:
    """The chosen topic (:func:`_raw_messages`) and its ``(log time ns, message)`` in log order."""
    chosen, raw = _raw_messages(path, msgtypes, topic, preferred_topic)
    try:
        return chosen, [(t, TYPESTORE.deserialize_cdr(data, msgtype)) for t, msgtype, data in raw]
    except Exception as exc:
        raise DataFileError(Path(path), None, f"cannot read as a ROS 2 bag: {exc}") from exc


#: message types whose CDR starts with a ``std_msgs/Header``: after the 4-byte encapsulation, ``stamp.sec``
#: (int32) and ``stamp.nanosec`` (uint32), little-endian for encapsulation 0x0001 (CDR_LE), else big-endian
_HEADER_FIRST = frozenset((JOINT_STATE, *TRACKER_TYPES))


def _header_stamp_s(data: bytes) -> float:
    sec, nanosec = struct.unpack_from("<iI" if data[1] == 1 else ">iI", data, 4)
    return float(sec) + 1e-9 * float(nanosec)


def _stamp_s(stamp: Any) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def _times(log_ns: Sequence[int], messages: Sequence[Any]) -> np.ndarray:
    """Header stamps when they are set and increase, else log times: seconds, absolute."""
    return _stamps_or_log_times(log_ns, np.array([_stamp_s(m.header.stamp) for m in messages]))


def _stamps_or_log_times(log_ns: Sequence[int], stamps_s: np.ndarray) -> np.ndarray:
    if stamps_s.size > 1 and np.all(np.diff(stamps_s) > 0.0):
        return stamps_s
    return np.asarray(log_ns, dtype=float) * 1e-9


def _vector(values: Any, n: int) -> np.ndarray:
    array = np.asarray(values, dtype=float).reshape(-1)
    return array if array.size == n else np.full(n, np.nan)


def _increasing(t_s: np.ndarray) -> np.ndarray:
    """Indices of the samples kept so that times increase strictly (repeats dropped)."""
    keep = [0] if t_s.size else []
    for k in range(1, t_s.size):
        if t_s[k] > t_s[keep[-1]]:
            keep.append(k)
    return np.asarray(keep, dtype=int)


def read_joint_trajectory(path: str | Path, topic: str | None = None) -> SampledMotion:
    """The one ``JointTrajectory`` message of the bag as a :class:`SampledMotion` (missing fields NaN)."""
    chosen, messages = _messages(path, [JOINT_TRAJECTORY], topic)
    if len(messages) != 1:
        raise DataFileError(path, "topic", f"{chosen} holds {len(messages)} JointTrajectory messages; "
                                           "one trajectory per bag is read")
    message = messages[0][1]
    n = len(message.joint_names)
    points = message.points
    t_s = np.array([float(p.time_from_start.sec) + 1e-9 * float(p.time_from_start.nanosec) for p in points])
    stack = {field: np.array([_vector(getattr(p, field), n) for p in points]).reshape(len(points), n)
             for field in ("positions", "velocities", "accelerations", "effort")}
    return SampledMotion(tuple(message.joint_names), t_s, stack["positions"], stack["velocities"],
                         stack["accelerations"], stack["effort"])


def read_joint_states(path: str | Path, joint_names: Sequence[str] | None = None,
                      name_map: Mapping[str, str] | None = None, topic: str | None = None,
                      field: str = "joint_names", t0_s: float | None = None) -> JointStates:
    """``JointState`` messages (``/joint_states``, or the one topic of that type) as :class:`JointStates`.

    ``joint_names`` (the model's) picks and orders the joints, matched by name in any order
    (:func:`~pipeline.exchange.joint_names.match_joint_names`, ``name_map`` = {recorded: model});
    other joints are ignored, messages without all of them skipped. Without ``joint_names``: the joints
    of the first message. Quantities a message leaves empty are NaN. Times in seconds from ``t0_s``
    (absolute, :func:`first_stamp_s`) or from the first sample.
    """
    _chosen, messages = _messages(path, [JOINT_STATE], topic, preferred_topic="/joint_states")
    if not messages:
        raise DataFileError(path, "topic", "holds no JointState message")
    recorded = list(messages[0][1].name)
    if joint_names is None:
        model = list(recorded)
        mapping = {name: name for name in model}
    else:
        model = list(joint_names)
        all_recorded = list(dict.fromkeys(name for _, m in messages for name in m.name))
        mapping = match_joint_names(all_recorded, model, name_map, source=str(path), field=field)
    wanted = [mapping[name] for name in model]
    rows: list[tuple[int, Any, list[int]]] = []
    for log_ns, m in messages:
        index = {name: k for k, name in enumerate(m.name)}
        if all(name in index for name in wanted):
            rows.append((log_ns, m, [index[name] for name in wanted]))
    if not rows:
        raise DataFileError(path, field, f"no JointState message holds all of {wanted}")
    t_abs = _times([r[0] for r in rows], [r[1] for r in rows])
    keep = _increasing(t_abs)
    out = {}
    for attr in ("position", "velocity", "effort"):
        out[attr] = np.array([_vector(getattr(rows[k][1], attr), len(rows[k][1].name))[rows[k][2]]
                              for k in keep]).reshape(len(keep), len(model))
    origin = float(t_abs[keep[0]]) if t0_s is None else float(t0_s)
    return JointStates(tuple(model), t_abs[keep] - origin, out["position"], out["velocity"], out["effort"])


def _point_of(message: Any) -> tuple[float, float, float]:
    if hasattr(message, "point"):
        p = message.point
    elif hasattr(message, "pose"):
        p = message.pose.position
    else:
        p = message.transform.translation
    return float(p.x), float(p.y), float(p.z)


def _quaternion_of(message: Any) -> tuple[float, float, float, float]:   # Any: a generated message class
    """The orientation ``(x, y, z, w)`` of a pose or transform message; the identity for a point."""
    if hasattr(message, "pose"):
        o = message.pose.orientation
    elif hasattr(message, "transform"):
        o = message.transform.rotation
    else:
        return 0.0, 0.0, 0.0, 1.0
    return float(o.x), float(o.y), float(o.z), float(o.w)


def _orientations(path: str | Path, quaternions: np.ndarray) -> np.ndarray | None:
    """Rotation vectors of the readings' orientations, or None when every one is the identity (a 3-D
    instrument publishing a pose: its orientation is a placeholder, not a measurement)."""
    identity = np.all(np.abs(quaternions[:, :3]) <= 1e-12, axis=1) & (np.abs(np.abs(quaternions[:, 3]) - 1) <= 1e-12)
    if quaternions.size == 0 or np.all(identity):
        return None
    norms = np.linalg.norm(quaternions, axis=1)
    if np.any(~np.isfinite(norms) | (np.abs(norms - 1.0) > 1e-3)):
        k = int(np.argmax(~np.isfinite(norms) | (np.abs(norms - 1.0) > 1e-3)))
        raise DataFileError(path, "orientation", f"reading {k + 1}: quaternion of norm {norms[k]:.6g}, not a rotation")
    return np.asarray(Rotation.from_quat(quaternions).as_rotvec(), float)


def read_points(path: str | Path, topic: str | None = None, t0_s: float | None = None) -> TrackerPoints:
    """Tracker readings from ``PointStamped`` / ``PoseStamped`` / ``TransformStamped`` (the one such topic):
    positions, and orientations when a pose's or transform's are not all the identity (6-D readings).

    Times in seconds from ``t0_s`` (an absolute time, e.g. the joint states' first stamp from
    :func:`first_stamp_s`) or from the first reading.
    """
    _chosen, messages = _messages(path, TRACKER_TYPES, topic)
    if not messages:
        raise DataFileError(path, "topic", "holds no tracker message")
    t_abs = _times([t for t, _ in messages], [m for _, m in messages])
    keep = _increasing(t_abs)
    xyz = np.array([_point_of(messages[k][1]) for k in keep]).reshape(len(keep), 3)
    quaternions = np.array([_quaternion_of(messages[k][1]) for k in keep]).reshape(len(keep), 4)
    origin = float(t_abs[keep[0]]) if t0_s is None else float(t0_s)
    return TrackerPoints(t_abs[keep] - origin, xyz, str(messages[keep[0]][1].header.frame_id),
                         _orientations(path, quaternions))


def first_stamp_s(path: str | Path, msgtypes: Sequence[str] = (JOINT_STATE,), topic: str | None = None,
                  preferred_topic: str | None = "/joint_states") -> float:
    """The absolute time (s) of the first message of the chosen topic, as :func:`read_joint_states` counts it
    (the header stamps read from the CDR bytes, without deserialising the messages)."""
    _chosen, raw = _raw_messages(path, msgtypes, topic, preferred_topic)
    if not raw:
        raise DataFileError(path, "topic", "holds no message of " + " / ".join(msgtypes))
    if all(msgtype in _HEADER_FIRST and len(data) >= 12 for _, msgtype, data in raw):
        stamps = np.array([_header_stamp_s(data) for _, _, data in raw])
        return float(_stamps_or_log_times([t for t, _, _ in raw], stamps)[0])
    messages = [TYPESTORE.deserialize_cdr(data, msgtype) for _, msgtype, data in raw]
    return float(_times([t for t, _, _ in raw], messages)[0])


def topics(path: str | Path) -> Iterator[tuple[str, str, int]]:
    """``(topic, message type, message count)`` of every topic of a bag."""
    source = Path(path)
    counts: dict[tuple[str, str], int] = {}
    try:
        for part in _reader_paths(source):
            with Reader(part) as reader:
                for c in reader.connections:
                    counts[(c.topic, c.msgtype)] = counts.get((c.topic, c.msgtype), 0) + c.msgcount
    except DataFileError:
        raise
    except Exception as exc:
        raise DataFileError(source, None, f"cannot read as a ROS 2 bag: {exc}") from exc
    yield from ((topic, msgtype, count) for (topic, msgtype), count in counts.items())
