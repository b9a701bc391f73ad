"""FIGAROH's unified calibration configuration (``figaroh.calibration``: full geometric parameters,
unknown base and tool frames, one marker), written for the peer runs of the benchmarks."""

from __future__ import annotations

from pathlib import Path

from pipeline.core.yaml12 import dump_yaml


def figaroh_calibration_yaml(robot: str, joints: list[str], data_file: Path, n_samples: int, *,
                             tool_frame: str, marker: str, reference_joint: str, measured_dof: int,
                             method: str | None = None, sensor_type: str | None = None) -> str:
    """The YAML text: ``measured_dof`` 3 (a position marker) or 6 (a pose); ``method`` FIGAROH's
    parameter selection (None: its default); ``sensor_type`` e.g. ``laser_tracker`` (None: unset)."""
    parameters: dict[str, object] = {"calibration_level": "full_params", "include_non_geometric": False,
                                     "outlier_threshold": 1.0}
    if method is not None:
        parameters["estimation"] = {"method": method}
    markers: dict[str, object] = {"name": marker, "reference_joint": reference_joint,
                                  "measurable_dof": [k < measured_dof for k in range(6)]}
    if sensor_type is not None:
        markers["sensor_type"] = sensor_type
    config = {"robot": {"name": robot, "properties": {"joints": {"active_joints": list(joints)}}},
              "tasks": {"calibration": {
                  "enabled": True, "parameters": parameters,
                  "kinematics": {"base_frame": "universe", "tool_frame": tool_frame},
                  "measurements": {"markers": [markers]},
                  "data": {"source_file": str(data_file), "number_of_samples": int(n_samples)}}}}
    return dump_yaml(config)
