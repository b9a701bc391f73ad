"""``calibration.parameters: auto``: the error model of a measurement file chosen by k-fold
cross-validation and the one-standard-error rule.

Candidates (:data:`CANDIDATES`): the joint zero offsets, the geometric errors, geometric errors and
joint compliances (the elastostatic model), each alone and with the non-geometric residual map
(:mod:`pipeline.calibration.residual_map`, a Gaussian process over joint space fitted to the
training folds' residuals). The measurement set-up (tracker pose, reflector or marker offset, and
a 6-D marker's rotation) is estimated in every candidate.

The poses are split into ``k`` folds in file order modulo ``k`` (the three fitted rows of a 6-D
pose stay together); each fold is predicted by the robust fit of the other folds
(:func:`pipeline.calibration.robust.robust_estimate`: gross errors are rejected inside the training
folds only) and every held-out pose is scored: the distance
between the read and predicted marker origin, and for 6-D readings the angle between the read and
predicted marker frame. The cross-validation error of a candidate is the mean squared error over
all held-out poses; its standard error is the spread of the per-fold mean squared errors,
``SE = std(MSE_f) / sqrt(k)`` (Hastie, Tibshirani & Friedman, *The Elements of Statistical
Learning*, 2nd ed., Springer 2009, §7.10).

One-standard-error rule (ibid. §7.10, Fig. 7.9): among the candidates whose position error is
within one standard error of the smallest, and for 6-D readings whose orientation error is also
within one standard error of the smallest among those, the simplest is chosen: fewest identifiable
parameters, then without the map. A richer model must beat a simpler one by more than the noise of
the cross-validation estimate itself.

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
the row-wise noise model neglects. The factor is chosen on :data:`WEIGHT_SUBSET` and used by every
candidate and by the final fit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TypeVar

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from pipeline.calibration import measure as ms
from pipeline.calibration import subsets
from pipeline.calibration.config import Config
from pipeline.calibration.elastostatic import measurement_model
from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.estimate import Estimate
from pipeline.calibration.noise_model import NoiseModel, fit_with_noise_model
from pipeline.calibration.residual_map import fit_residual_map, restart_seed
from pipeline.core.errors import PipelineError
from pipeline.robot.model import RobotModel
from pipeline.robot.repeatability import repeatability_sigma_m
from pipeline.robot.residual_map import ResidualMap

#: the named parameter subsets compared (pipeline.calibration.subsets), simplest first
SUBSETS = ("joint_offsets", "geometric", "all")
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


@dataclass(frozen=True)
class Candidate:
    """A parameter subset, with or without the residual map."""

    parameters: str
    residual_map: bool

    @property
    def name(self) -> str:
        return self.parameters + (" + residual map" if self.residual_map else "")


CANDIDATES = tuple(Candidate(p, m) for p in SUBSETS for m in (False, True))
T = TypeVar("T")


@dataclass
class CandidateScore:
    """Held-out errors of one candidate, per pose (NaN where a fold could not be fitted)."""

    candidate: Candidate
    n_parameters: int
    fold_of_pose: np.ndarray                       # (n,) fold of each pose
    position_error_m: np.ndarray                   # (n,)
    orientation_error_rad: np.ndarray | None       # (n,) 6-D readings, else None
    #: (n,) poses that count in the score (False: a gross error, :func:`gross_heldout_poses`)
    scored: np.ndarray | None = None

    @property
    def mask(self) -> np.ndarray:
        return np.ones(len(self.position_error_m), bool) if self.scored is None else self.scored

    @property
    def valid(self) -> bool:
        return bool(np.all(np.isfinite(self.position_error_m[self.mask])))

    def mse_and_se(self, e: np.ndarray) -> tuple[float, float]:
        """Mean squared error over the scored held-out poses and its standard error across the folds."""
        m = self.mask
        folds = np.unique(self.fold_of_pose[m])
        per_fold = np.array([np.mean(e[m & (self.fold_of_pose == f)] ** 2) for f in folds])
        return float(np.mean(e[m] ** 2)), float(np.std(per_fold, ddof=1) / np.sqrt(len(folds)))

    def as_dict(self) -> dict:
        mse, se = self.mse_and_se(self.position_error_m) if self.valid else (float("nan"), float("nan"))
        out = {"candidate": self.candidate.name, "parameters": self.candidate.parameters,
               "residual_map": self.candidate.residual_map, "n_parameters": self.n_parameters,
               "rms_position_error_m": float(np.sqrt(mse)) if self.valid else None,
               "se_position_mse_m2": se if self.valid else None,
               "rms_orientation_error_rad": None, "se_orientation_mse_rad2": None}
        if self.orientation_error_rad is not None and self.valid:
            mse_r, se_r = self.mse_and_se(self.orientation_error_rad)
            out |= {"rms_orientation_error_rad": float(np.sqrt(mse_r)), "se_orientation_mse_rad2": se_r}
        return out


@dataclass
class ModelSelection:
    """The cross-validation table and the choice of the one-standard-error rule."""

    folds: int
    scores: list[CandidateScore]
    chosen: Candidate
    notes: list[str] = field(default_factory=list)
    #: factor on the marker-point rows' 1-sigma chosen by cross-validation (1: positions only)
    orientation_scale: float = 1.0
    #: (kappa, CV RMS position m, CV RMS orientation rad) of each factor tried
    orientation_scales_tried: list[tuple[float, float, float]] = field(default_factory=list)

    def score_of(self, c: Candidate) -> CandidateScore:
        return next(s for s in self.scores if s.candidate == c)

    def cross_validation(self) -> dict:
        """The chosen candidate's held-out figures (``summary.json`` ``cross_validation``)."""
        s = self.score_of(self.chosen)
        d = s.as_dict()
        m = s.mask
        per_fold = [float(np.sqrt(np.mean(s.position_error_m[m & (s.fold_of_pose == f)] ** 2)))
                    for f in range(self.folds)]
        return {"folds": self.folds, "n_poses": int(m.sum()), "n_gross_left_out": int((~m).sum()),
                "model": self.chosen.name,
                "rms_position_error_m": d["rms_position_error_m"],
                "rms_orientation_error_rad": d["rms_orientation_error_rad"],
                # every held-out pose, the gross ones too (the figure to compare with published ones)
                "rms_position_error_all_poses_m": _rms(s.position_error_m),
                "rms_orientation_error_all_poses_rad": (None if s.orientation_error_rad is None
                                                        else _rms(s.orientation_error_rad)),
                "orientation_weight_scale": self.orientation_scale,
                "per_fold_rms_m": per_fold, "n_folds_not_regular": 0}

    def as_dict(self) -> dict:
        return {"folds": self.folds, "chosen": self.chosen.name, "rule": "one standard error",
                "candidates": [s.as_dict() for s in self.scores], "notes": self.notes,
                "orientation_weight_scale": self.orientation_scale,
                "orientation_scales_tried": [{"scale": k, "rms_position_error_m": p, "rms_orientation_error_rad": r}
                                             for k, p, r in self.orientation_scales_tried]}

    def markdown(self) -> str:
        six_d = any(s.orientation_error_rad is not None for s in self.scores)
        head = "| model | identifiable parameters | CV RMS position [mm] | SE of MSE [mm²] |"
        rule = "|---|---|---|---|"
        if six_d:
            head += " CV RMS orientation [deg] | SE of MSE [deg²] |"
            rule += "---|---|"
        lines = ["### Model selection (parameters: auto)", "",
                 f"{self.folds}-fold cross-validation on the measurement file (recorded readings; every "
                 "held-out pose scored); chosen by the one-standard-error rule (Hastie, Tibshirani & "
                 f"Friedman 2009, §7.10): **{self.chosen.name}**.", "", head, rule]
        for s in self.scores:
            d = s.as_dict()
            mark = " (chosen)" if s.candidate == self.chosen else ""
            if not s.valid:
                lines.append(f"| {s.candidate.name} | {s.n_parameters} | a fold could not be fitted | |"
                             + (" | |" if six_d else ""))
                continue
            row = (f"| {s.candidate.name}{mark} | {s.n_parameters} | {1e3 * d['rms_position_error_m']:.3f} | "
                   f"{1e6 * d['se_position_mse_m2']:.3f} |")
            if six_d and d["rms_orientation_error_rad"] is not None:
                row += (f" {np.degrees(d['rms_orientation_error_rad']):.3f} | "
                        f"{np.degrees(1.0) ** 2 * d['se_orientation_mse_rad2']:.4f} |")
            lines.append(row)
        if self.orientation_scales_tried:
            tried = ", ".join(f"{k:g}: {1e3 * p:.3f} mm / {np.degrees(r):.3f}°"
                              for k, p, r in self.orientation_scales_tried)
            lines.append(f"- orientation weight: the marker-point rows' REML sigma times {self.orientation_scale:g}, "
                         f"chosen by cross-validation of {WEIGHT_SUBSET} (factor: CV RMS position / orientation: "
                         f"{tried})")
        lines += [f"- {n}" for n in self.notes]
        return "\n".join(lines + [""])


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(e, float) ** 2)))


