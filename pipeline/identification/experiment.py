"""The identification experiment, steps 1-4 of :mod:`pipeline.identification.stage`: the model the
torques are fitted to and the data they come from (paper ``004_abbe750b8bbcc3aa.txt`` §4.1-4.2).

* :func:`regressors`: the regressor of the current model (calibrated kinematics when the run has a
  calibration), the joints whose torques the fit uses (:mod:`.joints`) and the structural base
  set, decided on the nominal robot and kept for the current one (:mod:`.base_set`);
* :func:`excite_and_measure`: the user's record processed (:func:`.measure.process_record`; no
  excitation, nothing simulated; its efforts read against the nominal model and converted to joint
  torques when they are in another unit: :mod:`.effort_unit`), or the optimal Fourier excitation
  (:mod:`.design`) run on the hidden robot for ``periods`` periods and processed (period averaging,
  zero-phase filtering, differentiation, block decimation: :func:`.measure.process_periodic`);
* :func:`leave_out_dwells`: the rows at which a record's joint is at rest, left out of the fits
  (:mod:`.dwell`);
* :func:`choose_record_coulomb_widths`: a record's Coulomb smoothing width per joint, chosen on its
  training part without those rows (:mod:`.coulomb_width`);
* :func:`take_off_record_terms`: a record's friction and actuation terms beyond viscous + Coulomb
  friction, taken off its torques before the fits (:mod:`.friction_terms`).
"""

from __future__ import annotations

import time

import numpy as np

from pipeline.core.config import resolve_robot_dir
from pipeline.core.errors import InfeasibleError, PipelineError
from pipeline.identification import design as design_mod
from pipeline.identification import fourier
from pipeline.identification import measure as meas_mod
from pipeline.identification.base_set import (
    DESIGN_COND_MARGIN,
    columns_over_condition,
    structural_base_parameters,
    without_columns,
)
from pipeline.identification.config import DATA_BORDER_SAMPLES, Config
from pipeline.identification.coulomb_width import choose_widths, with_widths
from pipeline.identification.dwell import Dwells
from pipeline.identification.effort_unit import EffortUnit, read_effort_unit, scaled
from pipeline.identification.fit import offset_mask
from pipeline.identification.friction_terms import FrictionTerms, record_terms
from pipeline.identification.joints import select_joints
from pipeline.identification.outcome import Measured, Regressors
from pipeline.identification.record import load_user_record
from pipeline.identification.regressor import RegressorModel, standard_parameters
from pipeline.robot.assumed_values import predicted_drive_values
from pipeline.robot.model import RobotModel
from pipeline.robot.plausibility import placeholder_kind
from pipeline.robot.symbolic import SymbolicRobot
from pipeline.stage_api import StageContext


def nominal_robot(ctx: StageContext) -> RobotModel:
    """The robot as loaded from its files (structure of the base parameters); the context's robot
    when its files cannot be read."""
    try:
        return RobotModel.load(resolve_robot_dir(ctx.run))
    except PipelineError:
        return ctx.robot


def regressors(ctx: StageContext, cfg: Config) -> Regressors:
    """The regressor of the current model (calibrated kinematics when the run has a calibration),
    the joints the fit uses, and the structural base set decided on the nominal robot (:mod:`.base_set`)."""
    robot = ctx.robot
    act = robot.actuation
    user_data = bool(cfg.data_file)
    # a record's torques are motor-side through the gear matrix, unless measured on the link side
    coupled = cfg.actuator_coupling == "gear" or (cfg.actuator_coupling == "auto" and user_data
                                                  and act.torque_side == "motor")
    K = act.gear_matrix if coupled else np.eye(robot.nq)
    rec = load_user_record(cfg, robot) if user_data else None  # before any long computation
    # joints whose torques the fit uses: the named ones, else those whose column carries a signal
    sel = select_joints(cfg.joints, [str(n) for n in robot.model.names[1:]], {} if rec is None else rec.unmeasured)
    rows = None if sel.all_used else sel.used
    reg = RegressorModel(robot.model, K, act.coulomb_smoothing_rad_s, rows)
    nominal = nominal_robot(ctx)
    reg_nominal = RegressorModel(nominal.model, K, act.coulomb_smoothing_rad_s, rows)
    # Structural base set, decided on the nominal model (the design criterion's set); the current
    # (calibrated) model keeps the same set with its own combinations (:mod:`.base_set`)
    base_design, base = structural_base_parameters(reg_nominal, reg, ctx.rng, cfg.base_samples, cfg.base_tolerance,
                                                   robot.limits.lower_rad, robot.limits.upper_rad)
    return Regressors(coupled, rec, sel, reg, base_design, base)


