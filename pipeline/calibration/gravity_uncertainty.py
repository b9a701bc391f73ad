"""Gravity-model uncertainty in the measurement covariance of the elastostatic calibration.

The elastostatic model reads ``q_link = q - C g(q)`` with the gravity torques ``g`` of the dynamic
model in use (nominal, or identified: :mod:`pipeline.calibration.elastostatic`). ``g`` is linear
in the inertial parameters ``pi`` (Pinocchio's joint-torque regressor at ``v = a = 0``:
``g(q) = Y_g(q) pi``, only the mass and first-moment columns ``m, m c`` are non-zero). An error
``d pi`` of the model moves a reading by ``dy = (dy/dtau) Y_g(q) d pi`` with
``dy/dtau = -(dy/dq_link) C`` (exact CasADi Jacobian, :meth:`MeasurementModel.torque_jacobian`),
so a reading's covariance is

``Sigma_k = sigma_k^2 I + A_k Sigma_pi A_k^T``,  ``A_k = (dy/dtau)_k Y_g(q_k)``.

Prior ``Sigma_pi`` per body (linearised, independent log-normal mass error ``s`` and isotropic
COM error ``sigma_c``): ``d m = s m eps``, ``d(m c) = c d m + m d c``, i.e. the (m, m c) block
``[[s^2 m^2, s^2 m^2 c^T], [s^2 m^2 c, s^2 m^2 c c^T + m^2 sigma_c^2 I]]``. The COM term is the
absolute floor of first moments whose nominal value is ~0 (a centred COM). Defaults
(``calibration.gravity_model_relative_sigma`` 0.15, ``gravity_model_com_sigma_m`` 0.02 m) are the
typical data-sheet/CAD uncertainty of a robot's inertial parameters (DESIGN.md: "inertial
parameters 10-20 %"; the simulated truth draws the same magnitudes, pipeline.sim.truth). With
an identified gravity model (``calibration.gravity_model``) both are multiplied by
``gravity_model_identified_scale``. The payload is known (config) and adds no uncertainty.

The deflection errors of different readings are correlated through the common ``d pi``
(``Sigma = D + B B^T`` over all stacked readings, ``B_k = A_k L``, ``Sigma_pi = L L^T = Cov(d pi)``,
``d pi = L z``, rank ``r = 4 nb``). The fit weights each reading by its own 3x3 block
``Sigma_k = sigma_k^2 I + B_k B_k^T`` (*block-diagonal approximation* of the weights,
:class:`Whitener`): the exact generalised least squares would attribute the gravity-like part of
the residuals to ``z``, which the calibrated model (used with the nominal gravity model) does not
carry, and predicts held-out poses worse; the weighted fit instead absorbs the part of ``d pi`` that
acts like a compliance change into the compliances. The error propagation is exact for this
estimator (sandwich): ``theta_hat - theta = K (B z + n)``, ``K = (J^T W^T W J)^-1 J^T W^T W``,
``Cov = K D K^T + M M^T`` with the gain ``M = K B``, and a held-out reading's error is
``e_h = (B_h - J_h M) z - J_h K n + n_h`` (:mod:`pipeline.calibration.validate`); the
cross-reading correlations are kept there. The outlier test uses each reading's block ``Sigma_k``. With ``C = 0``
(rigid model, or compliances fitted to zero) the term vanishes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.calibration.error_model import MeasurementModel


@dataclass(frozen=True)
class GravityPrior:
    """Prior uncertainty of the gravity model's inertial parameters (module docstring)."""

    mass_relative_sigma: float
    com_sigma_m: float

    @property
    def is_zero(self) -> bool:
        return self.mass_relative_sigma == 0.0 and self.com_sigma_m == 0.0

    def parameter_covariance(self, model: pin.Model) -> np.ndarray:
        """``(10 nb, 10 nb)`` covariance of Pinocchio's dynamic parameters ``[m, m c, I]`` per body
        (second moments: zero, they do not enter ``g``)."""
        nb = model.njoints - 1
        S = np.zeros((10 * nb, 10 * nb))
        for j in range(nb):
            inertia = model.inertias[j + 1]
            m, c = float(inertia.mass), np.asarray(inertia.lever, float)
            v = np.concatenate([[m], m * c]) * self.mass_relative_sigma   # d(m, m c) from d m
            block = np.outer(v, v)
            block[1:, 1:] += (m * self.com_sigma_m) ** 2 * np.eye(3)
            S[10 * j : 10 * j + 4, 10 * j : 10 * j + 4] = block
        return S

    def factor(self, model: pin.Model) -> tuple[np.ndarray, np.ndarray | None]:
        """``(cols, L)``: the columns of Pinocchio's dynamic parameters the prior covers (masses and
        first moments with a non-zero variance) and ``L`` with ``L L^T`` their covariance, so that an
        error of those parameters is ``d pi[cols] = L z`` with ``z ~ N(0, I)``; ``L`` None when the
        prior covers none."""
        S = self.parameter_covariance(model)
        cols = np.flatnonzero(np.diag(S) > 0)
        L = np.linalg.cholesky(S[np.ix_(cols, cols)] + 1e-300 * np.eye(len(cols))) if len(cols) else None
        return cols, L


