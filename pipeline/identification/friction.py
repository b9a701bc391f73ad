"""Non-linear (Stribeck) friction on top of the linear base model (``friction_model: stribeck``).

The linear model has viscous and (smoothed) Coulomb friction per joint, ``fv v + fc tanh(v / w)``
(:mod:`.regressor`). The Stribeck model adds the excess of static over Coulomb friction that
decays with speed (Armstrong-Hélouvry, Dupont & Canudas de Wit 1994, "A survey of models, analysis
tools and compensation methods for the control of machines with friction", Automatica 30(7),
eq. of the "Stribeck" steady-state curve):

    tau_f,j = fv_j v + (fc_j + fs_j exp(-(v / vs_j)^2)) tanh(v / w)

with ``fs_j >= 0`` the static excess and ``vs_j > 0`` the Stribeck velocity. ``tau`` is linear in
the base parameters ``beta`` and in ``fs`` but not in ``vs``; all are estimated together by
IPOPT with exact derivatives (CasADi automatic differentiation, exact Hessian) minimising the
residual weighted by the per-joint noise sigmas (the WLS weights, Gautier). The fit is nested in
the viscous + Coulomb fit and starts from it (its WLS ``beta``, ``fs = 0``); a joint's term whose
likelihood-ratio gain (same weights as the fit) is below :data:`MIN_CHI2_GAIN` is dropped, the
others' gains recomputed without it, so a handed-on gain is never negative.
``log vs`` is the variable.

Physically plausible terms only: the static excess is bounded by
:data:`MAX_EXCESS_OVER_LIMIT` of the joint's torque limit (static friction of geared joints is a
few per cent of the rated torque; Armstrong-Hélouvry et al. 1994 §2 report static over Coulomb
friction ratios of about 1.1-1.5, i.e. an excess of a fraction of the Coulomb level), and the
Stribeck velocity is at least the Coulomb smoothing width ``w`` (a narrower dip is below what the
smooth sign resolves: a spike fitted to noise) and at most ``VS_MAX``.

With ``friction_model: stribeck`` the stage subtracts the fitted Stribeck term from the measured
torques before the physically consistent fit and hands ``fs``, ``vs`` on in the identified model
(``actuation.static_friction_excess_Nm``, ``actuation.stribeck_velocity_rad_s``; the model's
``friction_torque`` is :func:`pipeline.robot.friction.joint_friction_torque`) only when the
held-out validation torques select it: both models are scored on them (:func:`friction_summary`)
and the one with the smaller mean RMS / noise sigma is handed on.

**Load-dependent Coulomb friction** (a third candidate, on top of the configured model): Coulomb
friction grows with the torque the transmission carries, ``F_c (1 + mu |tau_load| / tau_max)``
(Bittencourt & Gunnarsson 2012, "Static friction in a robot joint - modeling and identification of
load and temperature effects", J. Dyn. Sys. Meas. Control 134(5)). Per joint the added term is

    tau_l,j = fl_j |tau_load,j| tanh(v_j / w),    fl_j = mu_j F_c,j / tau_max,j  (dimensionless)

linear in ``fl``, but the load torque depends on the unknowns (bilinear). Its estimate is the
model's own torque without this term, ``tau_load = W_b beta + tau_Stribeck`` with the torque
offsets left out (a sensor's offset is not carried by the gear), predicted by the fit without the
load term, which the fit with it extends (:func:`fit_load_friction`; :data:`LOAD_REFITS` > 1 refits
with the load torque of the previous fit with the term: its error, ``fl |tau|``, changes the column
by ``fl^2 |tau|``, second order, and on the simulated robots a second refit moved no base parameter
by more than 0.05 sigma). The simulated transmission's load is the total torque; the difference is
of the same second order. Using the fit's prediction rather than the measured torque keeps the
torque noise out of the column (no errors-in-variables bias). Its column is block-averaged like the
regressor: ``|tau_load|`` of the block times the block mean of ``tanh(v / w)``. The same load torque
is used wherever the term is evaluated (:func:`pipeline.robot.friction.load_friction_torque`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from pipeline.core.errors import SolverError
from pipeline.core.interrupts import raise_if_interrupted
from pipeline.core.solver_status import is_success
from pipeline.identification import estimate as est_mod
from pipeline.identification.measure import ProcessedData
from pipeline.identification.regressor import BaseParameters
from pipeline.identification.tx40 import heldout_validation
from pipeline.robot.friction import smooth_sign
from pipeline.robot.friction import stribeck_excess_torque as stribeck_torque

#: bounds of the Stribeck velocity [rad/s] (joint side)
VS_MIN_RAD_S = 1e-3
VS_MAX_RAD_S = 5.0
VS_START_RAD_S = 0.05
#: a joint's Stribeck term is kept when it lowers chi-squared by this much: the 0.1 % quantile of
#: chi-squared with 2 degrees of freedom (f_s, v_s), -2 ln(0.001)
MIN_CHI2_GAIN = 13.8
#: largest plausible static excess, as a fraction of the joint's torque limit (module doc)
MAX_EXCESS_OVER_LIMIT = 0.1
#: fits with the load-dependent term after the one without it, each with the load torque of the previous
LOAD_REFITS = 1
#: largest plausible load-dependent coefficient: a gear losing more than half the torque it carries to
#: friction (efficiency below about 2/3) is not a robot joint's; larger fits are refused (term dropped)
MAX_LOAD_COEFFICIENT = 0.5


@dataclass
class StribeckFit:
    beta: np.ndarray
    static_excess_Nm: np.ndarray  # fs per joint
    stribeck_velocity_rad_s: np.ndarray  # vs per joint
    coulomb_width_rad_s: float | np.ndarray
    status: str
    iterations: int
    #: per joint likelihood-ratio statistic of the Stribeck term (:func:`stribeck_chi2_gain`)
    chi2_gain: np.ndarray | None = None

    def stribeck_torque(self, v: np.ndarray) -> np.ndarray:
        """(N, nq) the Stribeck excess torque ``fs exp(-(v/vs)^2) tanh(v/w)``; for ``v`` of shape
        (N, k, nq) (:attr:`ProcessedData.v_blocks`) its mean over the k velocities of each sample."""
        st = stribeck_torque(v, self.static_excess_Nm, self.stribeck_velocity_rad_s, self.coulomb_width_rad_s)
        return st.mean(axis=1) if st.ndim == 3 else st

    def jacobian(self, v: np.ndarray) -> np.ndarray:
        """(N*nq, 2 k) columns d(torque)/d(fs_j, log vs_j) of the k kept terms (``fs_j > 0``), rows
        sample-major like the regressor; ``v`` (N, nq) or (N, m, nq) as in :meth:`stribeck_torque`.
        With the base regressor they form the Jacobian of the nested fit (its joint covariance)."""
        v3 = np.asarray(v, float)
        v3 = v3[:, None, :] if v3.ndim == 2 else v3
        n, _, nq = v3.shape
        sgn = smooth_sign(v3, self.coulomb_width_rad_s)
        u2 = (v3 / self.stribeck_velocity_rad_s) ** 2
        shape = (np.exp(-u2) * sgn).mean(axis=1)                      # d/d fs
        dlog = (self.static_excess_Nm * 2 * u2 * np.exp(-u2) * sgn).mean(axis=1)   # d/d log vs
        kept = np.flatnonzero(self.static_excess_Nm > 0)
        out = np.zeros((n, nq, 2 * len(kept)))
        for c, j in enumerate(kept):
            out[:, j, 2 * c], out[:, j, 2 * c + 1] = shape[:, j], dlog[:, j]
        return out.reshape(n * nq, -1)

    def predict(self, Wb: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(N, nq) torques of the base regressor ``Wb`` (sample-major rows) and velocities ``v``."""
        nq = np.asarray(v).shape[1]
        return (Wb @ self.beta).reshape(-1, nq) + self.stribeck_torque(v)