def one_standard_error(scores: list[CandidateScore]) -> Candidate:
    """The simplest candidate within one standard error of the best (module docstring)."""
    valid = [s for s in scores if s.valid]
    if not valid:
        raise PipelineError(None, "calibration.parameters", "auto: no candidate model could be fitted on "
                            "every cross-validation fold; give calibration.parameters explicitly")
    pos = {id(s): s.mse_and_se(s.position_error_m) for s in valid}
    best = min(valid, key=lambda s: pos[id(s)][0])
    near = [s for s in valid if pos[id(s)][0] <= pos[id(best)][0] + pos[id(best)][1]]
    if all(s.orientation_error_rad is not None for s in near):
        ori = {id(s): s.mse_and_se(s.orientation_error_rad) for s in near}  # type: ignore[arg-type]
        best_r = min(near, key=lambda s: ori[id(s)][0])
        near = [s for s in near if ori[id(s)][0] <= ori[id(best_r)][0] + ori[id(best_r)][1]]
    return min(near, key=lambda s: (s.n_parameters, s.candidate.residual_map)).candidate


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


def score_subset(mm: MeasurementModel, basis: np.ndarray, meas: ms.Measurements, orientation_sigma_rad: float,
                 folds: int, max_iterations: int, rng: np.random.Generator, robust: dict | None = None,
                 noise: NoiseModel | None = None) -> tuple[CandidateScore, Callable[[], CandidateScore]]:
    """Held-out errors of one parameter subset without and with the residual map; each training fold
    is fitted with the noise model ``noise`` (its REML remainder estimated on the training fold,
    :func:`pipeline.calibration.noise_model.fit_with_noise_model`; ``robust``: the robust fit's loss,
    confidence and max_fraction), so gross errors are rejected inside the training folds only and
    every held-out pose is scored. The score with the map is computed when its callable is called
    (the seeds of its fits are drawn from ``rng`` fold by fold here: an orientation weight that is
    not chosen skips the maps and leaves every later draw as it was)."""
    robust = ROBUST_DEFAULTS | (robust or {})
    n = len(meas)
    six_d = meas.rotvec is not None and mm.marker_points
    rec = ms.expand_orientation(meas, orientation_sigma_rad) if six_d else meas
    pose = rec.pose_index if rec.pose_index is not None else np.arange(len(rec))
    fold_of_pose = np.arange(n) % folds
    e_plain = np.full(n, np.nan)
    e_rot = np.full(n, np.nan) if six_d else None
    maps: list[tuple[Estimate, np.ndarray, int, np.ndarray, np.ndarray]] = []
    for f in range(folds):
        train = (pose % folds) != f
        test = np.flatnonzero(fold_of_pose == f)
        train_poses = np.flatnonzero(fold_of_pose != f)
        if not len(test):
            continue

        def part(a: np.ndarray | None, m: np.ndarray = train) -> np.ndarray | None:
            return None if a is None else a[m]

        fold = ms.Measurements(rec.Q[train], rec.Y[train], rec.sigma_m[train], f"fold {f + 1}",
                               payload_mounted=part(rec.payload_mounted), offset_m=part(rec.offset_m))
        try:
            est, _, _ = fit_with_noise_model(mm, fold, basis, noise or NoiseModel(), None,
                                             max_iterations=max_iterations, **robust)
        except PipelineError:
            continue   # this fold's training poses do not excite every parameter
        e, R_tb, ang = heldout_errors(mm, est, meas, test)
        e_plain[test] = np.linalg.norm(e, axis=1)
        if e_rot is not None and ang is not None:
            e_rot[test] = ang
        maps.append((est, train_poses, restart_seed(rng), test, e))
    p = basis.shape[1]

    def mapped() -> CandidateScore:
        e_map = np.full(n, np.nan)
        for est, train_poses, seed, test, e in maps:
            e_train, R_tb, _ = heldout_errors(mm, est, meas, train_poses)
            gp = fit_residual_map(meas.Q[train_poses], e_train @ R_tb.T, seed)
            e_map[test] = np.linalg.norm(e - gp.predict(meas.Q[test])[0] @ R_tb, axis=1)
        return CandidateScore(Candidate("", True), p, fold_of_pose, e_map, e_rot)

    return CandidateScore(Candidate("", False), p, fold_of_pose, e_plain, e_rot), mapped


