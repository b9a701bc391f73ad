"""The calibration's non-geometric residual map: a Gaussian-process correction of the TCP position
over joint space, handed on with the calibrated model (no scikit-learn needed to apply it).

What no rigid or elastostatic parameter explains (gear eccentricity, thermal drift, cable forces)
leaves a smooth position error ``d(q)`` in the base frame. The calibration fits a zero-mean
Gaussian process per axis with a shared squared-exponential kernel (Rasmussen & Williams,
*Gaussian Processes for Machine Learning*, MIT Press 2006, eq. 2.31)

    k(q, q') = s^2 exp(-|q - q'|^2 / (2 l^2)),   observations  d_k + n_k,  n_k ~ N(0, s_n^2 I),

hyperparameters ``s, l, s_n`` by the log marginal likelihood (ibid. §5.4.1). The posterior at a
configuration ``q*`` (ibid. Algorithm 2.1, with ``L = chol(K + s_n^2 I)``, ``alpha = L^T \\ (L \\ D)``):

    mean  d(q*) = k*^T alpha,     variance  s^2 - |L \\ k*|^2   (per axis, the same for the three).

:meth:`ResidualMap.correct` adds the mean to base-frame TCP positions; :meth:`ResidualMap.predict`
gives its standard deviation, which joins the model's predicted error. Far from the calibration
poses the correction fades to zero and its variance grows back to ``s^2``: the map never claims
knowledge it does not have.

Support. A long length scale ``l`` (the marginal likelihood's choice when the residual is smooth
over the calibration poses) would carry the GP's mean far beyond them, where nothing was measured.
The mean is therefore tapered by the calibration poses' density at the support radius ``r``
(a multiple of the largest nearest-neighbour distance among the poses,
:func:`pipeline.calibration.residual_map.support_radius_rad`)

    rho(q) = sum_i exp(-|q - q_i|^2 / (2 r^2)),    w(q) = 1 - exp(-c rho(q)),

so ``w ~ 1`` among the poses and ``w -> 0`` outside them: the corrected model falls back to the
geometric (or elastostatic) model. The tapered mean ``w m`` of a residual ``d`` with prior variance
``s^2`` and posterior ``N(m, v)`` has the error variance ``E(d - w m)^2 = v + (1 - w)^2 (s^2 - v)``
(``E m^2 = s^2 - v`` under the prior): the stated uncertainty widens to the prior's outside the
support. Without a radius (maps saved before it) ``w = 1``.

Later stages' kinematics (:class:`pipeline.robot.model.RobotModel` carries the map of a calibrated
robot; its tool frames' positions, Jacobian and the IK of :mod:`pipeline.robot.paths` and
:mod:`pipeline.robot.reference` add it) need the mean's derivatives, in closed form for the
squared-exponential kernel with ``d_i = q - q_i``, ``k_i = k(q, q_i)``:

    d mean / dq = -sum_i alpha_i k_i d_i^T / l^2,
    v^T (d^2 mean / dq^2) v = sum_i alpha_i k_i ((d_i . v)^2 / l^4 - |v|^2 / l^2)

(the second is the map's share of the drift ``J_dot v`` of a joint-space velocity ``v``). With the
taper, ``g_i = exp(-|d_i|^2 / (2 r^2))``, ``e = c exp(-c rho)``:

    grad rho = -sum_i g_i d_i / r^2,   v^T H_rho v = sum_i g_i ((d_i . v)^2 / r^4 - |v|^2 / r^2),
    grad w = e grad rho,               v^T H_w v = e (v^T H_rho v - c (grad rho . v)^2),
    d (w m) / dq = w dm/dq + m grad w^T,
    v^T H_(w m) v = w v^T H_m v + 2 (dm/dq v)(grad w . v) + m v^T H_w v.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

__all__ = ["ResidualMap"]

#: ``c`` of the taper ``w = 1 - exp(-c rho)`` (module docstring): one pose at the query gives w = 0.95
SUPPORT_GAIN = 3.0


@dataclass(frozen=True)
class ResidualMap:
    """GP posterior of the base-frame TCP position residual (module docstring)."""

    inputs_rad: np.ndarray            # (n, nq) joint configurations of the training poses
    alpha_m: np.ndarray               # (n, 3) ``(K + s_n^2 I)^-1 D``
    cholesky: np.ndarray              # (n, n) lower factor of ``K + s_n^2 I`` (m^2)
    length_scale_rad: float           # l
    signal_std_m: float               # s
    noise_std_m: float                # s_n, the reading noise and what the map does not explain
    #: r of the taper (module docstring); None: no taper
    support_radius_rad: float | None = None

    KEYS = {"inputs_rad": "residual_map_inputs_rad", "alpha_m": "residual_map_alpha_m",
            "cholesky": "residual_map_cholesky"}

    def _cross(self, Q: np.ndarray) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, float))
        d2 = ((Q[:, None, :] - self.inputs_rad[None, :, :]) ** 2).sum(-1)
        return self.signal_std_m ** 2 * np.exp(-0.5 * d2 / self.length_scale_rad ** 2)

    def _taper(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``w`` (N,), ``g_i`` (N, n) and the offsets ``d_i = q - q_i`` (N, n, nq) of the taper."""
        Q = np.atleast_2d(np.asarray(Q, float))
        d = Q[:, None, :] - self.inputs_rad[None, :, :]
        if self.support_radius_rad is None:
            return np.ones(len(Q)), np.zeros(d.shape[:2]), d
        g = np.exp(-0.5 * (d ** 2).sum(-1) / self.support_radius_rad ** 2)
        return 1.0 - np.exp(-SUPPORT_GAIN * g.sum(1)), g, d

    def support_weight(self, Q: np.ndarray) -> np.ndarray:
        """``(N,)`` taper ``w`` of the mean (module docstring): 1 among the calibration poses, 0 far away."""
        return self._taper(Q)[0]

    def predict(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean ``(N, 3)`` (m, base frame), tapered outside the support, and the standard
        deviation per axis ``(N,)`` (m) of the residual left after it (module docstring)."""
        k = self._cross(Q)
        mean = k @ self.alpha_m
        v = np.linalg.solve(self.cholesky, k.T)
        s2 = self.signal_std_m ** 2
        var = np.maximum(s2 - (v ** 2).sum(0), 0.0)
        w = self._taper(Q)[0]
        return w[:, None] * mean, np.sqrt(var + (1.0 - w) ** 2 * (s2 - var))

    def predict_reading(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`predict`'s mean ``(N, 3)`` and the standard deviation per axis ``(N,)`` (m) of a
        new reading's residual once the map is applied: ``sqrt(v(q) + s_n^2)``, the posterior
        (tapered) variance and the noise the map did not explain (Rasmussen & Williams 2006, §2.2:
        the predictive variance of a noisy target adds ``s_n^2``). ``s_n`` takes the place of the
        reading noise the rigid model's remainder stated: that remainder also held the smooth part
        the map now explains, which would count twice beside the posterior variance."""
        mean, std = self.predict(Q)
        return mean, np.sqrt(std ** 2 + self.noise_std_m ** 2)

    def mean(self, q: np.ndarray) -> np.ndarray:
        """Posterior mean ``(3,)`` (m, base frame) at one configuration, tapered."""
        return self._taper(q)[0][0] * (self._cross(q)[0] @ self.alpha_m)

    def _taper_derivatives(self, q: np.ndarray, v: np.ndarray | None) -> tuple[float, np.ndarray, float]:
        """``w``, ``grad w`` (nq,) and ``v^T H_w v`` at one configuration (0 without ``v``)."""
        w, g, d = self._taper(q)
        if self.support_radius_rad is None:
            return 1.0, np.zeros(self.inputs_rad.shape[1]), 0.0
        r2 = self.support_radius_rad ** 2
        g, d = g[0], d[0]
        e = SUPPORT_GAIN * (1.0 - float(w[0]))
        grad_rho = -(g[:, None] * d).sum(0) / r2
        if v is None:
            return float(w[0]), e * grad_rho, 0.0
        h_rho = float(np.sum(g * ((d @ v) ** 2 / r2 ** 2 - float(v @ v) / r2)))
        return float(w[0]), e * grad_rho, e * (h_rho - SUPPORT_GAIN * float(grad_rho @ v) ** 2)

    def _plain_jacobian(self, q: np.ndarray) -> np.ndarray:
        d = np.asarray(q, float)[None, :] - self.inputs_rad
        k = self._cross(q)[0]
        return -(self.alpha_m * k[:, None]).T @ d / self.length_scale_rad ** 2

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """``(3, nq)`` derivative of the tapered mean at one configuration (module docstring)."""
        w, grad_w, _ = self._taper_derivatives(q, None)
        m = self._cross(q)[0] @ self.alpha_m
        return w * self._plain_jacobian(q) + np.outer(m, grad_w)

    def drift(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``(3,)`` second derivative of the tapered mean along the joint velocity ``v`` (module docstring)."""
        d = np.asarray(q, float)[None, :] - self.inputs_rad
        v = np.asarray(v, float)
        l2 = self.length_scale_rad ** 2
        k = self._cross(q)[0]
        h_m = (k * ((d @ v) ** 2 / l2 ** 2 - float(v @ v) / l2)) @ self.alpha_m
        w, grad_w, h_w = self._taper_derivatives(q, v)
        m = k @ self.alpha_m
        return w * h_m + 2.0 * (self._plain_jacobian(q) @ v) * float(grad_w @ v) + m * h_w

    def correct(self, positions_m: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Base-frame positions ``(N, 3)`` of the calibrated model at ``Q`` plus the mapped residual."""
        return np.asarray(positions_m, float) + self.predict(Q)[0]

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The ``results.npz`` entries of the map."""
        out = {key: np.asarray(getattr(self, name)) for name, key in self.KEYS.items()}
        radius = np.nan if self.support_radius_rad is None else self.support_radius_rad
        out["residual_map_hyperparameters"] = np.array([self.length_scale_rad, self.signal_std_m, self.noise_std_m,
                                                        radius])
        return out

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> ResidualMap | None:
        """The map in a stage's arrays; None when the calibration handed none on."""
        if cls.KEYS["alpha_m"] not in arrays:
            return None
        hyper = [float(v) for v in np.asarray(arrays["residual_map_hyperparameters"], float)]
        length, signal, noise = hyper[:3]
        radius = hyper[3] if len(hyper) > 3 and np.isfinite(hyper[3]) else None   # maps saved before: no taper

        def get(name: str) -> np.ndarray:
            return np.asarray(arrays[cls.KEYS[name]], float)

        return cls(get("inputs_rad"), get("alpha_m"), get("cholesky"), length, signal, noise, radius)
