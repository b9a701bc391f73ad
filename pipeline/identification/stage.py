"""Stage ``identification``: optimal Fourier excitation, measurement, estimation, validation,
and the real Stäubli TX40 record (paper ``004_abbe750b8bbcc3aa.txt`` §4).

:func:`run` sequences the steps, each in its own module; what they hand each other is in
:mod:`.outcome`:

1. regressors (:func:`.experiment.regressors`): the regressor of the current model (calibrated
   kinematics when the run has a calibration), the joints the fit uses (:mod:`.joints`) and the
   structural base set, decided on the nominal robot and kept for the current one (:mod:`.base_set`);
2. data (:func:`.experiment.excite_and_measure`): the Fourier trajectory minimising the condition
   number of the base regressor under limits, torques, floor and self-collision (CasADi/IPOPT,
   :mod:`.design`), never worse than the best of 20 random feasible ones (fallback, stated in
   summary and report), run on the hidden robot for ``periods`` periods; or the user's record
   (``data_file``): no excitation, the hidden robot (``ctx.real``) never used. An excitation whose
   base regressor stays above the condition-number bound leaves the base parameters over it out of
   the design, which then optimises the rest (:func:`.experiment.shrink_base_set`; named in the
   report). Period averaging, zero-phase filtering, differentiation, block decimation (:mod:`.measure`);
   a record's rows at which a joint is at rest, left out of the fits (:mod:`.dwell`), its Coulomb
   smoothing width per joint, chosen on its training part (:mod:`.coulomb_width`), and its friction
   and actuation terms beyond viscous + Coulomb (:mod:`.friction_terms`);
3. fits (:func:`.fit.fit_models`): the data must excite the model (:mod:`.gates`); OLS, Gautier's
   WLS and the physically consistent fit (log-Cholesky, IPOPT); with ``friction_model: stribeck``
   a Stribeck term first (:mod:`.friction`); the candidate with load-dependent Coulomb friction;
4. validation (:mod:`.validate`): measured vs predicted torques on the run's ISO 9283 path (a
   random Fourier trajectory, the report says why, when that path cannot be used) or on the
   record's held-out tail (fit on its first ``data_train_fraction``, noise sigma from the WLS
   residuals); the friction model that predicts them best is handed on
   (:func:`.validate.choose_friction_model`); base-parameter sigmas from the HAC sandwich
   (:func:`.fit.base_covariance`); the robot handed on keeps robot.yaml's rotor inertia on the joints whose
   torques show none (:func:`.handed_on.keep_unseen_rotor_inertia`);
5. the TX40 record, only for the TX40 or when asked (:func:`.tx40.tx40_record`);
6. outputs (:mod:`.report`) and quality gates (:func:`.gates.add_result_gates`): condition number
   vs design, validation RMS vs noise, predicted torques vs limits ->
   :class:`~pipeline.core.errors.QualityGateError` unless ``--accept-poor``.

:func:`check` reads and checks the configuration and the user's record before any stage runs.
"""

from __future__ import annotations

import time

from pipeline.core.blas import single_thread_blas
from pipeline.core.errors import ConfigError, PipelineError
from pipeline.identification import report
from pipeline.identification.config import Config, ExcitationConfig
from pipeline.identification.experiment import (
    choose_record_coulomb_widths,
    excite_and_measure,
    leave_out_dwells,
    regressors,
    take_off_record_terms,
)
from pipeline.identification.fit import base_covariance, fit_models
from pipeline.identification.gates import add_result_gates
from pipeline.identification.handed_on import handed_on_robot, keep_unseen_rotor_inertia
from pipeline.identification.joints import select_joints
from pipeline.identification.outcome import Fits, Measured, Outcome, Regressors, Validation, identified_robot
from pipeline.identification.record import load_user_record
from pipeline.identification.tx40 import check_tx40_config, tx40_record, tx40_wanted
from pipeline.identification.validate import (
    choose_friction_model,
    record_term_scores,
    scored_against_truth,
    validate_on_path,
    validate_on_record,
)
from pipeline.quality import QualityGates
from pipeline.robot.model import RobotModel
from pipeline.stage_api import StageContext, StageResult

NAME = "identification"
DEPENDS: tuple[str, ...] = ("model", "calibration")
#: provenance (pipeline.run.stage_plan): the field naming a recorded file, else what is simulated
RECORDED_INPUT = "data_file"
SIMULATES = "joint torques of the hidden robot"
warm_up = None                       # its compiled code is built where it is used
#: settings of other sections this stage reads (the runner adds them to its inputs hash): the
#: validation path is the run's EN ISO 9283 path (robot ``run_defaults`` included)
CONFIG_READS: tuple[str, ...] = ("control.iso", "control.ik_seeds_deg", "control.ik_tolerance_m",
                                  "control.path_frame")


