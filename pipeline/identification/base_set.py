"""Structural base-parameter set: decided on the nominal model, used on the current one.

Which standard-parameter combinations are identifiable is a property of the robot's *structure*
(joint axes, which links carry which parameters, Gautier 1990; Khalil & Dombre), not of
micrometre differences between the nominal and a calibrated (or a reloaded) model. A column-
pivoted QR of the regressor stacked on random states of the *nominal* model (``Y P = Q R``,
columns normalised) keeps the columns with ``|R_kk| > tolerance |R_00|``. The default
:data:`STRUCTURAL_BASE_TOLERANCE` = 1e-3 is meaningful for noisy data: a direction with a smaller
relative ``R_kk`` would amplify the torque noise more than a thousandfold in its estimate (on the
RX130L the nominal gap is 0.56 -> 2e-15, while millimetre calibration errors create an extra
direction at 7e-4 that the fit must not chase).

With the independent columns ``I`` fixed, the combination of the dependent ones ``D`` for the
*current* model is the least-squares ``M = argmin ||Y_I M - Y_D||`` on the same random states
(``Y p ~= Y_I (p_I + M p_D)``), so base values of the current model's parameters stay exact
for the combinations that exist and the set (names, count) is the same for the nominal, a
calibrated and a reloaded calibrated model.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from pipeline.identification.regressor import (
    ZERO_COLUMN_TOLERANCE,
    BaseParameters,
    RegressorModel,
    base_parameters_from_regressor,
)

#: relative |R_kk| / |R_00| (normalised columns) below which a direction is not identifiable
STRUCTURAL_BASE_TOLERANCE = 1e-3


def random_states(
    rng: np.random.Generator, nv: int, n_samples: int, lower: np.ndarray | None, upper: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q uniform in the limits (±pi without), v ~ N(0, 2²), a ~ N(0, 5²)."""
    lo = -np.pi * np.ones(nv) if lower is None else np.asarray(lower, float)
    hi = np.pi * np.ones(nv) if upper is None else np.asarray(upper, float)
    Q = rng.uniform(lo, hi, size=(n_samples, nv))
    V = rng.normal(size=(n_samples, nv)) * 2.0
    A = rng.normal(size=(n_samples, nv)) * 5.0
    return Q, V, A


def structural_base_parameters(
    reg_nominal: RegressorModel,
    reg_current: RegressorModel,
    rng: np.random.Generator,
    n_samples: int = 300,
    tolerance: float = STRUCTURAL_BASE_TOLERANCE,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
) -> tuple[BaseParameters, BaseParameters]:
    """``(nominal, current)`` base parameters with the same independent set (see module doc).

    ``nominal`` is the pivoted QR of the nominal regressor; ``current`` keeps its independent
    columns and fits the combination of the dependent ones on the current model's regressor.
    """
    if reg_nominal.n_parameters != reg_current.n_parameters:
        raise ValueError("nominal and current model differ in structure (number of parameters)")
    Q, V, A = random_states(rng, reg_nominal.nv, n_samples, lower, upper)
    nominal = base_parameters_from_regressor(reg_nominal.stacked(Q, V, A), reg_nominal.names, tolerance)
    Y = reg_current.stacked(Q, V, A)
    return nominal, base_with_set(Y, nominal)


def base_with_set(Y: np.ndarray, structure: BaseParameters) -> BaseParameters:
    """Base parameters of regressor ``Y`` with ``structure``'s independent columns (least-squares
    combination of the dependent ones, in normalised columns so units do not matter)."""
    indep, dep = structure.independent, structure.dependent
    norms = np.linalg.norm(Y, axis=0)
    scale = np.where(norms <= ZERO_COLUMN_TOLERANCE * max(norms.max(), 1e-300), 1.0, norms)
    if len(dep):
        Ys = Y / scale
        comb_s = scipy.linalg.lstsq(Ys[:, indep], Ys[:, dep])[0]
        comb = comb_s * scale[dep][None, :] / scale[indep][:, None]
        comb[np.abs(comb) < 1e-10] = 0.0
    else:
        comb = np.zeros((len(indep), 0))
    return BaseParameters(
        independent=indep.copy(),
        dependent=dep.copy(),
        combination=comb,
        standard_names=list(structure.standard_names),
        tolerance=structure.tolerance,
        rank_gap=structure.rank_gap,
    )


#: the excitation's base set is shrunk until its condition number is this factor below
#: ``identification.max_cond_base_regressor_data``: the measured data (noise, filtering, decimation)
#: are checked against the bound itself and must still clear it
DESIGN_COND_MARGIN = 10.0


def columns_over_condition(Wb: np.ndarray, max_cond: float) -> np.ndarray:
    """Positions (into the base set) of the columns of the base regressor ``Wb`` to leave out so that
    the rest has ``cond <= max_cond``: a column-pivoted QR of ``Wb`` (in its own units, as the design
    criterion and the data gate measure it) orders the columns by what each adds beyond the ones
    before it; the longest leading run of that order with ``cond(Wb[:, run]) <= max_cond`` is kept
    (the condition number of a leading run grows with its length, singular-value interlacing), the
    rest is returned (sorted; empty when ``cond(Wb) <= max_cond``)."""
    _, _, piv = scipy.linalg.qr(np.asarray(Wb, float), mode="economic", pivoting=True)

    def cond(k: int) -> float:
        s = np.linalg.svd(Wb[:, piv[:k]], compute_uv=False)
        return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")

    lo, hi = 1, Wb.shape[1]          # cond(first column) = 1
    if cond(hi) <= max_cond:
        return np.zeros(0, int)
    while hi - lo > 1:               # largest k with cond(k) <= max_cond lies in [lo, hi)
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if cond(mid) <= max_cond else (lo, mid)
    return np.sort(piv[lo:])


def without_columns(base: BaseParameters, drop: np.ndarray, Y: np.ndarray) -> BaseParameters:
    """``base`` with its independent columns at positions ``drop`` moved to the dependent set.

    Each left-out column of the base regressor ``W_D`` is replaced by its least-squares combination
    of the kept ones on the standard regressor ``Y`` (normalised columns), ``W_D ~= W_K C``; then
    ``W beta ~= W_K (beta_K + C beta_D)``, so the new base parameters are ``beta_K + C beta_D``: the
    kept standard columns ``p_K`` with combination ``M_K + C M_D`` of the old dependents ``p_old`` and
    ``C`` of the left-out columns ``p_D`` (``M``: ``base.combination``)."""
    drop = np.asarray(drop, int)
    keep = np.setdiff1d(np.arange(base.n_base), drop)
    if not len(drop):
        return base
    W = base.base_regressor(np.asarray(Y, float))
    norms = np.linalg.norm(W, axis=0)
    scale = np.where(norms > 0, norms, 1.0)
    C_s = scipy.linalg.lstsq(W[:, keep] / scale[keep], W[:, drop] / scale[drop])[0]
    C = C_s * scale[drop][None, :] / scale[keep][:, None]
    M = base.combination
    comb_old = M[keep] + C @ M[drop] if M.shape[1] else np.zeros((len(keep), 0))
    dependent = np.concatenate([base.dependent, base.independent[drop]])
    combination = np.hstack([comb_old, C])
    order = np.argsort(dependent)
    combination = combination[:, order]
    combination[np.abs(combination) < 1e-10] = 0.0
    return BaseParameters(independent=base.independent[keep].copy(), dependent=dependent[order],
                          combination=combination, standard_names=list(base.standard_names),
                          tolerance=base.tolerance, rank_gap=base.rank_gap)
