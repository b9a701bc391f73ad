"""A recording of joint states in any format an arm logs: a ROS 2 bag (:mod:`.ros2_bag`), the joint-state
CSV (:mod:`.motion_csv`), the model's joints picked by name (:mod:`.joint_names`), or a Universal Robots RTDE
recording (:mod:`.ur_rtde_csv`, joints by index)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from pipeline.core.errors import DataFileError
from pipeline.exchange import ros2_bag
from pipeline.exchange.joint_names import match_joint_names
from pipeline.exchange.motion import JointStates
from pipeline.exchange.motion_csv import is_joint_state_csv, read_joint_states_csv
from pipeline.exchange.ur_rtde_csv import is_rtde_csv, read_rtde_csv


def is_recording(path: str | Path) -> bool:
    """A ROS 2 bag, a joint-state CSV or an RTDE recording."""
    return ros2_bag.is_bag(path) or is_joint_state_csv(path) or is_rtde_csv(path)


def read_recorded_joint_states(path: str | Path, joint_names: Sequence[str], name_map: Mapping[str, str] | None = None,
                               field: str = "joint_names") -> tuple[JointStates, float]:
    """The joints ``joint_names`` (the model's, in its order) of a recording, times from its first sample, and
    that sample's time on the recording's clock (s: a bag's stamp, a CSV's ``t_s``)."""
    names = list(joint_names)
    if ros2_bag.is_bag(path):
        t0 = ros2_bag.first_stamp_s(path)
        return ros2_bag.read_joint_states(path, names, name_map, field=field, t0_s=t0), t0
    if is_rtde_csv(path):
        logged, _ = read_rtde_csv(path, len(names))
        t0 = float(logged.t_s[0])
        return JointStates(tuple(names), logged.t_s - t0, logged.q_rad, logged.qd_rad_s, logged.effort_Nm), t0
    if not is_joint_state_csv(path):
        raise DataFileError(path, None, "neither a ROS 2 bag nor a joint-state CSV (t_s,q_<joint>_rad,...) nor an "
                            "RTDE recording (timestamp, actual_q_0, ...)")
    logged = read_joint_states_csv(path)
    mapping = match_joint_names(logged.joint_names, names, name_map, source=str(path), field=field)
    picked = logged.select([mapping[name] for name in names])
    t0 = float(picked.t_s[0]) if picked.n_samples else 0.0
    return JointStates(tuple(names), picked.t_s - t0, picked.q_rad, picked.qd_rad_s, picked.effort_Nm), t0
