"""The drives' cascaded servo law, sample by sample, for plants stepped from Python.

One position sample ``T_p`` (paper 004 §2.3: 400 µs) of the cascade of :mod:`pipeline.sim.loop`::

    position loop (every T_p):  e_p = Kp (q_d_fb - q_meas[k - d_m])
    velocity loop (every T_v = T_p / n_vel), per sub-sample j:
        q_enc   = round((q + noise) / res) * res
        v_hat  <- v_hat + alpha ((q_enc - q_enc_prev) / T_v - v_hat)
        e_v     = v_ff[j] + e_p - v_hat ;  I <- clip(I + Ki T_v e_v, +-tau_max), held while
                  |tau_cmd| > tau_max and e_v pushes further (conditional-integration anti-windup)
        tau_cmd = tau_ff[j] + Kv e_v + I

The compiled loop (:func:`pipeline.sim.loop.build_step`) writes the same law as CasADi
expressions; :func:`pipeline.sim.loop.python_rollout` and the MuJoCo plant
(:mod:`pipeline.sim.mujoco_plant`) call this class, so both Python plants run one law.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class CascadeState:
    """The drive's memory: velocity integrator, last encoder reading, velocity estimate and the
    encoder readings still on their way back (``buffer[0]`` the oldest)."""

    integral_Nm: np.ndarray
    q_enc_prev: np.ndarray
    v_hat: np.ndarray
    buffer: list[np.ndarray] = field(default_factory=list)


@dataclass(frozen=True)
class ServoLaw:
    """Gains (per joint), velocity filter, encoder resolution and sample times of the cascade."""

    kp: np.ndarray
    kv: np.ndarray
    ki: np.ndarray
    alpha: float
    resolution_rad: float
    velocity_sample_time_s: float
    effort_Nm: np.ndarray

    def encoder(self, q: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """Encoder reading: noise, then quantisation to the resolution."""
        return np.floor((q + noise) / self.resolution_rad + 0.5) * self.resolution_rad

    def position_error(self, state: CascadeState, q_d_fb: np.ndarray, q_enc0: np.ndarray) -> np.ndarray:
        """``Kp (q_d_fb - q_fb)`` with ``q_fb`` the oldest reading in flight (``q_enc0`` without delay)."""
        q_fb = state.buffer[0] if state.buffer else q_enc0
        return self.kp * (q_d_fb - q_fb)

    def velocity_step(self, state: CascadeState, q_enc: np.ndarray, v_ff: np.ndarray, tau_ff: np.ndarray,
                      e_p: np.ndarray) -> np.ndarray:
        """One velocity-loop sample: the estimate and integrator updated in ``state``; returns ``tau_cmd``."""
        state.v_hat = state.v_hat + self.alpha * ((q_enc - state.q_enc_prev) / self.velocity_sample_time_s
                                                  - state.v_hat)
        state.q_enc_prev = q_enc
        e_v = v_ff + e_p - state.v_hat
        integ_new = np.clip(state.integral_Nm + self.ki * self.velocity_sample_time_s * e_v,
                            -self.effort_Nm, self.effort_Nm)
        tau_new = tau_ff + self.kv * e_v + integ_new
        hold = (np.abs(tau_new) > self.effort_Nm) & (e_v * tau_new > 0)
        state.integral_Nm = np.where(hold, state.integral_Nm, integ_new)
        return tau_ff + self.kv * e_v + state.integral_Nm

    @staticmethod
    def end_sample(state: CascadeState, q_enc0: np.ndarray) -> None:
        """The sample's first encoder reading enters the measurement delay line."""
        if state.buffer:
            state.buffer = [*state.buffer[1:], q_enc0]
