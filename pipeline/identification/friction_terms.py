"""Friction and actuation terms beyond viscous + Coulomb, chosen per joint by held-out data.

The linear model (:mod:`.regressor`) has per joint ``fv v + fc tanh(v / w) + offset``. Recorded
logs of current-controlled arms (torque = gear ratio x motor constant x current, friction acting in
the motor) leave structure that this class cannot explain. Each joint may take any of these term
classes, each linear in its coefficients (shape parameters fixed on a grid):

* ``coulomb_asymmetry``: direction-dependent Coulomb friction, ``fa |tanh(v / w)|``; with the
  Coulomb term and the torque offset it gives ``fc+ = fc + fa`` for ``v > 0`` and ``fc- = fc - fa``
  for ``v < 0`` above a separate offset (Armstrong-Hélouvry, Dupont & Canudas de Wit 1994,
  Automatica 30(7): the Coulomb level depends on the direction of motion).
* ``sigmoid``: the sigmoid friction of Gaz, Cognetti, Oliva, Robuffo Giordano & De Luca 2019
  ("Dynamic identification of the Franka Emika Panda robot with retrieval of feasible parameters
  using penalty-based optimization", IEEE RA-L 4(4), eq. 6),
  ``phi1 / (1 + exp(-phi2 (v + phi3))) - phi1 / (1 + exp(-phi2 phi3))``, in the units the record's
  efforts have (motor current times a constant for a current-controlled arm: the sigmoid is then
  a friction in the motor-current domain). Up to a constant (the offset's) it is
  ``(phi1 / 2) tanh(phi2 (v + phi3) / 2)``: a Coulomb level with its own width and a shift of the
  velocity at which it changes sign. ``phi2, phi3`` are chosen on :data:`SIGMOID_WIDTHS` x
  :data:`SIGMOID_SHIFTS` (times the joint's velocity spread) by the largest drop of the weighted
  residual; ``phi1`` is linear.
* ``position``: a position-dependent torque ``a1 sin q + b1 cos q + a2 sin 2q + b2 cos 2q`` of the
  joint's own angle (cable and hose springs, gear eccentricity; columns within the span of the rigid
  model, such as gravity, drop out).
* ``effort_gain``: an error ``g`` of the record's effort-to-torque constant, ``tau_meas = (1 + g)
  tau_model``, linearised at the model's own torque on the joint (the column ``tau_hat_j``, the
  fit without the term; bilinear like the load-dependent Coulomb friction of :mod:`.friction`).
  Only identifiable because other joints' rows share the base parameters, and only relative to the
  other joints: a common scale of all efforts is the scale of all parameters (a gain ``g`` on one
  joint and ``1 / (1 + g) - 1`` on all others fit alike).

**Selection, without the held-out tail.** The training part of the record (the first
``train_fraction``) is cut into :data:`N_FOLDS` contiguous blocks in time; each of the last
:data:`N_SCORED_BLOCKS` is predicted by the fit (Gautier's WLS of the base parameters with the
terms) on every block before it (forward chaining: each score extrapolates forward in time, as the
held-out tail does). Per joint, forward selection: each round adds the class that lowers that
joint's cross-validated RMS most, when it does by at least :data:`MIN_RELATIVE_GAIN`, its fitted
term is plausible (:meth:`JointTerm.plausible`) and no other joint's RMS rises by more than that
fraction. The chosen terms are then fitted on the whole training part (the held-out tail never
enters) and their torque taken off the record's torques before the rigid-body fits
(:func:`take_off`), like the Stribeck term of :mod:`.friction`; the held-out predictions get it
back (:func:`add_back`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from pipeline.identification.estimate import weighted_solution
from pipeline.identification.gates import band_noise_sigma, model_class_structure
from pipeline.identification.measure import ProcessedData
from pipeline.identification.outcome import Validation
from pipeline.identification.signals import record_filter_settings

TERM_CLASSES = ("coulomb_asymmetry", "sigmoid", "position", "effort_gain")
#: contiguous blocks of the training part in the selection's cross-validation; the last N_SCORED_BLOCKS
#: are each scored by the fit on every block before them (forward chaining, like the held-out tail)
N_FOLDS = 5
N_SCORED_BLOCKS = 3
#: a term class is added to a joint when it lowers the joint's cross-validated RMS by at least this
MIN_RELATIVE_GAIN = 0.02
#: sigmoid widths 2 / phi2 and shifts -phi3, times the joint's velocity standard deviation
SIGMOID_WIDTHS = (0.01, 0.03, 0.1, 0.3, 1.0)
SIGMOID_SHIFTS = (-0.3, -0.1, -0.03, 0.0, 0.03, 0.1, 0.3)
#: harmonics of the joint angle in the position-dependent term
POSITION_HARMONICS = (1, 2)
#: largest plausible term (Coulomb asymmetry, sigmoid level phi1, each harmonic's amplitude of the position
#: term) as a fraction of the joint's torque limit: the bound of the Stribeck excess (:mod:`.friction`)
MAX_TERM_OVER_LIMIT = 0.1
#: largest plausible error of an effort-to-torque constant (motor constants are stated within a few per cent)
MAX_EFFORT_GAIN = 0.25
#: a candidate column whose part outside the rigid model's span is below this fraction of its norm is dropped
MIN_INDEPENDENT_NORM = 1e-6


@dataclass
class JointTerm:
    """One term class on one joint (0-based column ``joint`` of the record's torques): its shape
    (sigmoid: ``width_rad_s`` = 2 / phi2, ``shift_rad_s`` = -phi3) and coefficients."""

    kind: str
    joint: int
    width_rad_s: float = 0.0
    shift_rad_s: float = 0.0
    coefficients: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def values(self, q: np.ndarray, v: np.ndarray, coulomb_width_rad_s: float, model_Nm: np.ndarray | None
               ) -> np.ndarray:
        """(N, m) the term's columns at the joint's positions ``q`` (N,), velocities ``v`` (N,) or (N, k)
        (block mean) and, for ``effort_gain``, the model's torque ``model_Nm`` (N,) on the joint."""
        v2 = v[:, None] if v.ndim == 1 else v
        w = coulomb_width_rad_s
        if self.kind == "coulomb_asymmetry":
            return np.abs(np.tanh(v2 / w) if w > 0 else np.sign(v2)).mean(axis=1)[:, None]
        if self.kind == "sigmoid":
            s = np.tanh((v2 - self.shift_rad_s) / self.width_rad_s) - np.tanh(-self.shift_rad_s / self.width_rad_s)
            return s.mean(axis=1)[:, None]
        if self.kind == "position":
            return np.column_stack([f(h * q) for h in POSITION_HARMONICS for f in (np.sin, np.cos)])
        if self.kind == "effort_gain":
            if model_Nm is None:
                raise ValueError("effort_gain needs the model's torque")
            return np.asarray(model_Nm, float)[:, None]
        raise ValueError(f"unknown term class {self.kind!r}")

    def plausible(self, limit_Nm: float) -> bool:
        """Friction that dissipates (a sigmoid rising with velocity) and terms within their bounds
        (:data:`MAX_TERM_OVER_LIMIT` x the torque limit ``limit_Nm``, :data:`MAX_EFFORT_GAIN`)."""
        c = np.asarray(self.coefficients, float)
        bound = MAX_TERM_OVER_LIMIT * limit_Nm
        if self.kind == "sigmoid":
            return bool(0 < 2 * c[0] <= bound)
        if self.kind == "coulomb_asymmetry":
            return bool(abs(c[0]) <= bound)
        if self.kind == "position":
            return bool(np.all(np.hypot(c[0::2], c[1::2]) <= bound))
        return bool(abs(c[0]) <= MAX_EFFORT_GAIN)

    @property
    def n_columns(self) -> int:
        return 2 * len(POSITION_HARMONICS) if self.kind == "position" else 1

    def to_dict(self) -> dict:
        out: dict = {"kind": self.kind, "coefficients": [float(c) for c in self.coefficients]}
        if self.kind == "sigmoid":   # in Gaz et al.'s parameters
            phi2 = 2.0 / self.width_rad_s
            out |= {"phi1": float(2 * self.coefficients[0]) if self.coefficients.size else 0.0,
                    "phi2_s_rad": phi2, "phi3_rad_s": -self.shift_rad_s}
        return out


@dataclass
class FrictionTerms:
    """The terms chosen on a record (:func:`select_terms`) and the scores that chose them."""

    terms: list[JointTerm]
    coulomb_width_rad_s: float | np.ndarray
    #: per joint cross-validated RMS (training part) of the model without and with the chosen terms (N·m)
    cv_rms_before_Nm: np.ndarray
    cv_rms_after_Nm: np.ndarray
    n_train: int = 0
    n_folds: int = N_FOLDS
    #: base parameters fitted with the terms (the columns' coefficients are in the terms)
    beta: np.ndarray | None = None
    #: (N, nr) the terms' torque on every sample of the record they were taken off (:func:`take_off`)
    torque_Nm: np.ndarray | None = None

    def by_joint(self, n_rows: int) -> list[list[str]]:
        return [[t.kind for t in self.terms if t.joint == j] for j in range(n_rows)]

    def torque(self, data: ProcessedData, Wb: np.ndarray, beta: np.ndarray) -> np.ndarray:
        """(N, nr) the terms' torque on every sample of ``data``; ``Wb @ beta`` the rigid model's torque
        the effort-gain columns are linearised at."""
        cols, coef = columns(self.terms, data, Wb, beta, self.coulomb_width_rad_s)
        nr = data.tau.shape[1]
        return (cols @ coef).reshape(-1, nr) if coef.size else np.zeros((data.n_samples, nr))

    def summary(self, per_joint: Callable[[np.ndarray], list], joint_numbers: np.ndarray) -> dict:
        """Summary entries (JSON-able): the terms per joint (by 1-based number, [] where none was
        chosen) and the cross-validated RMS without and with them."""
        return {"friction_terms": {str(int(n)): [t.to_dict() for t in self.terms if t.joint == j]
                                   for j, n in enumerate(joint_numbers)},
                "friction_terms_cv_rms_before_Nm": per_joint(self.cv_rms_before_Nm),
                "friction_terms_cv_rms_after_Nm": per_joint(self.cv_rms_after_Nm),
                "friction_terms_cv": f"forward chaining over the last {N_SCORED_BLOCKS} of {self.n_folds} "
                                     f"contiguous blocks of the first {self.n_train} samples"}


def _joint_q(data: ProcessedData) -> np.ndarray:
    return data.q if data.rows is None else data.q[:, data.rows]


def columns(terms: list[JointTerm], data: ProcessedData, Wb: np.ndarray, beta: np.ndarray | None,
            coulomb_width_rad_s: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N*nr, m) regressor columns of ``terms`` (rows sample-major like ``Wb``) and their coefficients."""
    nr = data.tau.shape[1]
    n = data.n_samples
    q, vb = _joint_q(data), data.v_blocks
    model = None if beta is None else (Wb @ beta).reshape(n, nr)
    blocks, coef = [], []
    widths = row_widths(coulomb_width_rad_s, nr)
    for t in terms:
        vals = t.values(q[:, t.joint], vb[:, :, t.joint], float(widths[t.joint]),
                        None if model is None else model[:, t.joint])
        c = np.zeros((n, nr, vals.shape[1]))
        c[:, t.joint, :] = vals
        blocks.append(c.reshape(n * nr, -1))
        coef.append(t.coefficients if t.coefficients.size == vals.shape[1] else np.zeros(vals.shape[1]))
    if not blocks:
        return np.zeros((n * nr, 0)), np.zeros(0)
    return np.hstack(blocks), np.concatenate(coef)


def row_widths(coulomb_width_rad_s: float | np.ndarray, n_rows: int) -> np.ndarray:
    """(n_rows,) the Coulomb smoothing width of each torque row (one width for all, or one per row)."""
    return np.broadcast_to(np.asarray(coulomb_width_rad_s, float), (n_rows,))


def _joint_sigma(res: np.ndarray) -> np.ndarray:
    return np.maximum(np.sqrt(np.mean(res**2, axis=0)), 1e-12)


def _head(data: ProcessedData, n: int) -> ProcessedData:
    """The first ``n`` samples of ``data``."""
    nr = data.tau.shape[1]
    return replace(data, q=data.q[:n], v=data.v[:n], a=data.a[:n], tau=data.tau[:n], Y=data.Y[: n * nr],
                   v_full=None if data.v_full is None else data.v_full[:n])


def fit_terms(terms: list[JointTerm], data: ProcessedData, Wb: np.ndarray, sigma: np.ndarray,
              coulomb_width_rad_s: float | np.ndarray) -> tuple[list[JointTerm], np.ndarray]:
    """WLS of the base parameters with the ``terms``' coefficients on ``data`` (``Wb`` its base
    regressor); effort-gain columns at the fit without them. Returns the fitted terms and ``beta``."""
    y = data.y
    beta0 = weighted_solution(Wb, y, sigma)
    cols, _ = columns(terms, data, Wb, beta0, coulomb_width_rad_s)
    x = weighted_solution(np.hstack([Wb, cols]), y, sigma)
    out, k = [], Wb.shape[1]
    for t in terms:
        out.append(replace(t, coefficients=x[k: k + t.n_columns]))
        k += t.n_columns
    return out, x[: Wb.shape[1]]


class BlockedFolds:
    """Forward-chaining cross-validation on contiguous blocks in time: each of the last
    :data:`N_SCORED_BLOCKS` blocks is scored by the fit on every block before it; per joint RMS over
    the scored samples. The rigid model's weighted normal equations are built once per fold; a
    candidate's columns (non-zero on few rows) only add their cross products."""

    def __init__(self, Wb: np.ndarray, y: np.ndarray, sigma: np.ndarray, n_folds: int):
        nr = len(sigma)
        n = Wb.shape[0] // nr
        self.nr = nr
        self.w = np.tile(1.0 / sigma, n)
        self.Ww, self.yw = Wb * self.w[:, None], y * self.w
        edges = np.linspace(0, n, n_folds + 1).astype(int) * nr
        first = n_folds - N_SCORED_BLOCKS
        self.folds = [(int(lo), int(hi)) for lo, hi in zip(edges[first:-1], edges[first + 1:], strict=True)]
        self.gram = {lo: (self.Ww[:lo].T @ self.Ww[:lo], self.Ww[:lo].T @ self.yw[:lo]) for lo, _ in self.folds}
        n_all = self.Ww.shape[0]
        self.gram[n_all] = (self.Ww.T @ self.Ww, self.Ww.T @ self.yw)

    def solve(self, cols: np.ndarray, upto: int) -> np.ndarray:
        """Weighted least squares of the rigid model with ``cols`` (unweighted) on the first ``upto`` rows."""
        Cw = cols[:upto] * self.w[:upto, None]
        GW, bW = self.gram[upto]
        X = self.Ww[:upto].T @ Cw
        G = np.block([[GW, X], [X.T, Cw.T @ Cw]])
        b = np.concatenate([bW, Cw.T @ self.yw[:upto]])
        d = np.sqrt(np.clip(np.diag(G), 1e-300, None))
        return np.linalg.lstsq(G / np.outer(d, d), b / d, rcond=1e-13)[0] / d

    def rms(self, cols: np.ndarray) -> np.ndarray:
        """Per joint cross-validated RMS (N·m) of the rigid model with ``cols`` (rows like ``Wb``)."""
        errs = []
        for lo, hi in self.folds:
            x = self.solve(cols, lo)
            A = np.hstack([self.Ww[lo:hi], cols[lo:hi] * self.w[lo:hi, None]])
            errs.append((self.yw[lo:hi] - A @ x) / self.w[lo:hi])
        return np.sqrt(np.mean(np.concatenate(errs).reshape(-1, self.nr) ** 2, axis=0))


