"""Stage ``model``: record the robot that the later stages start from.

Summary: DOF, reach (axis 1 to flange), moving mass, payload, joint limits
(:meth:`RobotModel.summary`), the assumptions still in force and the plausibility warnings
(:mod:`pipeline.robot.plausibility`); arrays: the limits in SI units; figures: a matplotlib picture of
the robot (kinematic chain and collision capsules) at the configured pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.core.errors import ConfigError
from pipeline.robot.defaults import ready_pose_rad
from pipeline.robot.model import RobotModel
from pipeline.robot.plausibility import robot_warnings
from pipeline.robot.plotting import robot_figure
from pipeline.stage_api import StageContext, StageResult

NAME = "model"
DEPENDS: tuple[str, ...] = ()
CONFIG_READS: tuple[str, ...] = ()
#: provenance (pipeline.run.stage_plan): no measurement, the robot files only
RECORDED_INPUT = ""
SIMULATES = ""
warm_up = None                       # nothing compiled


#: bounds of ``model.picture_size_in`` (inches per view) and of the number of views
PICTURE_SIZE_RANGE_IN = (1.0, 20.0)
MAX_VIEWS = 6
#: slack (rad) when comparing ``model.pose_deg`` with the joint limits (degree rounding)
LIMIT_TOLERANCE_RAD = 1e-9


@dataclass
class Config:
    """Picture settings of the ``model`` stage."""

    #: (elevation, azimuth) of each view in degrees
    views_deg: tuple[tuple[float, float], ...] = ((25.0, -60.0), (0.0, -90.0))
    #: joint configuration drawn (degrees, Pinocchio order); None: a "ready" pose
    #: (axis 2 at +30 deg, axis 3 at +60 deg where within limits, others 0)
    pose_deg: tuple[float, ...] | None = None
    picture_size_in: float = 5.0

    def validate(self, source: str) -> None:
        """Robot-independent ranges (the pose's length and limits: :func:`check`)."""
        if not 1 <= len(self.views_deg) <= MAX_VIEWS:
            raise ConfigError(source, "model.views_deg",
                              f"expected 1 to {MAX_VIEWS} [elevation, azimuth] pairs (deg), "
                              f"got {len(self.views_deg)}")
        for k, (elev, azim) in enumerate(self.views_deg):
            if not (np.isfinite(elev) and -90.0 <= elev <= 90.0):
                raise ConfigError(source, f"model.views_deg[{k}]",
                                  f"expected an elevation in [-90, 90] deg, got {elev}")
            if not (np.isfinite(azim) and -360.0 <= azim <= 360.0):
                raise ConfigError(source, f"model.views_deg[{k}]",
                                  f"expected an azimuth in [-360, 360] deg, got {azim}")
        if self.pose_deg is not None:
            if len(self.pose_deg) == 0:
                raise ConfigError(source, "model.pose_deg",
                                  "expected one angle (deg) per joint or null, got an empty list")
            if not np.all(np.isfinite(self.pose_deg)):
                raise ConfigError(source, "model.pose_deg",
                                  f"expected finite angles (deg), got {list(self.pose_deg)}")
        lo, hi = PICTURE_SIZE_RANGE_IN
        if not (np.isfinite(self.picture_size_in) and lo <= self.picture_size_in <= hi):
            raise ConfigError(source, "model.picture_size_in",
                              f"expected a size in [{lo:g}, {hi:g}] inches, got {self.picture_size_in}")


def _pose_problem(pose_deg: tuple[float, ...], robot: RobotModel) -> str | None:
    """Why ``pose_deg`` does not fit ``robot`` (length, joint limits), or None."""
    if len(pose_deg) != robot.nq:
        return f"expected {robot.nq} angles (deg), one per joint, got {len(pose_deg)}"
    q = np.deg2rad(np.asarray(pose_deg, float))
    lim = robot.limits
    names = [str(n) for n in robot.model.names[1:]]
    for i, qi in enumerate(q):
        lower, upper = lim.lower_rad[i], lim.upper_rad[i]
        if qi < lower - LIMIT_TOLERANCE_RAD or qi > upper + LIMIT_TOLERANCE_RAD:
            name = names[i] if i < len(names) else f"q{i + 1}"
            return (f"angle {i + 1} ({name}) is {pose_deg[i]:g} deg, outside the joint limits "
                    f"[{np.rad2deg(lower):.1f}, {np.rad2deg(upper):.1f}] deg")
    return None


def check(config: Config, robot: RobotModel) -> None:
    """Robot-dependent checks, run before anything is written: ``pose_deg`` has one angle
    per joint, each within the joint limits."""
    if config.pose_deg is not None:
        problem = _pose_problem(config.pose_deg, robot)
        if problem:
            raise ConfigError(None, "model.pose_deg", problem)


def _pose(ctx: StageContext) -> np.ndarray:
    robot = ctx.robot
    lim = robot.limits
    if ctx.config.pose_deg is None:
        return ready_pose_rad(robot)          # derived from the robot: collision-free, above the floor
    problem = _pose_problem(ctx.config.pose_deg, robot)      # check() ran already; a safety net
    if problem:
        raise ConfigError(ctx.run.source_of("model.pose_deg"), "model.pose_deg", problem)
    q = np.deg2rad(np.asarray(ctx.config.pose_deg, float))
    return np.clip(q, lim.lower_rad, lim.upper_rad)        # within the tolerance: onto the limit


def run(ctx: StageContext[Config]) -> StageResult:
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
    if robot.assumptions:
        rows += ["", "**Assumptions** (the robot files do not say these; `python -m pipeline robot init` writes "
                 "them to a robot.yaml to edit):", ""] + [f"* {a}" for a in robot.assumptions]
    if not robot.has_tracker:
        rows += ["", "No tracker in robot.yaml: no calibration; later stages use the nominal kinematics."]
    warnings = robot_warnings(robot, summary)
    for warning in warnings:
        ctx.progress.log(f"model: warning: {warning}")
    if warnings:
        rows += ["", "**Plausibility warnings** (against data-sheet scaling of serial arms, "
                 "`pipeline.robot.plausibility`):", ""] + [f"* {w}" for w in warnings]
    summary["assumptions"] = list(robot.assumptions)
    summary["plausibility_warnings"] = warnings
    summary["has_tracker"] = bool(robot.has_tracker)
    return StageResult(summary=summary, arrays=arrays, figures={"robot": fig},
                       data={"pose_deg": np.rad2deg(q)}, report_md="\n".join(rows))
