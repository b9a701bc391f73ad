"""Stage ``control``: model-based feedforward on the EN ISO 9283 path, simulated at 400 µs.

Paper ``004_abbe750b8bbcc3aa.txt`` §2.3 (DESIGN.md "Control", "EN ISO 9283 test path"). The steps
of :func:`run`, each in its own module:

1. models (:mod:`.estimate`): the best kinematics (calibrated after stage 1) and dynamics
   (identified after stage 2), the nominal robot, the elastic variants' joint stiffness;
2. design (:mod:`.design`): the ISO path (cube of edge L, diagonal plane, P1..P5) with a ruckig
   speed profile, IK at every sample -> q_d, v_d, a_d; servo design per joint from the reflected
   inertia (python-control, margins);
3. measure (:mod:`.measure`): the cascade closed around the real robot's plant (delays, encoder
   noise) for each feedforward variant (none, gravity, rigid body, rigid body + friction, elastic)
   from the best dynamics and, for comparison, from the nominal model; the same with the nominal
   kinematics (effect of the calibration on absolute TCP accuracy); the loop's speed;
4. validate (:mod:`.validate`): lag and TCP errors, registered and tracking errors;
5. report (:mod:`.report`): summary, figures, arrays, report text.

Works without the upstream stages (then ctx.robot is the nominal model and the comparisons
collapse to equal numbers; the summary says which models were used). The summary's keys are
listed in :mod:`pipeline.control.report`.
"""

from __future__ import annotations

import numpy as np

from pipeline.control import report
from pipeline.control.config import ControlConfig
from pipeline.control.design import (
    IsoReference,
    ServoDesign,
    filter_alpha,
    iso_reference,
    servo_report,
)
from pipeline.control.elastic_feedforward import ELASTIC_VARIANTS
from pipeline.control.estimate import ControlModels, control_models, elastic_stiffness
from pipeline.control.joint_stiffness import StiffnessChoice, deflection_budget, stiffness_markdown
from pipeline.control.measure import ServoRuns, kinematics_comparison, loop_speed, runs_within_torque
from pipeline.control.simulate import feedforward_coulomb_width, servo_gains
from pipeline.core.errors import ConfigError, PipelineError
from pipeline.robot.model import RobotModel
from pipeline.stage_api import StageContext, StageResult

NAME = "control"
DEPENDS: tuple[str, ...] = ("model", "calibration", "identification")
#: the stage's section (pipeline.stage_api.StageModule)
Config = ControlConfig
CONFIG_READS: tuple[str, ...] = ()
RECORDED_INPUT = ""
#: provenance (pipeline.run.stage_plan): what is simulated (this stage reads no recorded file)
SIMULATES = "servo loop on the hidden robot"
warm_up = None                       # its compiled code is built where it is used
__all__ = ["NAME", "DEPENDS", "CONFIG_READS", "RECORDED_INPUT", "SIMULATES", "Config", "check", "warm_up", "run"]


def check(config: ControlConfig, robot: RobotModel) -> None:
    """Validate the section against the robot before anything runs (ConfigError naming the field)."""
    config.validate(None)
    nq = robot.nq
    for i, seed in enumerate(config.ik_seeds_deg or []):
        if len(seed) != nq:
            raise ConfigError(None, f"control.ik_seeds_deg[{i}]", f"expected {nq} joint angles (deg) for robot "
                              f"{robot.name}, got {len(seed)}: {list(seed)!r}")


def run(ctx: StageContext[ControlConfig]) -> StageResult:
    cfg: ControlConfig = ctx.config
    if ctx.real is None:
        raise PipelineError(None, "control", "the hidden robot (pipeline.sim.truth) is not available")
    models = control_models(ctx)
    iso = iso_reference(models.robot, cfg)
    stiffness = elastic_stiffness(ctx, models)
    servo = design_servo(models.robot, iso, cfg)
    iso, measured = runs_within_torque(ctx, models, iso, servo)
    rms_nominal_kin, registered = kinematics_comparison(ctx, models, iso, servo, measured)
    speed = loop_speed(ctx, iso, servo, measured)
    out = outputs(cfg, models, iso, servo, measured, stiffness, speed, rms_nominal_kin, registered)
    width = feedforward_coulomb_width(ctx.real, models.robot, cfg)
    if width is not None:      # the arm's dry friction sticks: the feedforward's sign switching (.simulate)
        out.summary["feedforward_coulomb_width_rad_s"] = width.tolist()
    return out


def design_servo(robot: RobotModel, iso: IsoReference, cfg: ControlConfig) -> ServoDesign:
    """Gains from the reflected inertia at the reference's mean configuration, margins per joint."""
    gains = servo_gains(robot, np.mean(iso.ref.q_d, axis=0), cfg)
    nv = cfg.velocity_samples_per_position_sample
    alpha = filter_alpha(cfg.velocity_filter_hz, cfg.sample_time_s / nv)
    return ServoDesign(gains, nv, alpha, servo_report(gains, cfg.sample_time_s, nv, cfg.measurement_delay_samples,
                                                      alpha))


def outputs(cfg: ControlConfig, models: ControlModels, iso: IsoReference, servo: ServoDesign, measured: ServoRuns,
            stiffness: StiffnessChoice, speed: dict[str, float], rms_nominal_kin: float,
            registered: dict[str, float]) -> StageResult:
    """Summary, figures, arrays, data and report text of the runs (:mod:`pipeline.control.report`)."""
    summary = report.summary(cfg, iso, measured.metrics, measured.main, speed, rms_nominal_kin,
                             models.calibrated, models.identified, servo.report)
    summary.update(registered)
    stiffness_md = ""
    if any(v in ELASTIC_VARIANTS for v in cfg.variants):
        ref = iso.ref
        budget = deflection_budget(models.robot, ref.q_d, ref.v_d, ref.a_d, stiffness.stiffness_Nm_rad, iso.frame)
        summary["joint_stiffness"] = report.stiffness_summary(stiffness, budget)
        stiffness_md = "\n\n" + stiffness_markdown(stiffness, budget)
    figures = report.figures(iso, measured, servo, cfg, models.robot.nq)
    return StageResult(summary=summary, arrays=report.arrays(iso, measured, servo, cfg),
                       data=report.data(iso, measured, servo), figures=figures,
                       report_md=report.report_markdown(summary, measured.metrics, servo.report) + stiffness_md)
