"""``calibration.parameters: auto``: the error model of a measurement file chosen by k-fold
cross-validation and the one-standard-error rule.

Candidates (:data:`CANDIDATES`): the joint zero offsets, the zero offsets and the joint axes'
directions (the rotational errors of the joint placements, link lengths as stated), the geometric
errors, geometric errors and joint compliances (the elastostatic model), each alone and with the
non-geometric residual map (:mod:`pipeline.calibration.residual_map`, a Gaussian process over joint
space fitted to the training folds' residuals). The measurement set-up (tracker pose, reflector or marker offset, and
a 6-D marker's rotation) is estimated in every candidate.

The poses are split into ``k`` folds grouped in joint space
(:func:`pipeline.calibration.crossval.spatial_folds`: k-means clusters dealt to the folds; the three
fitted rows of a 6-D pose stay together), so a held-out fold lies where the training folds did not
measure and a model that only interpolates (the residual map above all) is scored where it must
extrapolate; each fold is predicted by the robust fit of the other folds
(:func:`pipeline.calibration.robust.robust_estimate`: gross errors are rejected inside the training
folds only) and every held-out pose is scored: the distance
between the read and predicted marker origin, and for 6-D readings the angle between the read and
predicted marker frame. A gross-error screen leaves poses out of every candidate's score, at most
``max_outlier_fraction`` of them (:mod:`pipeline.calibration.selection_scores`). The
cross-validation error of a candidate is the mean squared error over
all held-out poses; its standard error is the spread of the per-fold mean squared errors,
``SE = std(MSE_f) / sqrt(k)`` (Hastie, Tibshirani & Friedman, *The Elements of Statistical
Learning*, 2nd ed., Springer 2009, §7.10).

One-standard-error rule (ibid. §7.10, Fig. 7.9): among the candidates whose position error is
within one standard error of the smallest, the simplest is chosen: fewest identifiable parameters,
then without the map. A richer model must beat a simpler one by more than the noise of the
cross-validation estimate itself. A 6-D record scores two errors, and a candidate is near the best
when it is within one standard error of the smallest on each: its excess ``z = max_e (MSE_e(c) -
MSE_e(best_e)) / SE_e(best_e)`` over the position and the orientation error ``e``, each against
the candidate that is best on it, is at most 1. When no candidate is near on both (the one best in
position is far off in orientation, and the reverse), the band widens to the smallest excess any
candidate reaches, ``z <= min_c z(c)``, and the simplest within it is chosen: the rule gives up no
more on either error than the record forces. (Read lexicographically, position first, the rule
would let a model whose orientation error is several standard errors above the best win on
position alone.) For position-only records the excess is the position error's and the rule is
the textbook one.

Noise and weights. Each training fold is fitted with the readings' noise model
(:func:`pipeline.calibration.noise_model.fit_with_noise_model`: sensor + repeatability + a REML
remainder per row group, estimated on the training fold alone), so position and orientation
readings are weighted by the data, not by a data-sheet sigma. For 6-D readings the weight of the
orientation (the marker-point rows) against the position is then chosen by cross-validation
(:func:`orientation_weight`): the marker-point rows' 1-sigma is multiplied by a factor ``kappa``
walked from 1 over :data:`ORIENTATION_SCALES` while the held-out score improves; the score
is ``MSE_pos(kappa) / MSE_pos(1) + MSE_rot(kappa) / MSE_rot(1)`` (both errors count alike, free of
units). The REML variances alone are not the best weights here: a marker-point row repeats its
pose's position error (its reading is the origin plus a lever along the marker axes), a correlation
the row-wise noise model neglects. The factor is chosen on :data:`WEIGHT_SUBSET`.

The weight is chosen twice, for two purposes (nested cross-validation, Varma & Simon 2006, "Bias in
error estimation when using cross-validation for model selection", BMC Bioinformatics 7:91; Cawley
& Talbot 2010, JMLR 11). The final fit's weight is chosen by the cross-validation of the whole
record, and the candidates are compared (the one-standard-error rule) at that weight. The chosen
candidate's held-out figures (:meth:`ModelSelection.cross_validation`, the run's
``cross_validation``) are those of a nested cross-validation: each outer fold's weight is chosen by
a cross-validation of that fold's training poses alone (:func:`nested_orientation_weights`, inner
folds grouped in joint space as the outer ones) and the fold's fit uses it, so no held-out pose
takes part in choosing the weight of the fit that predicts it; a weight chosen on the folds it is
then scored on would report the minimum of a noisy curve, an optimistic figure. (The position rows'
weight, their REML remainder, is estimated on each training fold alone already.) The choice among
the candidates is not nested: the reported figure is that of the chosen model.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TypeVar

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.calibration import measure as ms
from pipeline.calibration import subsets
from pipeline.calibration.config import Config
from pipeline.calibration.crossval import screen_capped, spatial_folds
from pipeline.calibration.elastostatic import measurement_model
from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.estimate import Estimate
from pipeline.calibration.noise_model import NoiseModel, fit_with_noise_model, noise_of_robot
from pipeline.calibration.outcome import CalibrationNotes
from pipeline.calibration.residual_map import fit_residual_map, restart_seed
from pipeline.calibration.selection_scores import (  # noqa: F401 - re-exported (tests, stage)
    Candidate,
    CandidateScore,
    ModelSelection,
    gross_heldout_poses,
    one_standard_error,
    standard_errors_above_best,
)
from pipeline.calibration.validate import predicted_covariance
from pipeline.core.errors import PipelineError
from pipeline.robot.model import RobotModel
from pipeline.robot.residual_map import ResidualMap

#: the named parameter subsets compared (pipeline.calibration.subsets), simplest first
SUBSETS = ("joint_offsets", "joint_axes", "geometric", "all")
#: folds of the model selection when calibration.cross_validation_folds is 0
DEFAULT_FOLDS = 5
#: factors on the marker-point rows' 1-sigma tried by the orientation weight (module docstring)
ORIENTATION_SCALES = (0.25, 0.5, 1.0, 2.0, 4.0)
#: the parameter subset whose cross-validation chooses the orientation weight (else the first that fits)
WEIGHT_SUBSET = "geometric"
#: the robust fit's settings when the caller gives none (calibration config defaults)
ROBUST_DEFAULTS = {"loss": "huber", "confidence": 0.999, "max_fraction": 0.1}
#: evaluations of the measurement functions per training reading and fold (LM steps, the robust
#: refit's steps, the noise model's rounds), a lower bound of a candidate's average over its folds:
#: 95 to 406 measured on the UR10 6-D and RX130L records. Announced to each candidate's measurement
#: model before the scoring, so that its compiled code is built as soon as this known use pays for it.
EVALUATIONS_PER_READING = 60


CANDIDATES = tuple(Candidate(p, m) for p in SUBSETS for m in (False, True))
T = TypeVar("T")

def _origins(mm: MeasurementModel, n: int) -> np.ndarray | None:
    return np.zeros((n, 3)) if mm.marker_points else None


def heldout_errors(mm: MeasurementModel, est: Estimate, meas: ms.Measurements, rows: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Tracker-frame position errors ``(m, 3)`` of the marker origin at the poses ``rows``, the
    base-frame rotation ``R_tb`` and, for 6-D readings, the orientation errors ``(m,)`` (rad)."""
    Q = meas.Q[rows]
    mounted = None if meas.payload_mounted is None else meas.payload_mounted[rows]
    e = meas.Y[rows] - mm.predict(Q, est.x, est.registration, mounted, _origins(mm, len(rows)))
    R_tb = est.transform_tracker_to_base.rotation
    if meas.rotvec is None:
        return e, R_tb, None
    _, R_refl = mm.base_positions(Q, est.x, mounted, _origins(mm, len(rows)))
    R_pred = np.einsum("ji,njk->nik", R_tb, R_refl)
    R_meas = Rotation.from_rotvec(meas.rotvec[rows]).as_matrix()
    ang = np.linalg.norm(Rotation.from_matrix(np.einsum("nji,njk->nik", R_pred, R_meas)).as_rotvec(), axis=1)
    return e, R_tb, ang


