"""The model selection's scores: held-out errors per candidate, the gross-error screen, the
one-standard-error rule and the cross-validation table (:mod:`pipeline.calibration.model_selection`).

Every held-out pose of a candidate carries its position error ``|e|``, the nominal model's error
"before", and the predicted ``E|e|^2 = trace(J C J^T) + 3 sigma^2 (+ 3 s_map^2)`` of its fold's fit
(:func:`pipeline.calibration.validate.predicted_covariance`, the fold's noise model); the
cross-validated figures of the chosen candidate (:meth:`ModelSelection.cross_validation`) are all
computed from these arrays (:func:`pipeline.calibration.crossval.heldout_figures`), so a ratio in
``summary.json`` is the ratio of the figures beside it.

Gross-error screen (:func:`gross_heldout_poses`): one mask of held-out poses for every candidate,
from the candidate with the smallest median held-out error and a median-based scale. When it would
leave out more than ``max_outlier_fraction`` of the held-out poses it leaves out none
(:func:`pipeline.calibration.crossval.screen_capped`: so many "gross errors" say that the model, not
the readings, is off) and a note says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from pipeline.calibration.crossval import heldout_figures
from pipeline.core.errors import PipelineError


@dataclass(frozen=True)
class Candidate:
    """A parameter subset, with or without the residual map."""

    parameters: str
    residual_map: bool

    @property
    def name(self) -> str:
        return self.parameters + (" + residual map" if self.residual_map else "")


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
    #: (n,) predicted ``E|e|^2`` (m^2) of each held-out pose under its fold's fit (module docstring)
    predicted_var_m2: np.ndarray | None = None
    #: (n,) held-out error of the nominal model with the fold's registered tracker pose (m)
    before_error_m: np.ndarray | None = None

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
    #: (n,) held-out poses the gross-error screen found (before its cap), and the cap's fraction
    gross: np.ndarray | None = None
    max_fraction: float = 0.1
    #: the orientation weight of each fold's fit in :attr:`nested`, chosen on that fold's training poses
    #: alone (:func:`pipeline.calibration.model_selection.nested_orientation_weights`)
    fold_orientation_scales: list[float] | None = None
    #: the chosen candidate's held-out errors with those weights (nested cross-validation), and the poses
    #: its gross-error screen leaves out; None: the figures are those of the table (no weight was chosen)
    nested: CandidateScore | None = None
    nested_gross: np.ndarray | None = None

    def score_of(self, c: Candidate) -> CandidateScore:
        return next(s for s in self.scores if s.candidate == c)

    def cross_validation(self) -> dict:
        """The chosen candidate's held-out figures (``summary.json`` ``cross_validation``): the
        screened ones and those over every pose, each ratio of the figures beside it; with a chosen
        orientation weight those of the nested cross-validation (:attr:`nested`: no held-out pose
        chose the weight of the fit predicting it), else those of the table."""
        s = self.nested if self.nested is not None else self.score_of(self.chosen)
        n = len(s.position_error_m)
        screen = self.nested_gross if self.nested is not None else self.gross
        gross = np.zeros(n, bool) if screen is None else np.asarray(screen, bool)
        var = s.predicted_var_m2 if s.predicted_var_m2 is not None else np.full(n, np.nan)
        before = s.before_error_m if s.before_error_m is not None else np.full(n, np.nan)
        fitted = np.isfinite(s.position_error_m)
        parts = [(int(f), s.position_error_m[m], before[m], var[m], gross[m])
                 for f in range(self.folds) for m in [fitted & (s.fold_of_pose == f)] if m.any()]
        out = heldout_figures(parts, self.folds, self.max_fraction)
        keep = fitted & (np.ones(n, bool) if out["screen_capped"] else ~gross)
        rot = s.orientation_error_rad
        out |= {"n_gross_left_out": out["n_rejected"], "model": self.chosen.name,
                "rms_orientation_error_rad": None if rot is None else _rms(rot[keep]),
                "rms_orientation_error_all_poses_rad": None if rot is None else _rms(rot[fitted]),
                "orientation_weight_scale": self.orientation_scale,
                "orientation_weight_scale_per_fold": self.fold_orientation_scales}
        return out

    def as_dict(self) -> dict:
        excess = standard_errors_above_best(self.scores)
        return {"folds": self.folds, "chosen": self.chosen.name, "rule": "one standard error",
                "fold_grouping": "spatial (k-means in joint space)",
                "candidates": [s.as_dict() | {"standard_errors_above_best": _finite(excess.get(id(s)))}
                               for s in self.scores], "notes": self.notes,
                "orientation_weight_scale": self.orientation_scale,
                "orientation_weight_scale_per_fold": self.fold_orientation_scales,
                "orientation_scales_tried": [{"scale": k, "rms_position_error_m": p, "rms_orientation_error_rad": r}
                                             for k, p, r in self.orientation_scales_tried]}

    def markdown(self, weight_subset: str = "geometric") -> str:
        six_d = any(s.orientation_error_rad is not None for s in self.scores)
        head = "| model | identifiable parameters | CV RMS position [mm] | SE of MSE [mm²] |"
        rule = "|---|---|---|---|"
        if six_d:
            head += " CV RMS orientation [deg] | SE of MSE [deg²] |"
            rule += "---|---|"
        lines = ["### Model selection (parameters: auto)", "",
                 f"{self.folds}-fold cross-validation on the measurement file (recorded readings; folds grouped in "
                 "joint space by k-means, so each held-out fold lies where the others did not measure; every "
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
            lines.append(f"- orientation weight of the final fit and of the table: the marker-point rows' REML sigma "
                         f"times {self.orientation_scale:g}, chosen by cross-validation of {weight_subset} (factor: CV "
                         f"RMS position / orientation: {tried})")
        if self.fold_orientation_scales is not None:
            per_fold = ", ".join(f"{k:.3g}" for k in self.fold_orientation_scales)
            over = ""
            if self.nested is not None and len(self.nested.position_error_m):
                over = f"; over every pose {1e3 * float(np.sqrt(np.mean(self.nested.position_error_m ** 2))):.3f} mm"
                if self.nested.orientation_error_rad is not None:
                    over += f" / {np.degrees(np.sqrt(np.mean(self.nested.orientation_error_rad ** 2))):.3f}°"
            lines.append(f"- the chosen model's held-out figures (cross_validation) are nested in the orientation "
                         f"weight: each fold's fit has it chosen the same way by a cross-validation of its own "
                         f"training poses (per fold: {per_fold}), so no held-out pose chose the weight it is scored "
                         f"with{over}. They are not nested in the choice among the candidates above, made on every "
                         "pose: they are the chosen model's figures, not those of choosing a model on fewer poses "
                         "(a validation file measures that)")
        excess = standard_errors_above_best(self.scores)
        if excess:
            band = max(1.0, min(excess.values()))
            listed = ", ".join(f"{s.candidate.name} {excess[id(s)]:.2f}" for s in self.scores if id(s) in excess)
            which = "the larger of the position's and the orientation's" if six_d else "position"
            lines.append(f"- excess over the best in the best's standard errors ({which}): {listed}; the simplest "
                         f"within {band:.2f} is chosen"
                         + (" (no candidate within 1 on every error: the band widened to the smallest excess)"
                            if band > 1.0 else ""))
        lines += [f"- {n}" for n in self.notes]
        return "\n".join(lines + [""])


def _finite(x: float | None) -> float | None:
    return float(x) if x is not None and np.isfinite(x) else None


def _rms(e: np.ndarray) -> float | None:
    e = np.asarray(e, float)
    return float(np.sqrt(np.mean(e ** 2))) if e.size else None


def standard_errors_above_best(scores: list[CandidateScore]) -> dict[int, float]:
    """Each valid candidate's excess over the best, in the best's standard errors (module docstring
    of :mod:`pipeline.calibration.model_selection`), keyed by ``id(score)``: ``(MSE - MSE_best) /
    SE_best`` of the position error, and for 6-D readings the larger of that and the orientation
    error's, each against the best candidate of that error."""
    valid = [s for s in scores if s.valid]
    excess = dict.fromkeys(map(id, valid), 0.0)
    errors = ["position_error_m"]
    if valid and all(s.orientation_error_rad is not None for s in valid):
        errors.append("orientation_error_rad")
    for error in errors:
        mse = {id(s): s.mse_and_se(getattr(s, error)) for s in valid}
        best_mse, best_se = min(mse.values())
        for s in valid:
            over = mse[id(s)][0] - best_mse
            z = over / best_se if best_se > 0 else (0.0 if over <= 0 else np.inf)
            excess[id(s)] = max(excess[id(s)], z)
    return excess


