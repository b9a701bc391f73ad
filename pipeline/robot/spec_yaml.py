"""robot.yaml written back from a :class:`~pipeline.robot.spec.RobotSpec` (the inverse of
:func:`pipeline.robot.spec.load_robot_spec`), used to save calibrated and identified models."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pipeline.robot.spec import OpticalTrackerSpec, RobotSpec


def _optical_yaml(o: OpticalTrackerSpec) -> dict[str, object]:
    return {"transform_camera_to_base": _se3_yaml(o.transform_camera_to_base),
            "camera_positions_m": [[float(v) for v in c] for c in o.camera_positions_m],
            "field_of_view_half_angle_deg": float(np.rad2deg(o.field_of_view_half_angle_rad)),
            "range_m": [float(v) for v in o.range_m],
            "probe_diodes_m": [[float(v) for v in d] for d in o.probe_diodes_m],
            "diode_axis": [float(v) for v in o.diode_axis],
            "emission_half_angle_deg": float(np.rad2deg(o.emission_half_angle_rad)),
            "min_diodes": int(o.min_diodes), "noise_const_m": float(o.noise_const_m),
            "noise_per_m": float(o.noise_per_m)}


def _one_or_each(values: np.ndarray) -> float | list[float]:
    """One number when every joint's value is the same, else the list (read back by ``number_or_vector``)."""
    return float(values[0]) if np.all(values == values[0]) else [float(v) for v in values]


def _se3_yaml(transform: pin.SE3) -> dict[str, list[float]]:
    return {"xyz": [float(v) for v in transform.translation],
            "rpy": [float(v) for v in pin.rpy.matrixToRpy(transform.rotation)]}


def robot_spec_to_yaml(spec: RobotSpec, urdf_name: str) -> dict[str, object]:
    """Inverse of :func:`load_robot_spec` (used to save calibrated/identified models)."""
    act = spec.actuation
    coupling = [[int(i), int(j), float(act.gear_matrix[i, j])]
                for i, j in zip(*np.nonzero(act.gear_matrix - np.diag(np.diag(act.gear_matrix))), strict=True)]
    out: dict[str, object] = {
        "name": spec.name,
        "urdf": urdf_name,
        "flange_frame": spec.flange_frame,
        "payload_kg": float(spec.payload_kg),
        **({} if spec.repeatability_m is None else {"repeatability_m": float(spec.repeatability_m)}),
        "tool": {
            "transform_tcp_to_flange": _se3_yaml(spec.tool.transform_tcp_to_flange),
            "reflector_offset_m": [float(v) for v in spec.tool.reflector_offset_m],
            "reflector_axis": [float(v) for v in spec.tool.reflector_axis],
        },
        "actuation": {
            "gear_ratio": [float(v) for v in act.gear_ratio],
            "gear_coupling": coupling,
            "rotor_inertia_kgm2": [float(v) for v in act.rotor_inertia_kgm2],
            "viscous_Nms_rad": [float(v) for v in act.viscous_Nms_rad],
            "coulomb_Nm": [float(v) for v in act.coulomb_Nm],
            "coulomb_smoothing_rad_s": _one_or_each(act.coulomb_smoothing_rad_s),
            "torque_side": act.torque_side,
        } | ({} if act.joint_stiffness_Nm_rad is None
             else {"joint_stiffness_Nm_rad": [float(v) for v in act.joint_stiffness_Nm_rad]})
        | ({} if act.static_friction_excess_Nm is None or act.stribeck_velocity_rad_s is None
           else {"static_friction_excess_Nm": [float(v) for v in act.static_friction_excess_Nm],
                 "stribeck_velocity_rad_s": [float(v) for v in act.stribeck_velocity_rad_s]})
        | ({} if act.coulomb_load_coefficient is None
           else {"coulomb_load_coefficient": [float(v) for v in act.coulomb_load_coefficient]}),
        "limits": {"acceleration_rad_s2": [float(v) for v in spec.acceleration_rad_s2]}
        | {k: [float(x) for x in v] for k, v in spec.limit_overrides.items()},
        "tracker": None if not spec.has_tracker else {
            "transform_tracker_to_base": _se3_yaml(spec.tracker.transform_tracker_to_base),
            "noise_const_m": float(spec.tracker.noise_const_m),
            "noise_per_m": float(spec.tracker.noise_per_m),
            "max_incidence_deg": float(np.rad2deg(spec.tracker.max_incidence_rad)),
        },
        "collision": {"floor_z_m": float(spec.collision.floor_z_m),
                      "floor_check_from_joint": int(spec.collision.floor_check_from_joint),
                      "ignore_pairs": [list(p) for p in spec.collision.ignore_pairs]},
        "capsules": [
            {"name": c.name, "frame": c.frame, "p0": [float(v) for v in c.p0], "p1": [float(v) for v in c.p1],
             "radius_m": float(c.radius_m)}
            for c in spec.capsules
        ],
    }
    extra = {"base_link": spec.base_link, "locked_joints": {k: float(v) for k, v in spec.locked_joints.items()},
             "assumptions": list(spec.assumptions), "assumed": {k: dict(v) for k, v in spec.assumed.items()}}
    out |= {k: v for k, v in extra.items() if v}
    if spec.optical_tracker is not None:
        out["optical_tracker"] = _optical_yaml(spec.optical_tracker)
    return out