def map_noise_floor_m(noise: NoiseModel, sensor_sigma_m: np.ndarray) -> float:
    """The residual map's noise floor: the readings' known noise (sensor and repeatability, no
    remainder), RMS over the readings (:func:`pipeline.calibration.residual_map.fit_residual_map`)."""
    known = replace(noise.known(), orientation_scale=1.0).total(np.asarray(sensor_sigma_m, float))
    return float(np.sqrt(np.mean(known ** 2))) if known.size else 0.0


def score_subset(mm: MeasurementModel, basis: np.ndarray, meas: ms.Measurements, orientation_sigma_rad: float,
                 fold_of_pose: np.ndarray, max_iterations: int, rng: np.random.Generator | None,
                 robust: dict | None = None, noise: NoiseModel | None = None,
                 fold_scales: np.ndarray | None = None) -> tuple[CandidateScore, Callable[[], CandidateScore]]:
    """Held-out errors of one parameter subset without and with the residual map, on the folds
    ``fold_of_pose`` (n,); each training fold
    is fitted with the noise model ``noise`` (its REML remainder estimated on the training fold,
    :func:`pipeline.calibration.noise_model.fit_with_noise_model`; ``robust``: the robust fit's loss,
    confidence and max_fraction), so gross errors are rejected inside the training folds only and
    every held-out pose is scored, with its predicted error under the fold's fit and noise model.
    ``fold_scales`` (one per fold): the orientation weight of each fold's fit (chosen on that fold's
    training poses, :func:`nested_orientation_weights`), else ``noise.orientation_scale`` in every fold.
    The score with the map is computed when its callable is called
    (the seeds of its fits are drawn from ``rng`` fold by fold here: an orientation weight that is
    not chosen skips the maps and leaves every later draw as it was; ``rng`` None: no map, the
    callable gives the plain score)."""
    robust = ROBUST_DEFAULTS | (robust or {})
    noise = noise or NoiseModel()
    n = len(meas)
    six_d = meas.rotvec is not None and mm.marker_points
    rec = ms.expand_orientation(meas, orientation_sigma_rad) if six_d else meas
    pose = rec.pose_index if rec.pose_index is not None else np.arange(len(rec))
    fold_of_pose = np.asarray(fold_of_pose, int)
    e_plain, var, before, noise_var = (np.full(n, np.nan) for _ in range(4))
    e_rot = np.full(n, np.nan) if six_d else None
    maps: list[tuple[Estimate, np.ndarray, int, np.ndarray, np.ndarray]] = []
    warm: np.ndarray | None = None      # the previous fold's fit starts the next (warm start)
    for f in range(int(fold_of_pose.max()) + 1 if n else 0):
        train = fold_of_pose[pose] != f
        test = np.flatnonzero(fold_of_pose == f)
        train_poses = np.flatnonzero(fold_of_pose != f)
        if not len(test):
            continue

        def part(a: np.ndarray | None, m: np.ndarray = train) -> np.ndarray | None:
            return None if a is None else a[m]

        fold = ms.Measurements(rec.Q[train], rec.Y[train], rec.sigma_m[train], f"fold {f + 1}",
                               payload_mounted=part(rec.payload_mounted), offset_m=part(rec.offset_m))
        weighted = noise if fold_scales is None else replace(noise, orientation_scale=float(fold_scales[f]))
        try:
            est, _, fold_noise = fit_with_noise_model(mm, fold, basis, weighted, None, max_iterations=max_iterations,
                                                      theta0=warm, **robust)
        except PipelineError:
            continue   # this fold's training poses do not excite every parameter
        warm = est.theta
        e, R_tb, ang = heldout_errors(mm, est, meas, test)
        e_plain[test] = np.linalg.norm(e, axis=1)
        sigma = replace(fold_noise, orientation_scale=1.0).total(meas.sigma_m[test])
        noise_var[test] = sigma ** 2
        cov, _ = predicted_covariance(mm, est, meas.Q[test], sigma)
        var[test] = np.trace(cov, axis1=1, axis2=2)
        before[test] = np.linalg.norm(meas.Y[test] - mm.predict(meas.Q[test], np.zeros(mm.n), est.registration,
                                                                None, _origins(mm, len(test))), axis=1)
        if e_rot is not None and ang is not None:
            e_rot[test] = ang
        if rng is not None:
            maps.append((est, train_poses, restart_seed(rng), test, e))
    p = basis.shape[1]
    floor = map_noise_floor_m(noise, meas.sigma_m)
    plain = CandidateScore(Candidate("", False), p, fold_of_pose, e_plain, e_rot, None, var, before)

    def mapped() -> CandidateScore:
        if rng is None:
            return plain
        e_map, var_map = np.full(n, np.nan), var.copy()
        for est, train_poses, seed, test, e in maps:
            e_train, R_tb, _ = heldout_errors(mm, est, meas, train_poses)
            gp = fit_residual_map(meas.Q[train_poses], e_train @ R_tb.T, seed, noise_floor_m=floor)
            mean, reading = gp.predict_reading(meas.Q[test])   # its reading variance in place of the noise
            e_map[test] = np.linalg.norm(e - mean @ R_tb, axis=1)
            var_map[test] += 3.0 * (reading ** 2 - noise_var[test])
        return CandidateScore(Candidate("", True), p, fold_of_pose, e_map, e_rot, None, var_map, before)

    return plain, mapped


