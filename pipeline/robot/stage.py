"""Stage ``model``: record the robot that the later stages start from.

Summary: DOF, reach (axis 1 to flange), moving mass, payload, joint limits
(:meth:`RobotModel.summary`); arrays: the limits in SI units; figures: a matplotlib picture of
the robot (kinematic chain and collision capsules) at the configured pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import ConfigError
from pipeline.plotting import robot_figure
from pipeline.runner import StageContext, StageResult

NAME = "model"
DEPENDS: tuple[str, ...] = ()


@dataclass
class Config:
    """Picture settings of the ``model`` stage."""

    #: (elevation, azimuth) of each view in degrees
    views_deg: tuple[tuple[float, float], ...] = ((25.0, -60.0), (0.0, -90.0))
    #: joint configuration drawn (degrees, Pinocchio order); None: a "ready" pose
    #: (axis 2 at +30 deg, axis 3 at +60 deg where within limits, others 0)
    pose_deg: tuple[float, ...] | None = None
    picture_size_in: float = 5.0


def _pose(ctx: StageContext) -> np.ndarray:
    robot = ctx.robot
    lim = robot.limits
    if ctx.config.pose_deg is None:
        q = np.zeros(robot.nq)
        if robot.nq >= 3:
            q[1], q[2] = np.deg2rad(30.0), np.deg2rad(60.0)
        return np.clip(q, lim.lower_rad, lim.upper_rad)
    q = np.deg2rad(np.asarray(ctx.config.pose_deg, float))
    if q.shape != (robot.nq,):
        raise ConfigError(ctx.run.source, "model.pose_deg", f"expected {robot.nq} angles, got {q.size}")
    if not robot.within_limits(q):
        raise ConfigError(ctx.run.source, "model.pose_deg", "outside the joint limits")
    return q


def run(ctx: StageContext) -> StageResult:
    robot = ctx.robot
    q = _pose(ctx)
    summary = robot.summary()
    lim = robot.limits
    fig = robot_figure(robot, q, views=ctx.config.views_deg, size_in=ctx.config.picture_size_in,
                       title=f"{robot.name}: {robot.nq} DOF, reach {summary['reach_m']:.3f} m, "
                             f"pose {np.round(np.rad2deg(q), 1).tolist()} deg")
    arrays = {
        "lower_rad": lim.lower_rad,
        "upper_rad": lim.upper_rad,
        "velocity_rad_s": lim.velocity_rad_s,
        "effort_Nm": lim.effort_Nm,
        "acceleration_rad_s2": lim.acceleration_rad_s2,
        "picture_q_rad": q,
        "flange_at_zero_m": robot.fk(np.zeros(robot.nq), robot.frame_flange).translation,
    }
    rows = [f"**{robot.name}**: {robot.nq} DOF, reach {summary['reach_m']:.3f} m (axis 1 to flange), moving mass "
            f"{summary['moving_mass_kg']:.1f} kg, payload {summary['payload_kg']:.1f} kg.", "",
            "| joint | lower [deg] | upper [deg] | velocity [deg/s] | torque [N·m] | gear ratio |",
            "|---|---|---|---|---|---|"]
    for i, name in enumerate(summary.get("joint_names", [f"q{i + 1}" for i in range(robot.nq)])):
        rows.append(f"| {name} | {np.rad2deg(lim.lower_rad[i]):.1f} | {np.rad2deg(lim.upper_rad[i]):.1f} | "
                    f"{np.rad2deg(lim.velocity_rad_s[i]):.0f} | {lim.effort_Nm[i]:.0f} | "
                    f"{robot.actuation.gear_ratio[i]:g} |")
    return StageResult(summary=summary, arrays=arrays, figures={"robot": fig},
                       data={"pose_deg": np.rad2deg(q)}, report_md="\n".join(rows))