def _sigmoid_shape(data: ProcessedData, Q: np.ndarray, r: np.ndarray, w: np.ndarray, joint: int,
                   coulomb_width_rad_s: float) -> JointTerm | None:
    """The sigmoid of the grid whose column, outside the span ``Q`` of the rigid model and the other
    terms (weighted), lowers the weighted residual ``r`` most (Frisch-Waugh-Lovell: one added column
    ``c`` lowers it by ``(c_perp . r)^2 / |c_perp|^2``)."""
    nr = data.tau.shape[1]
    vj = data.v_blocks[:, :, joint]
    spread = float(np.std(vj))
    if not spread > 0:
        return None
    best, best_gain = None, 0.0
    rows = np.arange(joint, data.n_samples * nr, nr)
    for width in SIGMOID_WIDTHS:
        for shift in SIGMOID_SHIFTS:
            t = JointTerm("sigmoid", joint, max(width * spread, coulomb_width_rad_s), shift * spread)
            cw = np.zeros(data.n_samples * nr)
            cw[rows] = t.values(vj[:, 0], vj, coulomb_width_rad_s, None)[:, 0] * w[rows]
            cp = cw - Q @ (Q.T @ cw)
            nn = float(cp @ cp)
            if nn <= MIN_INDEPENDENT_NORM**2 * float(cw @ cw):
                continue
            gain = float(cp @ r) ** 2 / nn
            if gain > best_gain:
                best, best_gain = t, gain
    return best