def select_model(meas: ms.Measurements, setup: Callable[[str], tuple[MeasurementModel, np.ndarray]],
                 orientation_sigma_rad: float, folds: int, max_iterations: int,
                 rng: np.random.Generator, robust: dict | None = None, noise: NoiseModel | None = None
                 ) -> ModelSelection:
    """Score every candidate (module docstring) and choose one. ``setup(parameters)`` gives the
    measurement model and identifiable basis of a parameter subset."""
    folds = min(folds, len(meas))
    fold_of_pose = spatial_folds(meas.Q, folds)
    scores: list[CandidateScore] = []
    notes: list[str] = []
    noise = noise or NoiseModel()
    models: dict[str, tuple[MeasurementModel, np.ndarray]] = {}
    for subset in SUBSETS:
        try:
            models[subset] = setup(subset)
        except PipelineError as exc:
            notes.append(f"{subset}: not fitted ({exc})")
    for mm, _ in models.values():     # a model with compliances fits its rigid part first (robust.py step 0)
        readings = len(ms.expand_orientation(meas, orientation_sigma_rad)) if mm.marker_points else len(meas)
        mm.expect_readings((2 if mm.compliance else 1) * (folds - 1) * readings * EVALUATIONS_PER_READING)

    def scored_with(subset: str, kappa: float, fold_scales: np.ndarray | None = None
                    ) -> tuple[CandidateScore, Callable[[], CandidateScore]]:
        mm, basis = models[subset]
        return score_subset(mm, basis, meas, orientation_sigma_rad, fold_of_pose, max_iterations, rng, robust,
                            replace(noise, orientation_scale=kappa), fold_scales)

    kappa = 1.0
    tried: list[tuple[float, float, float]] = []
    done: dict[float, tuple[CandidateScore, Callable[[], CandidateScore]]] = {}
    fold_scales: np.ndarray | None = None
    weight_subset = WEIGHT_SUBSET if WEIGHT_SUBSET in models else next(iter(models), "")
    if meas.rotvec is not None and weight_subset and models[weight_subset][0].marker_points:
        kappa, done = orientation_weight(lambda k: scored_with(weight_subset, k))    # the final fit's weight
        tried = [(k, *rms_errors(pair[0])) for k, pair in sorted(done.items())]
        mm_w, basis_w = models[weight_subset]
        fold_scales = nested_orientation_weights(
            meas, fold_of_pose, folds,
            lambda sub, inner, k: score_subset(mm_w, basis_w, sub, orientation_sigma_rad, inner, max_iterations,
                                               None, robust, replace(noise, orientation_scale=k))[0])
    for subset in models:     # the candidates compared at the final fit's weight
        plain, with_map = done[kappa] if subset == weight_subset and kappa in done else scored_with(subset, kappa)
        mapped = with_map()
        plain.candidate, mapped.candidate = Candidate(subset, False), Candidate(subset, True)
        scores += [plain, mapped]
    settings = ROBUST_DEFAULTS | (robust or {})
    max_fraction = float(settings["max_fraction"])
    gross = gross_heldout_poses(scores, float(settings["confidence"]))
    if screen_capped(gross, max_fraction):
        notes.append(f"{int(gross.sum())} of {len(gross)} held-out poses beyond the chi-square bound of the best "
                     f"candidate's robust error scale, more than calibration.max_outlier_fraction "
                     f"({max_fraction:g}) allows: none left out (the model, not the readings, is off)")
    elif gross.any():
        for score in scores:
            score.scored = ~gross
        notes.append(f"{int(gross.sum())} held-out pose(s) beyond the chi-square bound of the best candidate's "
                     "robust error scale (gross errors) left out of every candidate's score")
    chosen = one_standard_error(scores)
    sel = ModelSelection(folds, scores, chosen, notes, kappa, tried, gross, max_fraction)
    if fold_scales is not None:    # the chosen model's held-out figures, each fold with its own fold's weight
        plain, with_map = scored_with(chosen.parameters, kappa, fold_scales)
        held = with_map() if chosen.residual_map else plain
        held.candidate = chosen
        nested_gross = gross_heldout_poses([held], float(settings["confidence"]))
        sel.fold_orientation_scales = [float(k) for k in fold_scales]
        sel.nested = held
        sel.nested_gross = np.zeros_like(nested_gross) if screen_capped(nested_gross, max_fraction) else nested_gross
    return sel