def one_standard_error(scores: list[CandidateScore]) -> Candidate:
    """The simplest candidate within one standard error of the best on every error scored, the band
    widened to the smallest excess a candidate reaches when none is within one on every error
    (module docstring of :mod:`pipeline.calibration.model_selection`)."""
    valid = [s for s in scores if s.valid]
    if not valid:
        raise PipelineError(None, "calibration.parameters", "auto: no candidate model could be fitted on "
                            "every cross-validation fold; give calibration.parameters explicitly")
    excess = standard_errors_above_best(valid)
    band = max(1.0, min(excess.values()))
    near = [s for s in valid if excess[id(s)] <= band]
    return min(near, key=lambda s: (s.n_parameters, s.candidate.residual_map)).candidate


def gross_heldout_poses(scores: list[CandidateScore], confidence: float) -> np.ndarray:
    """(n,) held-out poses whose position error is a gross error for the candidate with the smallest
    median held-out error: ``e^2 > chi2_3(confidence) s^2`` with the robust per-axis scale
    ``s^2 = median(e^2) / median(chi2_3)`` (Rousseeuw & Croux 1993: a median-based scale is not
    inflated by the outliers it screens). One mask for every candidate, so a gross reading in a
    left-out fold neither favours the stiffest model nor hides in the score; the cap
    (:func:`pipeline.calibration.crossval.screen_capped`) is the caller's."""
    fitted = [s for s in scores if np.all(np.isfinite(s.position_error_m))]
    if not fitted:
        return np.zeros(len(scores[0].position_error_m) if scores else 0, bool)
    best = min(fitted, key=lambda s: float(np.median(s.position_error_m)))
    e2 = best.position_error_m ** 2
    scale2 = float(np.median(e2)) / chi2.median(3)
    return e2 > chi2.ppf(confidence, 3) * scale2