def check(config: Config, robot: RobotModel) -> None:
    """Called by the runner before any stage runs or anything is written: the configuration
    (robot-dependent ranges), the user's record (``data_file``) if any and the TX40 record's
    folder, so a bad value or file is reported before calibration runs."""
    cfg = config
    cfg.validate(None)
    n_params = 10 * (robot.model.njoints - 1) + 4 * robot.nq   # standard parameters (regressor columns)
    nq = robot.nq
    if cfg.base_samples * nq < n_params:
        raise ConfigError(None, "identification.base_samples",
                          f"{cfg.base_samples} random samples give {cfg.base_samples * nq} regressor rows for the "
                          f"{n_params} standard parameters of {robot.name}; need at least {-(-n_params // nq)} "
                          "(default 300)")
    if isinstance(cfg.effort_scale, list) and len(cfg.effort_scale) != robot.nq:
        raise ConfigError(None, "identification.effort_scale",
                          f"{len(cfg.effort_scale)} values for the {robot.nq} joints of {robot.name} (joint-side N·m "
                          "per logged effort unit, one per joint in the model's order)")
    rec = load_user_record(cfg, robot) if cfg.data_file else None
    select_joints(cfg.joints, [str(n) for n in robot.model.names[1:]], {} if rec is None else rec.unmeasured)
    if rec is None:
        ex = cfg.excitation
        n_per = int(round(1.0 / (ex.base_frequency_hz * cfg.sample_time_s)))
        m = n_per // cfg.decimation
        if m <= n_params:  # the fits need more samples than standard parameters
            raise ConfigError(None, "identification.decimation",
                              f"one period of {n_per} samples (1 / excitation.base_frequency_hz / sample_time_s) "
                              f"decimated by {cfg.decimation} leaves {m} samples, not more than the {n_params} "
                              f"standard parameters of {robot.name}; decimation must be at most "
                              f"{max(n_per // (n_params + 1), 1)}")
    if tx40_wanted(cfg, robot):
        check_tx40_config(cfg.tx40)


def run(ctx: StageContext) -> StageResult:
    with single_thread_blas():
        return _run(ctx)


def _run(ctx: StageContext) -> StageResult:
    cfg: Config = ctx.config
    cfg.validate(getattr(ctx.run, "source", None))
    if not cfg.data_file and ctx.real is None:
        raise PipelineError(None, "identification", "no hidden robot to measure and no data_file given")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    regs = regressors(ctx, cfg)
    timings["base_parameters_s"] = time.perf_counter() - t0
    measured = excite_and_measure(ctx, cfg, regs, timings)
    leave_out_dwells(cfg, regs, measured)
    choose_record_coulomb_widths(cfg, regs, measured, timings)
    terms = take_off_record_terms(ctx.robot, cfg, regs, measured, timings)
    fits = fit_models(ctx.robot, cfg, regs, measured, timings)
    t1 = time.perf_counter()
    val = (validate_on_record(ctx.robot, cfg, regs, measured, fits) if regs.record is not None
           else validate_on_path(ctx, cfg, regs, measured, fits))
    friction = choose_friction_model(ctx.robot, regs, fits, val) | record_term_scores(cfg, regs, measured, fits,
                                                                                      val, terms)
    hac, white_sigma = base_covariance(regs, measured, fits)
    keep_unseen_rotor_inertia(cfg, regs, fits)
    new_robot = handed_on_robot(ctx.robot, regs, fits)
    timings["validation_s"] = time.perf_counter() - t1
    truth = scored_against_truth(ctx, cfg, regs, fits)
    tx = tx40_record(ctx.robot, cfg, timings)
    timings["total_s"] = time.perf_counter() - t0
    outcome = Outcome(regs, measured, fits, val, friction, hac, white_sigma, truth, tx, timings)
    result = report.stage_result(cfg, outcome, new_robot)
    return gated(ctx, cfg, regs, measured, fits, val, result)


def gated(ctx: StageContext, cfg: Config, regs: Regressors, measured: Measured, fits: Fits, val: Validation,
          result: StageResult) -> StageResult:
    """The quality gates on the finished result (:func:`.gates.add_result_gates`); a failed one raises
    :class:`~pipeline.core.errors.QualityGateError` with the result on it, unless ``--accept-poor``."""
    gates = QualityGates(NAME, accept_poor=bool(getattr(ctx.run, "accept_poor", False)))
    add_result_gates(gates, cfg, fits.cond_data, None if measured.excitation is None
                     else measured.excitation.cond_optimized, val.rms_over_noise, val.pred_phys,
                     ctx.robot.limits.effort_Nm[regs.used], fits.phys.status, regs.used + 1)
    return gates.finish(result)


__all__ = ["NAME", "DEPENDS", "CONFIG_READS", "RECORDED_INPUT", "SIMULATES", "Config", "ExcitationConfig", "check",
           "warm_up", "run", "identified_robot", "tx40_wanted"]