def select_model(meas: ms.Measurements, setup: Callable[[str], tuple[MeasurementModel, np.ndarray]],
                 orientation_sigma_rad: float, folds: int, max_iterations: int,
                 rng: np.random.Generator, robust: dict | None = None, noise: NoiseModel | None = None
                 ) -> ModelSelection:
    """Score every candidate (module docstring) and choose one. ``setup(parameters)`` gives the
    measurement model and identifiable basis of a parameter subset."""
    folds = min(folds, len(meas))
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

    def scored_with(subset: str, kappa: float) -> tuple[CandidateScore, Callable[[], CandidateScore]]:
        mm, basis = models[subset]
        return score_subset(mm, basis, meas, orientation_sigma_rad, folds, max_iterations, rng, robust,
                            replace(noise, orientation_scale=kappa))

    kappa = 1.0
    tried: list[tuple[float, float, float]] = []
    done: dict[float, tuple[CandidateScore, Callable[[], CandidateScore]]] = {}
    weight_subset = WEIGHT_SUBSET if WEIGHT_SUBSET in models else next(iter(models), "")
    if meas.rotvec is not None and weight_subset and models[weight_subset][0].marker_points:
        kappa, done = orientation_weight(lambda k: scored_with(weight_subset, k))
        tried = [(k, *rms_errors(pair[0])) for k, pair in sorted(done.items())]
    for subset in models:
        plain, with_map = done[kappa] if subset == weight_subset and kappa in done else scored_with(subset, kappa)
        mapped = with_map()
        plain.candidate, mapped.candidate = Candidate(subset, False), Candidate(subset, True)
        scores += [plain, mapped]
    gross = gross_heldout_poses(scores, float((robust or {}).get("confidence", 0.999)))
    if gross.any():
        for score in scores:
            score.scored = ~gross
        notes.append(f"{int(gross.sum())} held-out pose(s) beyond the chi-square bound of the best candidate's "
                     "robust error scale (gross errors) left out of every candidate's score")
    chosen = one_standard_error(scores)
    return ModelSelection(folds, scores, chosen, notes, kappa, tried)


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