def rms_errors(score: CandidateScore) -> tuple[float, float]:
    """CV RMS position (m) and orientation (rad) error of a 6-D score over its poses (NaN: a fold failed)."""
    rot = score.orientation_error_rad if score.orientation_error_rad is not None else np.full(1, np.nan)
    return float(np.sqrt(np.mean(score.position_error_m ** 2))), float(np.sqrt(np.mean(rot ** 2)))


def orientation_weight(scored: Callable[[float], tuple[CandidateScore, T]]
                       ) -> tuple[float, dict[float, tuple[CandidateScore, T]]]:
    """The factor ``kappa`` on the marker-point rows' 1-sigma (module docstring) and the scores of
    every factor tried; ``scored(kappa)`` gives the plain score of the weight subset (and the mapped
    one, or what gives it: only the plain one is compared). From
    1 the walk goes down :data:`ORIENTATION_SCALES` (heavier orientation) while the score
    ``MSE_pos / MSE_pos(1) + MSE_rot / MSE_rot(1)`` decreases, else up while it decreases."""
    done = {1.0: scored(1.0)}
    ref_p, ref_r = rms_errors(done[1.0][0])
    if not (np.isfinite(ref_p) and np.isfinite(ref_r)) or ref_p <= 0 or ref_r <= 0:
        return 1.0, done

    def value(k: float) -> float:
        if k not in done:
            done[k] = scored(k)
        p, r = rms_errors(done[k][0])
        v = (p / ref_p) ** 2 + (r / ref_r) ** 2
        return v if np.isfinite(v) else np.inf

    i0 = ORIENTATION_SCALES.index(1.0)
    best_i, best_v = i0, value(1.0)
    for step in (-1, 1):
        i = i0 + step
        while 0 <= i < len(ORIENTATION_SCALES):
            v = value(ORIENTATION_SCALES[i])
            if v >= best_v:
                break
            best_i, best_v = i, v
            i += step
        if best_i != i0:
            break
    return ORIENTATION_SCALES[best_i], done


