"""``python -m pipeline export RUN_DIR``: every designed experiment and plan of a run, as files for an arm.

For each stage the run holds (files and columns: ``docs/exchange.md``):

- calibration: ``calibration_poses.csv`` (the designed poses in the tour's order, the TCP and
  reflector positions the nominal model predicts, the tracker's line of sight),
  ``calibration_measurements_template.csv`` (``q1..qn,x,y,z`` as ``calibration.measurements_csv``
  reads it, x, y, z left to fill) and the motion ``calibration_tour`` (a designed experiment), with
  ``--program`` also as controller programs of its joint waypoints (URScript, KRL, RAPID:
  :mod:`pipeline.exchange.robot_program`);
  ``calibration_parameters.csv`` (the identified error parameters, their standard deviations and units);
- identification: the motion ``excitation`` (approach, the designed periods, return; nominal torque);
- trajectory: the motions ``trajectory_<plan>`` (q, q̇, q̈, feedforward from the identified model);
- control: ``servo_gains.yaml``;
- always ``robot/``: the handed-on model as a robot folder (URDF with the joint types of its source and
  the joint friction, ``robot.yaml``) and ``joint_limits.yaml``.

Every motion is written as ``<name>.csv`` and as the rosbag2 folder ``<name>/`` (JointTrajectory on
``/<robot>/joint_trajectory``), after the check of every sample against the joint limits. All files
are written into a staging folder beside the target and renamed into place at the end.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pipeline.calibration.error_model import TRACKER_NAMES, parameter_unit
from pipeline.calibration.report import identified_parameters
from pipeline.core.artefacts import write_text
from pipeline.core.errors import ArtefactWriteError, PipelineError
from pipeline.core.yaml12 import read_yaml_file, yaml_key
from pipeline.exchange.joint_limits import JointLimitTable, handed_on_urdf, write_joint_limits_yaml
from pipeline.exchange.motion import SampledMotion
from pipeline.exchange.parameter_table import ParameterTable, write_parameter_table_csv
from pipeline.exchange.robot_program import AXES, ProgramFormat
from pipeline.exchange.ros2_bag import BagFormat, joint_trajectory_topic
from pipeline.identification.config import Config as IdentificationConfig
from pipeline.identification.fourier import FourierTrajectory
from pipeline.robot.defaults import ready_pose_rad
from pipeline.robot.model import RobotModel
from pipeline.run import export_motions as em
from pipeline.run.export_motions import ExportContext
from pipeline.run.export_tour import calibration_files
from pipeline.run.stage_io import load_run
from pipeline.stage_api import StageOutput

#: the stages whose robot is handed on, last first
HANDED_ON_ORDER = ("trajectory", "control", "identification", "calibration", "model")


def _nominal_robot(run_dir: Path) -> tuple[RobotModel, dict]:
    config_file = run_dir / "config.yaml"
    if not config_file.is_file():
        raise PipelineError(run_dir, None, "not a run directory (no config.yaml)")
    config = read_yaml_file(config_file, PipelineError)
    if not isinstance(config, dict) or not isinstance(config.get("robot"), str):
        raise PipelineError(config_file, "robot", "missing: not a run's config.yaml")
    return RobotModel.load(config["robot"]), config


def _parse_start(start: Sequence[float] | None, robot: RobotModel) -> np.ndarray:
    if start is None:
        return ready_pose_rad(robot)
    q = np.asarray(start, float)
    if q.shape != (robot.nq,):
        raise PipelineError(None, "--start", f"{q.size} values, {robot.name} has {robot.nq} joints")
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    if np.any(q < lo) or np.any(q > hi):
        j = int(np.argmax((q < lo) | (q > hi)))
        raise PipelineError(None, "--start", f"joint {j + 1} at {q[j]:.4f} rad is outside [{lo[j]:.4f}, {hi[j]:.4f}]")
    if robot.in_collision(q):
        raise PipelineError(None, "--start", "the start configuration collides (the stages' capsules)")
    return q


def excitation_motion(ctx: ExportContext, ident: StageOutput, periods: int) -> SampledMotion | None:
    """The designed excitation: approach from the start, ``periods`` periods, return; nominal torque."""
    traj_data = ident.data.get("excitation", {}).get("trajectory")
    if not traj_data:
        return None      # a recorded identification: nothing designed
    traj = FourierTrajectory(np.asarray(traj_data["coefficients"], float), float(traj_data["base_frequency_hz"]))
    n = max(int(round(traj.period_s * periods * ctx.rate_hz)), 2)
    t = np.linspace(0.0, traj.period_s * periods, n + 1)
    q, v, a = traj.evaluate(t)
    rest = (ctx.start_rad, np.zeros(ctx.nominal.nq), np.zeros(ctx.nominal.nq))
    approach = em.move(ctx.nominal, ctx.limits, rest, (q[0], v[0], a[0]), ctx.rate_hz, "excitation (approach)")
    back = em.move(ctx.nominal, ctx.limits, (q[-1], v[-1], a[-1]), rest, ctx.rate_hz, "excitation (return)")
    return em.joined(ctx.nominal, [approach, (t, q, v, a), back], ctx.nominal)


def plan_motions(ctx: ExportContext, traj: StageOutput, torque_robot: RobotModel) -> dict[str, SampledMotion]:
    """Every stored plan ``trajectory_<name>_t/_q`` re-sampled at the rate, feedforward from ``torque_robot``."""
    out = {}
    for key in sorted(traj.arrays):
        if key.startswith("trajectory_") and key.endswith("_t") and f"{key[:-2]}_q" in traj.arrays:
            t_plan, q_plan = np.asarray(traj.arrays[key], float), traj.arrays[f"{key[:-2]}_q"]
            t, q, v, a = em.resample_plan(t_plan, q_plan, ctx.rate_hz)
            slower = em.time_scale_within(v, a, ctx.limits)
            if slower > 1.0:    # a plan stored a hair over a limit: slowed uniformly to keep it
                ctx.notes.append(f"{key[:-2]}: slowed by {100 * (slower - 1):.3g} % to keep the velocity and "
                                 "acceleration limits on its samples")
                t, q, v, a = em.resample_plan(t_plan * slower, q_plan, ctx.rate_hz)
            out[key[:-2]] = em.joined(ctx.nominal, [(t, q, v, a)], torque_robot)
    return out


def servo_gains_yaml(control: StageOutput, joint_names: Sequence[str]) -> str:
    """Per-axis gains with the sample time and delays they were designed for (YAML text)."""
    s, a = control.summary, control.arrays
    delays = s.get("delay_samples", {})
    lines = ["# servo gains per axis (cascade: position P, velocity PI) and what they were designed for",
             "# kp_1_s: position gain 1/s; kv_Nms_rad: velocity gain N m s/rad; ki_Nm_rad: velocity integral N m/rad",
             f"sample_time_s: {float(s.get('sample_time_s', float('nan'))):.17g}",
             f"velocity_sample_time_s: {float(s.get('velocity_sample_time_s', float('nan'))):.17g}",
             f"setpoint_delay_samples: {int(delays.get('setpoint', 0))}",
             f"measurement_delay_samples: {int(delays.get('measurement', 0))}",
             f"feedforward_advanced: {str(bool(s.get('feedforward_advanced', False))).lower()}",
             "axes:"]
    for j, name in enumerate(joint_names):
        lines += [f"  {yaml_key(name)}:",
                  f"    kp_1_s: {float(a['servo_kp_1_s'][j]):.17g}",
                  f"    kv_Nms_rad: {float(a['servo_kv_Nms_rad'][j]):.17g}",
                  f"    ki_Nm_rad: {float(a['servo_ki_Nm_rad'][j]):.17g}"]
    return "\n".join(lines) + "\n"


def robot_files(ctx: ExportContext) -> None:
    """``robot/``: the handed-on model as a robot folder (URDF with the source's joint types and the joint
    friction, robot.yaml: ``--set robot=export/robot`` loads it back) and MoveIt's joint_limits.yaml."""
    folder = ctx.staging / "robot"
    ctx.handed_on.save(folder, handed_on_urdf(ctx.handed_on, ctx.nominal.urdf_path))
    write_joint_limits_yaml(folder / "joint_limits.yaml", ctx.limits,
                            f"robot {ctx.handed_on.name}; continuous joints keep the limits the plans were verified "
                            "against")
    ctx.written += [f"robot/{ctx.handed_on.name}.urdf", "robot/robot.yaml", "robot/joint_limits.yaml"]