def select_terms(data: ProcessedData, base_regressor: Callable, n_train: int, coulomb_width_rad_s: float | np.ndarray,
                 limit_Nm: np.ndarray, classes: tuple[str, ...] = TERM_CLASSES,
                 min_relative_gain: float = MIN_RELATIVE_GAIN, n_folds: int = N_FOLDS) -> FrictionTerms:
    """Per joint forward selection of the term classes on the first ``n_train`` samples, scored by
    blocked cross-validation (module doc); the chosen terms fitted on all ``n_train`` samples."""
    nr = data.tau.shape[1]
    whole = _head(data, n_train)
    W, y = base_regressor(whole.Y), whole.y
    beta0 = weighted_solution(W, y, np.ones(nr))
    sigma = _joint_sigma(whole.tau - (W @ beta0).reshape(-1, nr))
    beta0 = weighted_solution(W, y, sigma)
    cv = BlockedFolds(W, y, sigma, n_folds)
    w = cv.w
    chosen: list[JointTerm] = []

    def cols_of(terms: list[JointTerm]) -> np.ndarray:
        return columns(terms, whole, W, beta0, coulomb_width_rad_s)[0]

    before = cv.rms(cols_of([]))
    current = before.copy()
    while True:     # each round adds the one term, over all joints, with the largest relative gain
        base_cols = cols_of(chosen)
        Q: np.ndarray | None = None
        r = cv.yw
        best_gain, best_term, best_rms = min_relative_gain, None, current
        for j in range(nr):
            for kind in classes:
                if any(t.joint == j and t.kind == kind for t in chosen):
                    continue
                if kind == "sigmoid":
                    if Q is None:
                        Q, _ = np.linalg.qr(np.hstack([cv.Ww, base_cols * w[:, None]]))
                        r = cv.yw - Q @ (Q.T @ cv.yw)
                    term = _sigmoid_shape(whole, Q, r, w, j, float(row_widths(coulomb_width_rad_s, nr)[j]))
                else:
                    term = JointTerm(kind, j)
                if term is None:
                    continue
                trial_cols = np.hstack([base_cols, cols_of([term])])
                term = replace(term, coefficients=cv.solve(trial_cols, len(y))[-term.n_columns:])
                if not term.plausible(float(limit_Nm[j])):
                    continue
                trial = cv.rms(trial_cols)
                gain = 1.0 - trial[j] / current[j]
                others = np.arange(nr) != j     # no other joint worse by more than the gain asked of this one
                if gain >= best_gain and np.all(trial[others] <= (1.0 + min_relative_gain) * current[others]):
                    best_gain, best_term, best_rms = gain, term, trial
        if best_term is None:
            break
        chosen.append(best_term)
        current = best_rms
    fitted, beta = fit_terms(chosen, whole, W, sigma, coulomb_width_rad_s)
    while not all(t.plausible(float(limit_Nm[t.joint])) for t in fitted):   # jointly refitted out of bounds
        chosen = [c for c, t in zip(chosen, fitted, strict=True) if t.plausible(float(limit_Nm[t.joint]))]
        fitted, beta = fit_terms(chosen, whole, W, sigma, coulomb_width_rad_s)
    current = cv.rms(cols_of(chosen))
    return FrictionTerms(fitted, coulomb_width_rad_s, before, current, n_train, n_folds, beta)