def pose_subset(meas: ms.Measurements, poses: np.ndarray) -> ms.Measurements:
    """The readings of ``meas`` at the poses (rows) ``poses``, a record of its own."""
    def part(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[poses]

    return ms.Measurements(meas.Q[poses], meas.Y[poses], meas.sigma_m[poses], meas.source, part(meas.rotvec),
                           len(poses), payload_mounted=part(meas.payload_mounted), lines=part(meas.lines))


def nested_orientation_weights(meas: ms.Measurements, fold_of_pose: np.ndarray, folds: int,
                               scored: Callable[[ms.Measurements, np.ndarray, float], CandidateScore]) -> np.ndarray:
    """``(folds,)`` orientation weight of each outer fold, chosen by :func:`orientation_weight` on a
    cross-validation of that fold's training poses alone (nested cross-validation: the held-out
    fold neither fits nor chooses the weight it is scored with, Cawley & Talbot 2010, "On
    over-fitting in model selection and subsequent selection bias in performance evaluation",
    JMLR 11; Varma & Simon 2006, BMC Bioinformatics 7:91). The inner folds are
    :func:`pipeline.calibration.crossval.spatial_folds` of the training poses, as many as the outer
    ones (at most one per pose); ``scored(record, inner_fold_of_pose, kappa)`` scores the weight subset."""
    fold_of_pose = np.asarray(fold_of_pose, int)
    scales = np.ones(int(fold_of_pose.max()) + 1 if fold_of_pose.size else 0)
    for f in range(len(scales)):
        train = np.flatnonzero(fold_of_pose != f)
        if not len(train) or len(train) == len(fold_of_pose):
            continue
        sub = pose_subset(meas, train)
        inner = spatial_folds(sub.Q, min(folds, len(sub)))

        def inner_score(kappa: float, sub: ms.Measurements = sub, inner: np.ndarray = inner
                        ) -> tuple[CandidateScore, None]:
            return scored(sub, inner, kappa), None

        scales[f] = orientation_weight(inner_score)[0]
    return scales


def choose_parameters(robot: RobotModel, cfg: Config, user: ms.Measurements | None, six_d: bool,
                      rng: np.random.Generator, identify: Callable) -> tuple[Config, ModelSelection | None]:
    """``cfg`` with the chosen parameter subset when ``parameters`` is auto and there is a
    measurement file ``user`` (else unchanged, no selection); ``identify(robot, mm, cfg, rng)`` gives
    (report, basis) of a subset (:func:`pipeline.calibration.stage.identify_parameter_set`). A chosen
    rigid model drops an upstream gravity model (only the elastostatic model uses it)."""
    if user is None or cfg.parameters != "auto":
        return cfg, None

    def setup(parameters: str) -> tuple[MeasurementModel, np.ndarray]:
        c = replace(cfg, parameters=parameters)
        mm = measurement_model(robot, c, marker_points=six_d)
        return mm, identify(robot, mm, c, rng)[1]

    sel = select_model(user, setup, cfg.orientation_sigma_rad, cfg.cross_validation_folds or DEFAULT_FOLDS,
                       cfg.max_lm_iterations, rng, {"loss": cfg.robust_loss, "confidence": cfg.outlier_confidence,
                                                    "max_fraction": cfg.max_outlier_fraction},
                       noise_of_robot(robot, recorded=True))
    p = sel.chosen.parameters
    return replace(cfg, parameters=p,
                   gravity_model=cfg.gravity_model if subsets.wants_compliance(p) else None), sel


def final_residual_map(sel: ModelSelection | None, mm: MeasurementModel, est: Estimate,
                       user: ms.Measurements | None, rec: ms.Measurements, rejected: np.ndarray,
                       rng: np.random.Generator, noise: NoiseModel | None = None) -> ResidualMap | None:
    """The residual map of the chosen model, fitted to the final fit's residuals at the marker
    origins of the poses the outlier test kept (None: the map was not chosen), its noise floored at
    the known noise of ``noise`` (:func:`map_noise_floor_m`)."""
    if sel is None or user is None or not sel.chosen.residual_map:
        return None
    rows = np.asarray(rejected, int)
    bad = set((rec.pose_index[rows] if rec.pose_index is not None else rows).tolist())
    keep = np.array([i for i in range(len(user)) if i not in bad], int)
    e, R_tb, _ = heldout_errors(mm, est, user, keep)
    floor = map_noise_floor_m(noise, user.sigma_m[keep]) if noise is not None else 0.0
    return fit_residual_map(user.Q[keep], e @ R_tb.T, rng, noise_floor_m=floor)


def stage_entries(notes: CalibrationNotes, parameters: str | list[str]) -> tuple[dict, dict[str, np.ndarray], str]:
    """Summary entries, ``results.npz`` arrays (the residual map handed on) and the report section
    of the model selection, the residual map and the marker rotation kept in an outcome's notes
    (``parameters``: the configured subset; auto without a selection is all)."""
    summary: dict = {"parameters": "all"} if parameters == "auto" else {}
    arrays: dict[str, np.ndarray] = {}
    md = ""
    sel: ModelSelection | None = notes.model_selection
    if sel is not None:
        summary["model_selection"] = sel.as_dict()
        summary["parameters"] = sel.chosen.parameters
        md += sel.markdown()
    rmap: ResidualMap | None = notes.residual_map
    summary["residual_map"] = None
    if rmap is not None:
        arrays.update(rmap.to_arrays())
        _, std = rmap.predict(rmap.inputs_rad)
        reading = float(np.sqrt(np.mean(std ** 2) + rmap.noise_std_m ** 2))
        summary["residual_map"] = {"signal_std_m": rmap.signal_std_m, "length_scale_rad": rmap.length_scale_rad,
                                   "noise_std_m": rmap.noise_std_m, "noise_floor_m": notes.residual_map_floor_m,
                                   "support_radius_rad": rmap.support_radius_rad, "n_poses": int(len(rmap.inputs_rad)),
                                   "posterior_std_at_poses_m": float(np.sqrt(np.mean(std ** 2))),
                                   "reading_std_at_poses_m": reading}
        md += (f"\nResidual map handed on (Gaussian process over joint space, Rasmussen & Williams 2006): signal "
               f"{1e3 * rmap.signal_std_m:.3f} mm, length scale {rmap.length_scale_rad:.3f} rad, noise "
               f"{1e3 * rmap.noise_std_m:.3f} mm (at least the readings' known noise), support radius "
               f"{rmap.support_radius_rad:.3f} rad (the correction fades beyond it); posterior std at the "
               f"calibration poses {1e3 * summary['residual_map']['posterior_std_at_poses_m']:.3f} mm per axis, "
               f"{1e3 * reading:.3f} mm for a reading there.\n")
    rot = notes.marker_rotation_on_flange
    if rot is not None:
        summary["marker_rotation_on_flange_deg"] = float(np.degrees(np.linalg.norm(
            Rotation.from_matrix(rot).as_rotvec())))
        md += (f"\nMarker frame on the flange (6-D readings): turned {summary['marker_rotation_on_flange_deg']:.2f}° "
               "from the flange axes (closed-form rotation average, refined by the fit's tool rotations).\n")
    return summary, arrays, md