def gravity_regressor(model: pin.Model, Q: np.ndarray) -> np.ndarray:
    """``(N, nv, 10 nb)`` regressor with ``g(q) = Y_g(q) pi`` (``computeJointTorqueRegressor``,
    ``v = a = 0``)."""
    Q = np.atleast_2d(np.asarray(Q, float))
    data = model.createData()
    zero = np.zeros(model.nv)
    return np.array([pin.computeJointTorqueRegressor(model, data, q, zero, zero).copy() for q in Q])


class GravityCovariance:
    """Per-reading gravity-model covariance blocks of a measurement model (module docstring)."""

    def __init__(self, mm: MeasurementModel, prior: GravityPrior) -> None:
        self.mm = mm
        self.prior = prior
        self._cols, self._L = prior.factor(mm.gravity_model)

    @property
    def active(self) -> bool:
        return self.mm.compliance and self._L is not None

    def factors(self, Q: np.ndarray, x: np.ndarray, T0: pin.SE3, mounted: np.ndarray | None = None,
                offsets: np.ndarray | None = None) -> np.ndarray:
        """``(N, 3, r)`` factors ``B_k = A_k L`` with ``A_k Sigma_pi A_k^T = B_k B_k^T``; negative
        compliances of ``x`` count as zero (a compliance is non-negative)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        if not self.active:
            return np.zeros((len(Q), 3, 0))
        x = np.asarray(x, float).copy()
        x[self.mm.sl_compliance] = np.maximum(x[self.mm.sl_compliance], 0.0)
        D = self.mm.torque_jacobian(Q, x, T0, mounted, offsets)                 # (N, 3, nq)
        Yg = gravity_regressor(self.mm.gravity_model, Q)[:, :, self._cols]      # (N, nq, r)
        return np.einsum("nij,njr,rs->nis", D, Yg, self._L)

    def blocks(self, Q: np.ndarray, x: np.ndarray, T0: pin.SE3, mounted: np.ndarray | None = None,
               offsets: np.ndarray | None = None) -> np.ndarray:
        """``(N, 3, 3)`` gravity-model covariance ``A_k Sigma_pi A_k^T`` of each reading."""
        B = self.factors(Q, x, T0, mounted, offsets)
        return np.einsum("nir,njr->nij", B, B)



class Whitener:
    """Whitening of readings with covariance ``Sigma_k = sigma_k^2 I + B_k B_k^T`` in the
    block-diagonal approximation (module docstring): ``r_k = W_k e_k``, ``W_k = L_k^-1``,
    ``Sigma_k = L_k L_k^T``. Without factors: ``e_k / sigma_k``."""

    def __init__(self, sigma: np.ndarray, factors: np.ndarray | None = None) -> None:
        self.sigma = np.asarray(sigma, float)
        self.factors = None if factors is None or factors.shape[2] == 0 else np.asarray(factors, float)
        self.W: np.ndarray | None = None
        if self.factors is not None:
            B = self.factors
            blocks = self.sigma[:, None, None] ** 2 * np.eye(3) + np.einsum("nir,njr->nij", B, B)
            self.W = np.linalg.inv(np.linalg.cholesky(blocks))

    def vector(self, e: np.ndarray) -> np.ndarray:
        """Whitened stacked residual ``(3N,)`` of ``e`` (N, 3)."""
        if self.W is not None:
            return np.einsum("nij,nj->ni", self.W, e).reshape(-1)
        return (e / self.sigma[:, None]).reshape(-1)

    def matrix(self, J: np.ndarray) -> np.ndarray:
        """Whitened stacked Jacobian ``(3N, p)`` of blocks ``J`` (N, 3, p)."""
        p = J.shape[2]
        if self.W is not None:
            return np.einsum("nij,njp->nip", self.W, J).reshape(-1, p)
        return (J / self.sigma[:, None, None]).reshape(-1, p)

    def reading_norm(self, e: np.ndarray) -> np.ndarray:
        """``(N,)`` ``sqrt(e_k^T Sigma_k^-1 e_k)`` (chi-square, 3 dof, for a good reading)."""
        return np.linalg.norm(self.vector(e).reshape(-1, 3), axis=1)

    def sandwich(self, Jw: np.ndarray, information_inverse: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Covariance of the weighted least-squares estimate ``theta_hat - theta = K (B z + n)``,
        ``K = A^-1 J^T W^T W`` (``A^-1`` = ``information_inverse`` of the whitened ``Jw``), and the gain
        ``M = K B`` (p, r) (None without factors): ``Cov = K D K^T + M M^T``."""
        if self.factors is None:
            return information_inverse, None
        M = information_inverse @ Jw.T @ self.matrix(self.factors)
        WD = self.matrix(self.sigma[:, None, None] * np.eye(3)[None])      # (3N, 3) blocks W_k sigma_k
        G = (Jw.reshape(len(self.sigma), 3, -1).transpose(0, 2, 1) @ WD.reshape(len(self.sigma), 3, 3))  # (N,p,3)
        KD = np.einsum("pq,nqi->npi", information_inverse, G)
        C = np.einsum("npi,nqi->pq", KD, KD) + M @ M.T
        return 0.5 * (C + C.T), M