def gross_heldout_poses(scores: list[CandidateScore], confidence: float) -> np.ndarray:
    """(n,) held-out poses whose position error is a gross error for the candidate with the smallest
    median held-out error: ``e^2 > chi2_3(confidence) s^2`` with the robust per-axis scale
    ``s^2 = median(e^2) / median(chi2_3)`` (Rousseeuw & Croux 1993: a median-based scale is not
    inflated by the outliers it screens). One mask for every candidate, so a gross reading in a
    left-out fold neither favours the stiffest model nor hides in the score."""
    fitted = [s for s in scores if np.all(np.isfinite(s.position_error_m))]
    if not fitted:
        return np.zeros(len(scores[0].position_error_m) if scores else 0, bool)
    best = min(fitted, key=lambda s: float(np.median(s.position_error_m)))
    e2 = best.position_error_m ** 2
    scale2 = float(np.median(e2)) / chi2.median(3)
    return e2 > chi2.ppf(confidence, 3) * scale2


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
                       NoiseModel(repeatability_sigma_m(robot.spec.repeatability_m or 0.0)))
    p = sel.chosen.parameters
    return replace(cfg, parameters=p,
                   gravity_model=cfg.gravity_model if subsets.wants_compliance(p) else None), sel


def final_residual_map(sel: ModelSelection | None, mm: MeasurementModel, est: Estimate,
                       user: ms.Measurements | None, rec: ms.Measurements, rejected: np.ndarray,
                       rng: np.random.Generator) -> ResidualMap | None:
    """The residual map of the chosen model, fitted to the final fit's residuals at the marker
    origins of the poses the outlier test kept (None: the map was not chosen)."""
    if sel is None or user is None or not sel.chosen.residual_map:
        return None
    rows = np.asarray(rejected, int)
    bad = set((rec.pose_index[rows] if rec.pose_index is not None else rows).tolist())
    keep = np.array([i for i in range(len(user)) if i not in bad], int)
    e, R_tb, _ = heldout_errors(mm, est, user, keep)
    return fit_residual_map(user.Q[keep], e @ R_tb.T, rng)


