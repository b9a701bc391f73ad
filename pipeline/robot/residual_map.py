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

Later stages' kinematics (:class:`pipeline.robot.model.RobotModel` carries the map of a calibrated
robot; its tool frames' positions, Jacobian and the IK of :mod:`pipeline.robot.paths` and
:mod:`pipeline.robot.reference` add it) need the mean's derivatives, in closed form for the
squared-exponential kernel with ``d_i = q - q_i``, ``k_i = k(q, q_i)``:

    d mean / dq = -sum_i alpha_i k_i d_i^T / l^2,
    v^T (d^2 mean / dq^2) v = sum_i alpha_i k_i ((d_i . v)^2 / l^4 - |v|^2 / l^2)

(the second is the map's share of the drift ``J_dot v`` of a joint-space velocity ``v``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

__all__ = ["ResidualMap"]


@dataclass(frozen=True)
class ResidualMap:
    """GP posterior of the base-frame TCP position residual (module docstring)."""

    inputs_rad: np.ndarray            # (n, nq) joint configurations of the training poses
    alpha_m: np.ndarray               # (n, 3) ``(K + s_n^2 I)^-1 D``
    cholesky: np.ndarray              # (n, n) lower factor of ``K + s_n^2 I`` (m^2)
    length_scale_rad: float           # l
    signal_std_m: float               # s
    noise_std_m: float                # s_n, the reading noise and what the map does not explain

    KEYS = {"inputs_rad": "residual_map_inputs_rad", "alpha_m": "residual_map_alpha_m",
            "cholesky": "residual_map_cholesky"}

    def _cross(self, Q: np.ndarray) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, float))
        d2 = ((Q[:, None, :] - self.inputs_rad[None, :, :]) ** 2).sum(-1)
        return self.signal_std_m ** 2 * np.exp(-0.5 * d2 / self.length_scale_rad ** 2)

    def predict(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean ``(N, 3)`` (m, base frame) and its standard deviation per axis ``(N,)`` (m)."""
        k = self._cross(Q)
        mean = k @ self.alpha_m
        v = np.linalg.solve(self.cholesky, k.T)
        var = np.maximum(self.signal_std_m ** 2 - (v ** 2).sum(0), 0.0)
        return mean, np.sqrt(var)

    def mean(self, q: np.ndarray) -> np.ndarray:
        """Posterior mean ``(3,)`` (m, base frame) at one configuration."""
        return self._cross(q)[0] @ self.alpha_m

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """``(3, nq)`` derivative of the mean at one configuration (module docstring)."""
        d = np.asarray(q, float)[None, :] - self.inputs_rad
        k = self._cross(q)[0]
        return -(self.alpha_m * k[:, None]).T @ d / self.length_scale_rad ** 2

    def drift(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``(3,)`` second derivative of the mean along the joint velocity ``v`` (module docstring)."""
        d = np.asarray(q, float)[None, :] - self.inputs_rad
        v = np.asarray(v, float)
        l2 = self.length_scale_rad ** 2
        w = self._cross(q)[0] * ((d @ v) ** 2 / l2 ** 2 - float(v @ v) / l2)
        return w @ self.alpha_m

    def correct(self, positions_m: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Base-frame positions ``(N, 3)`` of the calibrated model at ``Q`` plus the mapped residual."""
        return np.asarray(positions_m, float) + self.predict(Q)[0]

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The ``results.npz`` entries of the map."""
        out = {key: np.asarray(getattr(self, name)) for name, key in self.KEYS.items()}
        out["residual_map_hyperparameters"] = np.array([self.length_scale_rad, self.signal_std_m, self.noise_std_m])
        return out

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> ResidualMap | None:
        """The map in a stage's arrays; None when the calibration handed none on."""
        if cls.KEYS["alpha_m"] not in arrays:
            return None
        length, signal, noise = (float(v) for v in np.asarray(arrays["residual_map_hyperparameters"], float))
        def get(name: str) -> np.ndarray:
            return np.asarray(arrays[cls.KEYS[name]], float)

        return cls(get("inputs_rad"), get("alpha_m"), get("cholesky"), length, signal, noise)