def excite_and_measure(ctx: StageContext, cfg: Config, regs: Regressors, timings: dict[str, float]) -> Measured:
    """The user's record processed (no excitation, nothing simulated), or the optimal excitation
    (:mod:`.design`) run on the hidden robot and processed (:mod:`.measure`); timed
    (``timings["excitation_s"]``, ``timings["data_s"]``)."""
    t1 = time.perf_counter()
    if regs.record is not None:  # the user's record: no excitation to design, nothing simulated
        data = meas_mod.process_record(regs.record, regs.reg, cfg.data_cutoff_hz, cfg.data_decimation,
                                       DATA_BORDER_SAMPLES)
        unit = record_effort_unit(ctx.robot, cfg, regs, data)
        timings["data_s"] = time.perf_counter() - t1
        return Measured(scaled(data, unit.scale_Nm_per_unit), str(cfg.data_file), effort_unit=unit)
    robot, ex = ctx.robot, cfg.excitation
    limits = fourier.ExcitationLimits.from_robot(
        robot, ex.position_margin, ex.velocity_margin, ex.acceleration_margin, ex.torque_margin,
        ex.floor_clearance_m, ex.self_clearance_m, ex.max_tcp_speed_m_s, ex.max_tcp_acceleration_m_s2)
    sym = SymbolicRobot(robot)

    def design() -> design_mod.ExcitationResult:
        return design_mod.optimize_excitation(
            robot, sym, regs.reg, regs.base_design, limits, ctx.rng, harmonics=ex.harmonics,
            base_frequency_hz=ex.base_frequency_hz, n_samples=ex.n_samples, n_starts=ex.n_starts,
            n_random=ex.n_random, max_iter=ex.max_iter, criterion=ex.criterion, n_check=ex.n_check,
            progress=ctx.progress, softness=ex.cond_softness, objective_change_tol=ex.objective_change_tol)

    exc = design()
    if exc.cond_optimized > cfg.max_cond_base_regressor_data and shrink_base_set(regs, exc, cfg):
        exc = design()                  # the rest optimised
    timings["excitation_s"] = time.perf_counter() - t1
    traj = exc.trajectory
    if not exc.feasibility.feasible:
        raise InfeasibleError(None, "identification.excitation",
                              f"the excitation violates the limits: {exc.feasibility.to_dict()}")
    t1 = time.perf_counter()
    sim = meas_mod.simulate_excitation(ctx.real, traj, cfg.periods, cfg.sample_time_s, ctx.rng)
    n_per = int(round(traj.period_s / cfg.sample_time_s))
    cutoff = cfg.state_cutoff_factor * ex.harmonics * ex.base_frequency_hz
    data = meas_mod.process_periodic(sim, regs.reg, n_per, cutoff, cfg.decimation)
    stiction = None
    if ctx.real is not None and ctx.real.dry_friction_sticks:   # held joints: out of the fits (without_stiction_band)
        data, stiction = meas_mod.without_stiction_band(data, float(np.max(regs.reg.joint_coulomb_width_rad_s)))
    timings["data_s"] = time.perf_counter() - t1
    return Measured(data, "simulation (ideal tracking of the hidden robot)", exc, limits, traj, stiction)


def record_effort_unit(robot: RobotModel, cfg: Config, regs: Regressors, data: meas_mod.ProcessedData) -> EffortUnit:
    """What the record's efforts are, against the nominal model's rigid-body torques (URDF inertias and the
    stated rotor inertia; :mod:`.effort_unit`), and the scale to joint torques, on the measured joints."""
    drive = predicted_drive_values(robot.actuation, robot.spec.assumed)
    zeros = np.zeros(robot.nq)
    p_rigid = standard_parameters(robot.model, drive["rotor_inertia_kgm2"], zeros, zeros)
    setting = cfg.effort_scale
    if isinstance(setting, list):
        setting = [float(setting[j]) for j in regs.used]
    placeholder_masses = any(placeholder_kind(line) == "inertials" for line in robot.assumptions)
    return read_effort_unit(data, p_rigid, regs.reg.n_parameters - 4 * robot.nq, robot.nq, setting,
                            np.asarray(robot.actuation.gear_ratio, float)[regs.used], placeholder_masses)