def stage_entries(notes: dict, parameters: str | list[str]) -> tuple[dict, dict[str, np.ndarray], str]:
    """Summary entries, ``results.npz`` arrays (the residual map handed on) and the report section
    of the model selection, the residual map and the marker rotation kept in an outcome's notes
    (``parameters``: the configured subset; auto without a selection is all)."""
    summary: dict = {"parameters": "all"} if parameters == "auto" else {}
    arrays: dict[str, np.ndarray] = {}
    md = ""
    sel: ModelSelection | None = notes.get("model_selection")
    if sel is not None:
        summary["model_selection"] = sel.as_dict()
        summary["parameters"] = sel.chosen.parameters
        md += sel.markdown()
    rmap: ResidualMap | None = notes.get("residual_map")
    summary["residual_map"] = None
    if rmap is not None:
        arrays.update(rmap.to_arrays())
        _, std = rmap.predict(rmap.inputs_rad)
        summary["residual_map"] = {"signal_std_m": rmap.signal_std_m, "length_scale_rad": rmap.length_scale_rad,
                                   "noise_std_m": rmap.noise_std_m, "n_poses": int(len(rmap.inputs_rad)),
                                   "posterior_std_at_poses_m": float(np.sqrt(np.mean(std ** 2)))}
        md += (f"\nResidual map handed on (Gaussian process over joint space, Rasmussen & Williams 2006): signal "
               f"{1e3 * rmap.signal_std_m:.3f} mm, length scale {rmap.length_scale_rad:.3f} rad, noise "
               f"{1e3 * rmap.noise_std_m:.3f} mm; posterior std at the calibration poses "
               f"{1e3 * summary['residual_map']['posterior_std_at_poses_m']:.3f} mm per axis.\n")
    rot = notes.get("marker_rotation_on_flange")
    if rot is not None:
        summary["marker_rotation_on_flange_deg"] = float(np.degrees(np.linalg.norm(
            Rotation.from_matrix(rot).as_rotvec())))
        md += (f"\nMarker frame on the flange (6-D readings): turned {summary['marker_rotation_on_flange_deg']:.2f}° "
               "from the flange axes (closed-form rotation average, refined by the fit's tool rotations).\n")
    return summary, arrays, md