def fit_stribeck(
    Wb: np.ndarray, y: np.ndarray, v: np.ndarray, beta0: np.ndarray, joint_sigma_Nm: np.ndarray,
    coulomb_width_rad_s: float | np.ndarray, max_iter: int = 200, min_chi2_gain: float = MIN_CHI2_GAIN,
    max_excess_Nm: np.ndarray | None = None,
) -> StribeckFit:
    """Joint weighted least squares of ``beta``, ``fs``, ``vs`` (module doc); raises
    :class:`SolverError` unless IPOPT succeeds (KeyboardInterrupt when interrupted).

    ``v``: (n, nq) velocities of the samples, or (n, k, nq) when each sample (row block of ``Wb``
    and ``y``) is the mean of k samples (:attr:`ProcessedData.v_blocks`): the Stribeck term is then
    averaged the same way, which keeps the model exact at velocity reversals inside a block.

    A joint's term is kept only when it is significant: its likelihood-ratio statistic
    (:func:`stribeck_chi2_gain`) at least ``min_chi2_gain``; else its ``fs`` is set to 0 (no
    Stribeck term fitted to noise is handed on). ``max_excess_Nm``: upper bound of ``fs`` per joint
    (:data:`MAX_EXCESS_OVER_LIMIT` x the torque limit; None: unbounded)."""
    v = np.asarray(v, float)
    v3 = v[:, None, :] if v.ndim == 2 else v
    n, k, nq = v3.shape
    nb = Wb.shape[1]
    w_row = np.tile(1.0 / np.asarray(joint_sigma_Nm, float), n)
    A = ca.DM(Wb * w_row[:, None])
    b = ca.DM(np.asarray(y, float) * w_row)
    beta = ca.MX.sym("beta", nb)
    fs = ca.MX.sym("fs", nq)
    log_vs = ca.MX.sym("log_vs", nq)
    sgn = smooth_sign(v3, coulomb_width_rad_s)
    mean = ca.DM(np.full((k, 1), 1.0 / k))
    columns = []
    for j in range(nq):   # (n, k) per joint, averaged over the block: (n, 1)
        shape = ca.exp(-((ca.DM(v3[:, :, j]) * ca.exp(-log_vs[j])) ** 2)) * ca.DM(sgn[:, :, j])
        columns.append(fs[j] * ca.mtimes(shape, mean))
    st = ca.horzcat(*columns)  # (n, nq)
    st_w = ca.vec(st.T) * ca.DM(w_row)  # sample-major like y
    r = ca.mtimes(A, beta) + st_w - b
    x = ca.vertcat(beta, fs, log_vs)
    solver = ca.nlpsol("stribeck_fit", "ipopt", {"x": x, "f": 0.5 * ca.sumsqr(r)},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                        "ipopt.max_iter": max_iter, "ipopt.tol": 1e-8})
    vs_min = np.broadcast_to(np.maximum(VS_MIN_RAD_S, np.asarray(coulomb_width_rad_s, float)), (nq,))
    fs_max = np.full(nq, np.inf) if max_excess_Nm is None else np.asarray(max_excess_Nm, float)
    lbx = np.concatenate([np.full(nb, -np.inf), np.zeros(nq), np.log(vs_min)])
    ubx = np.concatenate([np.full(nb, np.inf), fs_max, np.full(nq, np.log(VS_MAX_RAD_S))])
    x0 = np.concatenate([np.asarray(beta0, float), np.zeros(nq), np.log(np.maximum(VS_START_RAD_S, vs_min))])
    sol = solver(x0=x0, lbx=lbx, ubx=ubx)
    stats = solver.stats()
    status = str(stats["return_status"])
    raise_if_interrupted(status, "Stribeck friction fit")
    if not is_success(status):
        raise SolverError(None, "identification.friction_model", f"IPOPT returned {status} for the Stribeck fit")
    xs = np.asarray(sol["x"]).ravel()
    fs, vs = np.clip(xs[nb : nb + nq], 0.0, fs_max), np.exp(xs[nb + nq :])
    fit = StribeckFit(beta=xs[:nb], static_excess_Nm=fs, stribeck_velocity_rad_s=vs,
                      coulomb_width_rad_s=coulomb_width_rad_s, status=status,
                      iterations=int(stats["iter_count"]))
    sigma = np.asarray(joint_sigma_Nm, float)
    gain = stribeck_chi2_gain(Wb, y, fit.stribeck_torque(v3), sigma)
    while np.any(drop := (fit.static_excess_Nm > 0) & (gain < min_chi2_gain)):  # the rest's gains without them
        fit.static_excess_Nm = np.where(drop, 0.0, fit.static_excess_Nm)
        gain = stribeck_chi2_gain(Wb, y, fit.stribeck_torque(v3), sigma)
    fit.chi2_gain = np.where(fit.static_excess_Nm > 0, gain, 0.0)
    if np.any(fit.static_excess_Nm != fs):   # terms dropped: the base parameters without them
        w = np.tile(1.0 / sigma, n)
        fit.beta = np.linalg.lstsq(Wb * w[:, None], (np.asarray(y, float) - fit.stribeck_torque(v3).ravel()) * w,
                                   rcond=None)[0]
    return fit


