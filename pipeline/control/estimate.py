"""The models the control stage runs on: which kinematics and dynamics the feedforward takes, and
the joint stiffness of the elastic variants.

* Feedforward model: the run's best robot (calibrated kinematics after the calibration, identified
  dynamics after the identification; DESIGN.md "Control"), and for comparison the same kinematics
  with the nominal dynamics (:func:`with_dynamics_of`).
* Joint stiffness of the elastic variants: the calibration's elastostatic record (re-expressed for
  the identified inertias) or the nominal stiffness, per joint (:mod:`pipeline.control.joint_stiffness`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.control.joint_stiffness import StiffnessChoice, feedforward_stiffness
from pipeline.core.config import resolve_robot_dir
from pipeline.robot.handoff import ElastostaticRecord
from pipeline.robot.model import RobotModel
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad
from pipeline.stage_api import StageContext


@dataclass
class ControlModels:
    """The run's robot (``ctx.robot``), the nominal one from its files, and which upstream stages
    changed it (``calibrated``: kinematics, ``identified``: dynamics)."""

    robot: RobotModel
    nominal: RobotModel
    calibrated: bool
    identified: bool


def nominal_robot(ctx: StageContext) -> RobotModel:
    """The robot as loaded from its files."""
    return RobotModel.load(resolve_robot_dir(ctx.run))


def upstream_robot(ctx: StageContext, stage: str) -> RobotModel | None:
    """The robot an upstream stage handed on, None when it did not run."""
    out = ctx.upstream.get(stage)
    return None if out is None else out.robot


def control_models(ctx: StageContext) -> ControlModels:
    """The robot the feedforward takes, the nominal one, and the upstream stages behind it."""
    return ControlModels(ctx.robot, nominal_robot(ctx), upstream_robot(ctx, "calibration") is not None,
                         upstream_robot(ctx, "identification") is not None)


def with_dynamics_of(kinematics_robot: RobotModel, dynamics_robot: RobotModel) -> RobotModel:
    """Copy of ``kinematics_robot`` whose inertias, armature, friction and joint stiffness are
    ``dynamics_robot``'s."""
    out = kinematics_robot.copy()
    for j in range(1, out.model.njoints):
        out.model.inertias[j] = dynamics_robot.model.inertias[j].copy()
    out.model.armature = np.array(dynamics_robot.model.armature).copy()
    for name in ("viscous_Nms_rad", "coulomb_Nm", "rotor_inertia_kgm2"):
        setattr(out.actuation, name, np.array(getattr(dynamics_robot.actuation, name)).copy())
    for name in ("static_friction_excess_Nm", "stribeck_velocity_rad_s",    # identified Stribeck term, or None
                 "coulomb_load_coefficient"):                               # and load-dependent Coulomb term
        value = getattr(dynamics_robot.actuation, name)
        setattr(out.actuation, name, None if value is None else np.array(value).copy())
    out.spec.actuation.joint_stiffness_Nm_rad = nominal_joint_stiffness_Nm_rad(dynamics_robot)
    return out


def elastic_stiffness(ctx: StageContext, models: ControlModels) -> StiffnessChoice:
    """The elastic variants' stiffness, calibrated (re-expressed for the identified inertias) or
    nominal per joint; set on ``models.robot``'s actuation, where the feedforward reads it."""
    robot = models.robot
    cal_out = ctx.upstream.get("calibration")
    record = None if cal_out is None else ElastostaticRecord.from_arrays(cal_out.arrays, robot.nq)
    stiffness = feedforward_stiffness(robot, record, models.identified,
                                      nominal_joint_stiffness_Nm_rad(models.nominal))
    robot.spec.actuation.joint_stiffness_Nm_rad = stiffness.stiffness_Nm_rad
    return stiffness