def shrink_base_set(regs: Regressors, exc: design_mod.ExcitationResult, cfg: Config) -> bool:
    """The base parameters that the best excitation within the limits cannot excite: with the full
    structural set its base regressor on the design's samples has ``cond`` above
    ``identification.max_cond_base_regressor_data``, so the fit would be refused. The columns over
    the bound (:func:`.base_set.columns_over_condition`, target the bound over
    :data:`.base_set.DESIGN_COND_MARGIN`) leave the set, each replaced by its least-squares
    combination of the kept ones on those samples (:func:`.base_set.without_columns`), for the nominal
    set and the current model's alike; ``regs`` is updated and names them (``regs.dropped``). False
    when nothing would be left out."""
    traj = exc.trajectory
    Y = regs.reg.stacked(*traj.evaluate(traj.sample_times(exc.n_samples)))
    drop = columns_over_condition(regs.base_design.base_regressor(Y), cfg.max_cond_base_regressor_data
                                  / DESIGN_COND_MARGIN)
    if not len(drop) or len(drop) == regs.base_design.n_base:
        return False
    regs.dropped = [regs.base_design.names[i] for i in drop]
    regs.dropped_cond = exc.cond_optimized
    regs.base_design = without_columns(regs.base_design, drop, Y)
    regs.base = without_columns(regs.base, drop, Y)
    return True


def choose_record_coulomb_widths(cfg: Config, regs: Regressors, measured: Measured, timings: dict[str, float]) -> None:
    """A user's record with ``coulomb_width: auto``: the Coulomb smoothing width of every joint chosen on its
    first ``data_train_fraction`` (:func:`.coulomb_width.choose_widths`), set on ``regs.reg`` and in
    ``measured.data``'s regressor, and kept as ``measured.coulomb_widths``; timed
    (``timings["coulomb_width_s"]``). Nothing for a simulated experiment or ``coulomb_width: robot``."""
    if regs.record is None or cfg.coulomb_width != "auto":
        return
    t1 = time.perf_counter()
    K = regs.reg.gear_matrix
    diagonal = np.allclose(K, np.diag(np.diag(K)))      # the load-dependent candidate's condition (.fit)
    widths = choose_widths(measured.fit_data, regs.reg, regs.base.base_regressor,   # dwell rows left out
                           int(cfg.data_train_fraction * measured.data.n_samples),
                           offset_mask(regs, regs.reg.nv) if diagonal else None)
    regs.reg.coulomb_width_rad_s = widths.chosen_rad_s
    measured.data = with_widths(measured.data, regs.reg, widths.chosen_rad_s)
    measured.coulomb_widths = widths
    timings["coulomb_width_s"] = time.perf_counter() - t1


def leave_out_dwells(cfg: Config, regs: Regressors, measured: Measured) -> None:
    """A user's record without ``fit_dwells``: the rows at which a joint dwells (:mod:`.dwell`), left out of
    the fits (``measured.dwells``; None when there are none). Nothing for a simulated experiment."""
    if regs.record is None or cfg.fit_dwells:
        return
    dwells = Dwells.of(measured.data)
    measured.dwells = dwells if dwells.rows.any() else None


def take_off_record_terms(robot: RobotModel, cfg: Config, regs: Regressors, measured: Measured,
                          timings: dict[str, float]) -> FrictionTerms | None:
    """A user's record: the friction and actuation terms beyond viscous + Coulomb friction chosen on its
    first ``data_train_fraction`` and taken off its torques before the fits (:mod:`.friction_terms`;
    ``measured.data`` replaced), timed (``timings["friction_terms_s"]``). None for a simulated experiment."""
    if regs.record is None:
        return None
    t1 = time.perf_counter()
    measured.data, terms = record_terms(measured.data, regs.base.base_regressor, cfg.data_train_fraction,
                                        regs.reg.row_coulomb_width_rad_s, robot.limits.effort_Nm[regs.used])
    timings["friction_terms_s"] = time.perf_counter() - t1
    return terms