def stribeck_chi2_gain(Wb: np.ndarray, y: np.ndarray, st: np.ndarray, joint_sigma_Nm: np.ndarray) -> np.ndarray:
    """Per joint, the drop of the weighted residual sum of squares (the fit's own weights
    ``1 / joint_sigma_Nm``) that joint's Stribeck term ``st[:, j]`` buys, the base parameters
    refitted both ways: the likelihood-ratio statistic, chi-squared with 2 degrees of freedom
    (f_s, v_s) when the term is not there (Wilks). A negative gain means the term raises the
    residual: :func:`fit_stribeck` drops it (and every term below the threshold)."""
    n, nq = st.shape
    w = np.tile(1.0 / np.asarray(joint_sigma_Nm, float), n)
    Q, _ = np.linalg.qr(Wb * w[:, None])

    def ssr(rhs: np.ndarray) -> float:
        r = rhs * w
        return float(np.sum((r - Q @ (Q.T @ r)) ** 2))

    y = np.asarray(y, float)
    ssr_full = ssr(y - st.ravel())
    gain = np.empty(nq)
    for j in range(nq):
        without = st.copy()
        without[:, j] = 0.0
        gain[j] = ssr(y - without.ravel()) - ssr_full
    return gain


def stribeck_heldout(data: ProcessedData, base: BaseParameters, p_nominal: np.ndarray, nq: int,
                     train_fraction: float, regularization: float, max_iter: int,
                     coulomb_width_rad_s: float | np.ndarray,
                     field_name: str = "train_fraction", max_excess_Nm: np.ndarray | None = None,
                     ) -> dict[str, np.ndarray]:
    """Held-out predictions of the Stribeck model on a (non-periodic) record: Stribeck term fitted
    with the base parameters on the first ``train_fraction`` of the samples, taken off the torques,
    then :func:`~pipeline.identification.tx40.heldout_validation`'s fits; their predictions on the
    rest plus the Stribeck term (keys ``ols``, ``wls``, ``physical``)."""
    n_train, rows, Wb, wls = _train_part(data, base, train_fraction)
    vb = data.v_blocks
    fit = fit_stribeck(Wb[:rows], data.y[:rows], vb[:n_train], wls.beta, wls.joint_sigma_Nm, coulomb_width_rad_s,
                       max_excess_Nm=max_excess_Nm)
    return _heldout_less(data, fit.stribeck_torque(vb), base, p_nominal, nq, train_fraction, regularization,
                         max_iter, field_name)