def take_off(data: ProcessedData, terms: FrictionTerms, base_regressor: Callable) -> ProcessedData:
    """The record with the terms' torque taken off its torques (every sample, the terms as fitted on
    the training part: the held-out tail never enters them)."""
    if not terms.terms or terms.beta is None:
        return data
    terms.torque_Nm = terms.torque(data, base_regressor(data.Y), terms.beta)
    return replace(data, tau=data.tau - terms.torque_Nm)


def record_terms(data: ProcessedData, base_regressor: Callable, train_fraction: float,
                 coulomb_width_rad_s: float | np.ndarray, limit_Nm: np.ndarray) -> tuple[ProcessedData, FrictionTerms]:
    """A record's terms (:func:`select_terms` on its first ``train_fraction``) and the record with
    their torque taken off (:func:`take_off`)."""
    terms = select_terms(data, base_regressor, int(train_fraction * data.n_samples), coulomb_width_rad_s, limit_Nm)
    return take_off(data, terms, base_regressor), terms


def add_back(val: Validation, terms_Nm: np.ndarray) -> None:
    """Measured and predicted torques of a validation (:class:`~pipeline.identification.outcome.Validation`)
    with the terms' torque ``terms_Nm`` (n_test, nr) of its samples added back (the errors stay)."""
    for name in ("tau_Nm", "pred_phys", "pred_wls", "pred_vc", "pred_load", "pred_load_wls", "pred_load_vc",
                 "pred_load_vc_wls"):
        x = getattr(val, name, None)
        if x is not None:
            setattr(val, name, x + terms_Nm)