def export_run(run_dir: str | Path, to: str | Path | None = None, rate_hz: float = 1000.0,
               start: Sequence[float] | None = None,
               bag_format: BagFormat = "sqlite3",
               programs: Sequence[ProgramFormat] = ()) -> tuple[Path, list[str], list[str]]:
    """Export a finished run (module docstring); returns the folder, the files written and the notes."""
    run = Path(run_dir)
    if not run.is_dir():
        raise PipelineError(run, None, "run directory not found")
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise PipelineError(None, "--rate-hz", f"must be > 0, got {rate_hz}")
    if bag_format not in ("sqlite3", "mcap"):
        raise PipelineError(None, "--bag-format", f"must be sqlite3 or mcap, got {bag_format!r}")
    nominal, config = _nominal_robot(run)
    if programs and nominal.nq != AXES:
        raise PipelineError(None, "--program", f"{', '.join(programs)} drive {AXES} axes; {nominal.name} has "
                            f"{nominal.nq} joints")
    stages = load_run(run)
    if not stages:
        raise PipelineError(run, None, "no finished stage to export")
    handed = _robot_of(stages, HANDED_ON_ORDER, nominal)
    target = Path(to) if to is not None else run / "export"
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = target.with_name(f".{target.name}.partial-{os.getpid()}")
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    try:
        ctx = ExportContext(run, staging, nominal, handed, JointLimitTable.of_model(nominal),
                            _parse_start(start, nominal), float(rate_hz), bag_format,
                            joint_trajectory_topic(nominal.name), tuple(programs))
        _export_stages(ctx, stages, config)
        robot_files(ctx)
        _replace(staging, target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return target, ctx.written, ctx.notes


def _robot_of(stages: dict[str, StageOutput], order: Sequence[str], default: RobotModel) -> RobotModel:
    """The robot of the first stage in ``order`` that holds one, else ``default``."""
    for name in order:
        robot = stages[name].robot if name in stages else None
        if robot is not None:
            return robot
    return default


def _export_stages(ctx: ExportContext, stages: dict[str, StageOutput], config: dict) -> None:
    if "calibration" in stages and "configurations_selected" in stages["calibration"].arrays \
            and not str(stages["calibration"].summary.get("selection_method", "")).startswith("user"):
        calibration_files(ctx, stages["calibration"])
    if "calibration" in stages:
        calibration_parameters(ctx, stages["calibration"])
    if "identification" in stages:
        raw = config.get("identification")
        section: dict = raw if isinstance(raw, dict) else {}
        periods = int(section.get("periods", IdentificationConfig().periods))
        motion = excitation_motion(ctx, stages["identification"], periods)
        if motion is not None:
            ctx.write_motion("excitation", motion)
    if "trajectory" in stages:
        torque_robot = _robot_of(stages, ("identification", "trajectory"), ctx.nominal)
        for name, motion in plan_motions(ctx, stages["trajectory"], torque_robot).items():
            ctx.write_motion(name, motion)
    if "control" in stages and "servo_kp_1_s" in stages["control"].arrays:
        write_text(ctx.staging / "servo_gains.yaml",
                   servo_gains_yaml(stages["control"], [str(n) for n in ctx.nominal.model.names[1:]]))
        ctx.written.append("servo_gains.yaml")


def calibration_parameters(ctx: ExportContext, calibration: StageOutput) -> None:
    """``calibration_parameters.csv``: every identified error parameter of the arm and its reflector
    (deviation from the nominal model, :mod:`pipeline.calibration.error_model`: joint placement offsets,
    joint zero offsets ``j{i}.dq``, compliances, the reflector offset) with its standard deviation and
    unit. The tracker's pose is a parameter of the set-up, estimated about its registration, not of the
    arm: left out."""
    identified = [p for p in identified_parameters(calibration.data) if p[0] not in TRACKER_NAMES]
    if not identified:
        return
    names = tuple(name for name, _, _ in identified)
    table = ParameterTable(names, np.array([v for _, v, _ in identified]), np.array([s for _, _, s in identified]),
                           tuple(parameter_unit(name) for name in names))
    write_parameter_table_csv(ctx.staging / "calibration_parameters.csv", table)
    ctx.written.append("calibration_parameters.csv")


def _replace(staging: Path, target: Path) -> None:
    """``staging`` renamed to ``target``; an older export there is removed only after the rename."""
    old = target.with_name(f".{target.name}.old-{os.getpid()}")
    try:
        if target.exists():
            target.rename(old)
        staging.rename(target)
    except OSError as exc:
        if old.exists() and not target.exists():
            old.rename(target)
        raise ArtefactWriteError(target, None, f"cannot move the export into place: {exc}") from exc
    shutil.rmtree(old, ignore_errors=True)