def _train_part(data: ProcessedData, base: BaseParameters, train_fraction: float,
                ) -> tuple[int, int, np.ndarray, est_mod.LeastSquaresEstimate]:
    """Samples and rows of the first ``train_fraction`` of a record, the base regressor of all samples
    and the WLS fit on those rows."""
    n_train = int(train_fraction * data.n_samples)
    nr = data.tau.shape[1]
    Wb = base.base_regressor(data.Y)
    return n_train, n_train * nr, Wb, est_mod.wls(Wb[: n_train * nr], data.y[: n_train * nr], nr)


def _heldout_less(data: ProcessedData, friction_Nm: np.ndarray, base: BaseParameters, p_nominal: np.ndarray,
                  nq: int, train_fraction: float, regularization: float, max_iter: int,
                  field_name: str) -> dict[str, np.ndarray]:
    """:func:`~pipeline.identification.tx40.heldout_validation` on the torques less ``friction_Nm``
    (N, nr); its predictions on the held-out tail plus that friction."""
    ho = heldout_validation(replace(data, tau=data.tau - friction_Nm), base, p_nominal, nq, train_fraction,
                            regularization, max_iter, field_name, n_rows=data.tau.shape[1])
    return {k: pred + friction_Nm[ho.n_train:] for k, pred in ho.pred.items()}