def _finite_or_none(values: list) -> list:
    return [None if v is None or not np.isfinite(v) else v for v in values]


def record_scores(terms: FrictionTerms, val: Validation, residual_Nm: np.ndarray, record_sample_time_s: float,
                  cutoff_hz: float | None, decimation: int | None, data: ProcessedData,
                  per_joint: Callable[[np.ndarray], list], joint_numbers: np.ndarray) -> dict:
    """Summary entries of a record's terms and the model-class check
    (:func:`~pipeline.identification.gates.model_class_structure`) on the handed-on fit's residual
    ``residual_Nm`` (all samples, torques less the terms) and the held-out RMS of ``val`` (whose
    torques get the terms back, :func:`add_back`); the lag is one period of the record's position
    cut-off at the processed rate, the noise estimate the processed torques' band above the cut-off
    (:func:`~pipeline.identification.gates.band_noise_sigma`)."""
    if terms.torque_Nm is not None:
        n_test = val.tau_Nm.shape[0]
        add_back(val, terms.torque_Nm[-n_test:])
    cutoff, factor = record_filter_settings(1.0 / record_sample_time_s, cutoff_hz, decimation)
    dt = data.sample_time_s
    lag = max(1, int(round(1.0 / (cutoff * dt))))
    top_hz = 0.5 / dt * (0.8 if factor > 1 else 1.0)     # the decimation filter's edge (signals.decimate)
    noise = band_noise_sigma(data.tau, dt, cutoff, top_hz)
    check = model_class_structure(residual_Nm, np.asarray(val.rms_phys, float), lag, joint_numbers, noise)
    for key in ("model_class_residual_autocorrelation", "model_class_heldout_over_fit"):
        check[key] = per_joint(np.asarray(check[key], float))
    over_noise = np.array([np.nan if x is None else x for x in check["model_class_heldout_over_noise"]], float)
    check["model_class_heldout_over_noise"] = _finite_or_none(per_joint(over_noise))
    check["model_class_noise_sigma_Nm"] = _finite_or_none(per_joint(noise))
    return terms.summary(per_joint, joint_numbers) | check


