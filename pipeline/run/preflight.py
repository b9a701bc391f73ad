"""Feasibility checks before compute (``python -m pipeline check``): seconds instead of a failed run.

For every stage that would run, a small sample goes through the stage's own feasibility
functions, so a robot that cannot run a stage is named before minutes of search:

* calibration: random configurations through the candidate filter
  (:func:`pipeline.calibration.feasibility.probe`): the reflector outside every capsule, seen by
  the tracker within its incidence angle and with a clear beam, in some of them;
* identification: one random excitation that passes the stage's limits and collision check
  (:func:`pipeline.identification.fourier.random_feasible_trajectories`);
* control: the IK seeds inside the limits and collision-free, the ISO 9283 cube (configured or
  derived) and its joint reference (:func:`pipeline.control.design.iso_reference`);
* trajectory: the PtP start and goal collision-free, the CP path's joint path
  (:func:`pipeline.trajectory.solve.cp_joint_path`), and the PtP NLP built as the stage builds it
  (names derived from the URDF, symbolic dynamics; few intervals, not compiled).

Each problem is one :class:`~pipeline.core.errors.PipelineError` naming the setting to change.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import feasibility as fz
from pipeline.calibration.config import Config as CalibrationConfig
from pipeline.control.config import ControlConfig
from pipeline.control.design import iso_reference
from pipeline.core.errors import ConfigError, InfeasibleError, PipelineError
from pipeline.identification import fourier
from pipeline.identification.config import Config as IdentificationConfig
from pipeline.robot.defaults import ik_seeds_or_derived_rad, ptp_move_rad
from pipeline.robot.model import RobotModel
from pipeline.robot.symbolic import SymbolicRobot
from pipeline.run.runner import Prepared
from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.ptp import PtpProblem
from pipeline.trajectory.solve import cp_joint_path

#: random configurations of the calibration probe (a chunk of the stage's own first 1 %)
CHECK_SAMPLES = 40_000
#: random excitations tried before the identification check gives up
EXCITATION_TRIES = 50
#: intervals of the PtP NLP built by the trajectory check (the run's are ``trajectory.ptp_n_intervals``)
CHECK_PTP_INTERVALS = 4


def _calibration(robot: RobotModel, cfg: CalibrationConfig) -> None:
    if cfg.measurements_csv or not robot.has_tracker:
        return
    margins = cd.FilterMargins(cfg.margin_collision_m, math.radians(cfg.margin_incidence_deg), cfg.margin_beam_m)
    diag = fz.probe(cd.chain_from_robot(robot), margins, [c.name for c in robot.capsules], CHECK_SAMPLES)
    if diag.n_feasible == 0:
        raise fz.infeasible_error(diag, robot.spec.path)


def _identification(robot: RobotModel, cfg: IdentificationConfig) -> None:
    if cfg.data_file:
        return
    ex = cfg.excitation
    limits = fourier.ExcitationLimits.from_robot(
        robot, ex.position_margin, ex.velocity_margin, ex.acceleration_margin, ex.torque_margin,
        ex.floor_clearance_m, ex.self_clearance_m, ex.max_tcp_speed_m_s, ex.max_tcp_acceleration_m_s2)
    found = fourier.random_feasible_trajectories(robot, limits, ex.harmonics, ex.base_frequency_hz, 1,
                                                 np.random.default_rng(0), max_tries=EXCITATION_TRIES,
                                                 n_check=ex.n_check)
    if not found:
        raise InfeasibleError(None, "identification.excitation",
                              f"none of {EXCITATION_TRIES} random excitations stays inside the joint, speed and "
                              "torque limits and free of collisions: lower excitation.position_margin / "
                              "self_clearance_m / floor_clearance_m or base_frequency_hz, or check the capsules")


def _collision_free(robot: RobotModel, Q: np.ndarray, field: str) -> None:
    for k, q in enumerate(np.atleast_2d(Q)):
        where = f"{field}[{k}]" if len(np.atleast_2d(Q)) > 1 else field
        if not robot.within_limits(q):
            raise ConfigError(None, where, f"{np.round(np.degrees(q), 1).tolist()} deg is outside the joint limits")
        if robot.in_collision(q):
            raise ConfigError(None, where, f"{np.round(np.degrees(q), 1).tolist()} deg puts capsules of "
                              f"{robot.name} in collision (or below collision.floor_z_m); choose another pose")


def _control(robot: RobotModel, cfg: ControlConfig) -> None:
    if cfg.ik_seeds_deg is not None:
        _collision_free(robot, ik_seeds_or_derived_rad(robot, cfg.ik_seeds_deg), "control.ik_seeds_deg")
    iso_reference(robot, cfg)


def _trajectory(robot: RobotModel, cfg: TrajectoryConfig) -> None:
    if cfg.ptp_start_deg is not None and cfg.ptp_goal_deg is not None:
        _collision_free(robot, np.radians(cfg.ptp_start_deg), "trajectory.ptp_start_deg")
        _collision_free(robot, np.radians(cfg.ptp_goal_deg), "trajectory.ptp_goal_deg")
    else:
        ptp_move_rad(robot)
    if cfg.cp_ik_seed_deg is not None:
        _collision_free(robot, np.radians(cfg.cp_ik_seed_deg), "trajectory.cp_ik_seed_deg")
    cp_joint_path(robot, cfg)
    _build_ptp_nlp(robot, cfg)


def _build_ptp_nlp(robot: RobotModel, cfg: TrajectoryConfig) -> None:
    """The PtP NLP as the stage builds it (its names from the URDF, its symbolic dynamics), on
    :data:`CHECK_PTP_INTERVALS` intervals and not compiled: what would fail building it fails here."""
    pm = PlanningModel.from_robot(robot, cfg.torque_reserve)
    try:
        PtpProblem(pm, SymbolicRobot(robot), CHECK_PTP_INTERVALS, jit=False)
    except RuntimeError as exc:       # CasADi reports an NLP it cannot build as a RuntimeError
        message = " ".join(str(exc).split())
        raise InfeasibleError(None, "trajectory.ptp", f"the point-to-point NLP of {robot.name} cannot be built "
                              f"({message[-200:]})") from None


CHECKS: dict[str, Callable[[Any, Any], None]] = {
    "calibration": _calibration, "identification": _identification, "control": _control,
    "trajectory": _trajectory,
}


def preflight(prep: Prepared) -> Iterator[PipelineError]:
    """The problems of the stages that would run (not reused), one error each, in stage order,
    yielded as found (the caller prints each at once). An error without a file names the file (or
    ``--set``) its setting came from, or the stage when its field is not a setting."""
    for plan in prep.plans:
        check = CHECKS.get(plan.name)
        if check is None or prep.reasons.get(plan.name) is None:
            continue
        try:
            check(prep.nominal, plan.config)
        except PipelineError as exc:
            if exc.file is None and exc.field and exc.field.split(".")[0] in prep.cfg.sections:
                exc = type(exc)(prep.cfg.source_of(exc.field), exc.field, exc.problem)
            elif exc.file is None:          # not a setting (e.g. the IK of a path point): name the stage
                exc = type(exc)(f"stage {plan.name}", exc.field, exc.problem)
            yield exc