def load_column_values(load_Nm: np.ndarray, v: np.ndarray, coulomb_width_rad_s: float | np.ndarray) -> np.ndarray:
    """(N, nr) ``|tau_load| tanh(v / w)`` per sample and joint (``sign`` for ``w = 0``); for ``v`` of
    shape (N, k, nr) (:attr:`ProcessedData.v_blocks`) the block mean of ``tanh`` times the block's load."""
    v3 = np.asarray(v, float)
    v3 = v3[:, None, :] if v3.ndim == 2 else v3
    sgn = smooth_sign(v3, coulomb_width_rad_s)
    return np.abs(np.asarray(load_Nm, float)) * sgn.mean(axis=1)


def load_columns(load_Nm: np.ndarray, v: np.ndarray, coulomb_width_rad_s: float | np.ndarray,
                 joints: np.ndarray) -> np.ndarray:
    """(N*nr, len(joints)) regressor columns of ``fl_j`` for the ``joints`` (column indices of the
    torques), rows sample-major like the base regressor (module doc)."""
    vals = load_column_values(load_Nm, v, coulomb_width_rad_s)
    n, nr = vals.shape
    out = np.zeros((n, nr, len(joints)))
    for c, j in enumerate(joints):
        out[:, j, c] = vals[:, j]
    return out.reshape(n * nr, -1)