def not_handed_on_note(summary: dict) -> str | None:
    """The warning that the chosen terms stay in this stage (None: none chosen): robot.yaml's friction
    law has viscous, Coulomb, Stribeck and load-dependent Coulomb terms only, so the robot handed on
    to the control and trajectory stages lacks them."""
    chosen = {n: [t["kind"] for t in terms] for n, terms in (summary.get("friction_terms") or {}).items() if terms}
    if not chosen:
        return None
    return ("friction and actuation terms chosen on "
            + "; ".join(f"joint {n} ({', '.join(kinds)})" for n, kinds in chosen.items())
            + " enter this stage's predictions and validation only: the robot handed on keeps robot.yaml's "
              "friction law (viscous, Coulomb, Stribeck), so the control and trajectory stages do not use them")


def report_lines(summary: dict) -> list[str]:
    """The report's paragraph on a record's terms and the model-class check (none without a record)."""
    if "friction_terms" not in summary:
        return []
    chosen = {n: [t["kind"] for t in terms] for n, terms in summary["friction_terms"].items() if terms}
    out = ["", "Friction and actuation terms beyond viscous + Coulomb, chosen by "
           f"{summary.get('friction_terms_cv', 'cross-validation')}: "
           + ("; ".join(f"joint {n}: {', '.join(kinds)}" for n, kinds in chosen.items()) if chosen else "none") + "."]
    note = not_handed_on_note(summary)
    if note:
        out += ["", f"**Not handed on:** {note[0].upper()}{note[1:]}."]
    flagged = summary.get("model_class_structure_joints") or []
    out += ["", ("**Warning:** " + "; ".join(w for w in summary.get("warnings", []) if "model class" in w) + ".")
            if flagged else "Model-class check: no joint's residual keeps structure (autocorrelation, held-out "
            "over fit and over noise within their bounds)."]
    return out


__all__ = ["MIN_RELATIVE_GAIN", "N_FOLDS", "N_SCORED_BLOCKS", "TERM_CLASSES", "BlockedFolds", "FrictionTerms",
           "JointTerm", "add_back", "columns", "fit_terms", "not_handed_on_note", "record_scores", "record_terms",
           "report_lines", "select_terms", "take_off"]