@dataclass
class LoadFriction:
    """Load-dependent Coulomb friction ``fl |tau_load| tanh(v / w)`` per joint (module doc); ``fl = 0``:
    no term on that joint."""

    coefficient: np.ndarray
    coulomb_width_rad_s: float | np.ndarray
    #: per joint likelihood-ratio statistic of the term (chi-squared, 1 degree of freedom)
    chi2_gain: np.ndarray | None = None

    @property
    def joints(self) -> np.ndarray:
        return np.flatnonzero(self.coefficient != 0)

    def torque(self, load_Nm: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(N, nr) the term at load torques ``load_Nm`` (N, nr) and velocities ``v`` (N, nr) or (N, k, nr)."""
        return self.coefficient * load_column_values(load_Nm, v, self.coulomb_width_rad_s)

    def jacobian(self, load_Nm: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Columns d(torque)/d(fl_j) of the kept terms (with the base regressor: the joint covariance)."""
        return load_columns(load_Nm, v, self.coulomb_width_rad_s, self.joints)


@dataclass
class LoadFit:
    """The fit with the load-dependent term: base parameters, the Stribeck term refitted with it (None
    without one), the term and the load torque of its final column (N, nr)."""

    beta: np.ndarray
    stribeck: StribeckFit | None
    load: LoadFriction
    load_Nm: np.ndarray

    def torque(self, Wb: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(N, nr) the friction beyond the base regressor: Stribeck excess plus the load-dependent term."""
        st = 0.0 if self.stribeck is None else self.stribeck.stribeck_torque(v)
        return st + self.load.torque(self.load_Nm, v)


def load_free_torque(Wb: np.ndarray, beta: np.ndarray, offsets: np.ndarray, nr: int,
                     stribeck: StribeckFit | None, v: np.ndarray) -> np.ndarray:
    """(N, nr) the load torque of the module doc: the base model's torque ``Wb beta`` without the
    torque offsets (``offsets``: mask of the base parameters that are offsets), plus the Stribeck term."""
    torque = (Wb[:, ~offsets] @ np.asarray(beta, float)[~offsets]).reshape(-1, nr)
    return torque if stribeck is None else torque + stribeck.stribeck_torque(v)


def fit_load_friction(Wb: np.ndarray, y: np.ndarray, v: np.ndarray, beta0: np.ndarray,
                      stribeck0: StribeckFit | None, joint_sigma_Nm: np.ndarray,
                      coulomb_width_rad_s: float | np.ndarray,
                      offsets: np.ndarray, max_excess_Nm: np.ndarray | None = None) -> LoadFit:
    """Weighted least squares of ``beta`` and ``fl`` (module doc), nested in the fit ``beta0`` (with its
    Stribeck term ``stribeck0``, refitted jointly by :func:`fit_stribeck`; None: viscous + Coulomb).
    The load torque of each of the :data:`LOAD_REFITS` fits is the previous fit's
    :func:`load_free_torque`. Joints whose term is not physical (``fl <= 0``: friction falling with
    load; ``fl > MAX_LOAD_COEFFICIENT``) lose it and the rest is refitted once more with the same load
    torque. A term that is not significant is kept: on a joint whose load varies little its column is
    nearly the Coulomb one, so dropping it hardly changes the fit but moves ``fc`` (and the offset) by
    ``fl`` times the mean load, away from the zero-load Coulomb friction the parameter means.
    ``chi2_gain``: per joint likelihood-ratio statistic of the term (base parameters refitted both
    ways), reported."""
    sigma = np.asarray(joint_sigma_Nm, float)
    nr, nb = len(sigma), Wb.shape[1]
    beta, fit, joints = np.asarray(beta0, float), stribeck0, np.arange(nr)
    fl = np.zeros(nr)

    def solve(load: np.ndarray, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, StribeckFit | None]:
        A = np.hstack([Wb, load_columns(load, v, coulomb_width_rad_s, joints)])
        x0 = np.concatenate([beta, fl[joints]])
        if stribeck0 is None:
            x, out = est_mod.weighted_solution(A, y, sigma), None
        else:
            out = fit_stribeck(A, y, v, x0, sigma, coulomb_width_rad_s, max_excess_Nm=max_excess_Nm)
            x = out.beta
        coef = np.zeros(nr)
        coef[joints] = x[nb:]
        return x[:nb], coef, None if out is None else replace(out, beta=x[:nb])

    for _ in range(LOAD_REFITS):
        load = load_free_torque(Wb, beta, offsets, nr, fit, v)
        beta, fl, fit = solve(load, joints)
    term = LoadFriction(fl, coulomb_width_rad_s)
    st = 0.0 if fit is None else fit.stribeck_torque(v)
    gain = stribeck_chi2_gain(Wb, np.asarray(y, float) - np.ravel(np.broadcast_to(st, load.shape)),
                              term.torque(load, v), sigma)
    keep = (fl > 0) & (fl <= MAX_LOAD_COEFFICIENT)
    while not np.all(keep | (fl == 0)):     # drop and refit until every kept term is in its bounds
        beta, fl, fit = solve(load, np.flatnonzero(keep))
        keep &= (fl > 0) & (fl <= MAX_LOAD_COEFFICIENT)
    return LoadFit(beta, fit, LoadFriction(fl, coulomb_width_rad_s, np.where(keep, gain, 0.0)), load)


def load_heldout(data: ProcessedData, base: BaseParameters, p_nominal: np.ndarray, nq: int, train_fraction: float,
                 regularization: float, max_iter: int, coulomb_width_rad_s: float | np.ndarray, offsets: np.ndarray,
                 with_stribeck: bool, field_name: str = "train_fraction",
                 max_excess_Nm: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Held-out predictions of the load-dependent model on a (non-periodic) record, like
    :func:`stribeck_heldout`: the term (with the Stribeck term when ``with_stribeck``) fitted on the
    first ``train_fraction`` of the samples, its friction on every sample (load torque from that
    fit's base model, :func:`load_free_torque`) taken off the torques, then
    :func:`~pipeline.identification.tx40.heldout_validation`'s fits, their predictions plus it."""
    n_train, rows, Wb, wls = _train_part(data, base, train_fraction)
    vb = data.v_blocks
    fit0 = (fit_stribeck(Wb[:rows], data.y[:rows], vb[:n_train], wls.beta, wls.joint_sigma_Nm, coulomb_width_rad_s,
                         max_excess_Nm=max_excess_Nm) if with_stribeck else None)
    lf = fit_load_friction(Wb[:rows], data.y[:rows], vb[:n_train], wls.beta if fit0 is None else fit0.beta, fit0,
                           wls.joint_sigma_Nm, coulomb_width_rad_s, offsets, max_excess_Nm)
    lf.load_Nm = load_free_torque(Wb, lf.beta, offsets, data.tau.shape[1], lf.stribeck, vb)
    return _heldout_less(data, lf.torque(Wb, vb), base, p_nominal, nq, train_fraction, regularization, max_iter,
                         field_name)


def expand_to_joints(fit: StribeckFit, used: np.ndarray, nq: int) -> StribeckFit:
    """The fit of the measured joints ``used`` as a fit of all ``nq`` joints (no Stribeck term on
    the others)."""
    fs, vs = np.zeros(nq), np.full(nq, VS_START_RAD_S)
    fs[used], vs[used] = fit.static_excess_Nm, fit.stribeck_velocity_rad_s
    return replace(fit, static_excess_Nm=fs, stribeck_velocity_rad_s=vs, chi2_gain=None)


def load_summary(load: LoadFriction, status: str, per_joint: Callable[[np.ndarray], list] = list) -> dict:
    """Summary entries of the load-dependent candidate: ``fl`` per joint (0: no term), its likelihood-ratio
    gains and the status of its physically consistent fit. JSON-able."""
    return {"load_friction_coefficient": per_joint(load.coefficient),
            "load_friction_coefficient_bound": MAX_LOAD_COEFFICIENT,
            "load_friction_chi2_gain": None if load.chi2_gain is None else per_joint(load.chi2_gain),
            "load_friction_status": status}


def best_friction_model(rms_Nm: dict[str, np.ndarray], sigma_Nm: np.ndarray | None) -> str:
    """The model whose held-out RMS / noise sigma is smallest on average over the joints scored (a
    joint the validation could not score, NaN, left out of every model's average alike)."""
    sigma = np.ones_like(next(iter(rms_Nm.values()))) if sigma_Nm is None else np.asarray(sigma_Nm, float)

    def mean_ratio(rms: np.ndarray) -> float:
        ratio = np.asarray(rms, float) / sigma
        return float(np.mean(ratio[np.isfinite(ratio)])) if np.any(np.isfinite(ratio)) else float("inf")
    return min(rms_Nm, key=lambda k: mean_ratio(rms_Nm[k]))


def friction_summary(rms_Nm: dict[str, np.ndarray], sigma_Nm: np.ndarray | None, fit: StribeckFit | None,
                     per_joint: Callable[[np.ndarray], list] = list,
                     torque_limit_Nm: np.ndarray | None = None) -> dict:
    """Summary entries of the friction models scored on the same held-out torques: per joint RMS
    (``friction_heldout_rms_Nm``), RMS / noise sigma, the model with the smaller mean RMS / sigma
    (``friction_model_best``, the one handed on) and the Stribeck fit with its static excess over the
    torque limit (no Stribeck entries without a fit). ``per_joint`` maps a value per measured joint to
    the list over all joints (None where unmeasured). JSON-able."""
    sigma = np.ones_like(next(iter(rms_Nm.values()))) if sigma_Nm is None else np.asarray(sigma_Nm, float)
    best = best_friction_model(rms_Nm, sigma_Nm)
    lim = np.full(len(sigma), np.nan) if torque_limit_Nm is None else np.asarray(torque_limit_Nm, float)
    return {
        "friction_heldout_rms_Nm": {k: per_joint(np.asarray(r, float)) for k, r in rms_Nm.items()},
        "friction_heldout_rms_over_noise": {k: per_joint(np.asarray(r, float) / sigma) for k, r in rms_Nm.items()},
        "friction_model_best": best,
    } | ({} if fit is None else {
        "stribeck_static_excess_Nm": per_joint(fit.static_excess_Nm),
        "stribeck_static_excess_over_limit": per_joint(fit.static_excess_Nm / lim),
        "stribeck_static_excess_bound_over_limit": MAX_EXCESS_OVER_LIMIT,
        "stribeck_velocity_rad_s": per_joint(fit.stribeck_velocity_rad_s),
        "stribeck_status": fit.status,
        "stribeck_chi2_gain": None if fit.chi2_gain is None else per_joint(fit.chi2_gain),
    })


__all__ = ["LOAD_REFITS", "MAX_EXCESS_OVER_LIMIT", "MAX_LOAD_COEFFICIENT", "LoadFit",
           "LoadFriction", "StribeckFit", "best_friction_model", "expand_to_joints", "fit_load_friction",
           "fit_stribeck", "friction_summary", "load_columns", "load_free_torque", "load_heldout", "load_summary",
           "stribeck_heldout", "stribeck_torque"]
