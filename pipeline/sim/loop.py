"""The sampled cascade (drive) + plant step as one CasADi function, compiled and cached.

One call of ``step`` covers one position-loop sample ``T_p`` (paper 004 §2.3: 400 µs)::

    position loop (every T_p):  e_p = Kp (q_d_fb - q_meas[k - d_m])
    velocity loop (every T_v = T_p / n_vel, paper: 200 µs), per joint, sub-sample j:
        v_cmd   = v_ff[j] + e_p                                   velocity feedforward per sub-sample
        q_enc   = round((q + noise) / res) * res                  encoder: noise + quantisation
        v_hat  <- v_hat + alpha ((q_enc - q_enc_prev) / T_v - v_hat)   differenced, low-passed
        e_v     = v_cmd - v_hat ;  I <- clip(I + Ki T_v e_v, +-tau_max), held while
                  |tau_cmd| > tau_max and e_v pushes further (conditional-integration anti-windup)
        tau_cmd = tau_ff[j] + Kv e_v + I                          ideal current loop
    plant: n_sub semi-implicit Euler substeps of  qdd = ABA(q, v, sat(tau_cmd) - friction(v))
           (``stribeck``: the truth's Stribeck + load-dependent friction; ``elastic``: the two-mass
           model of :mod:`pipeline.sim.elastic_dynamics`, the encoders on the motor side)

``q_d_fb`` is the setpoint aligned with the delayed measurement (the drive keeps the setpoint
history), so the measurement delay only acts on the feedback, not as a lag.
The step is rolled out with ``mapaccum`` over a chunk of samples, C code is generated and
compiled with gcc once per structure; the ``.so`` is cached under ``~/.cache/pipeline/control``
keyed by a hash of the structure, the loop settings, CasADi's version and this source.
:func:`rollout` runs it chunk after chunk through CasADi's buffer interface
(:class:`~pipeline.core.casadi_buffers.BufferedFunction`): inputs and outputs are numpy arrays, no ``DM``
in between (the ``DM`` round trip cost about 3x the evaluation itself on the elastic RX130L).
"""

from __future__ import annotations

import hashlib
import platform
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np
import pinocchio as pin

from pipeline.core import codegen
from pipeline.core.casadi_buffers import BufferedFunction
from pipeline.sim import dynamics, elastic_dynamics
from pipeline.sim.dynamics import ChainStructure
from pipeline.sim.elastic_dynamics import TRANSMISSION_PARAMS_PER_JOINT
from pipeline.sim.servo_law import CascadeState, ServoLaw


@dataclass(frozen=True)
class LoopStructure:
    """Everything the generated code depends on (numbers that vary are inputs)."""

    chain: ChainStructure
    velocity_samples_per_position_sample: int = 2
    substeps_per_velocity_sample: int = 4
    measurement_delay_samples: int = 1
    chunk_samples: int = 250
    elastic: bool = False        # two-mass joints: state + (theta, omega), encoders on theta
    stribeck: bool = False       # the truth's Stribeck / load-dependent friction (rigid joints)

    @property
    def nq(self) -> int:
        return self.chain.nq

    @property
    def transmission(self) -> bool:
        """Whether the loop takes the transmission numbers (after the loop parameters)."""
        return self.elastic or self.stribeck

    @property
    def n_state(self) -> int:
        return self.nq * (5 + self.measurement_delay_samples + (2 if self.elastic else 0))

    @property
    def n_input(self) -> int:
        return self.nq * (1 + 3 * self.velocity_samples_per_position_sample)

    @property
    def n_output(self) -> int:
        return self.nq * (6 if self.elastic else 5)

    @property
    def n_loop_params(self) -> int:
        extra = TRANSMISSION_PARAMS_PER_JOINT * self.nq if self.transmission else 0
        return self.chain.n_params + 3 * self.nq + 3 + extra

    def key(self) -> str:
        src = b"".join(Path(m.__file__).read_bytes() for m in (loop_module(), dynamics, elastic_dynamics))
        text = repr(self) + ca.__version__ + hashlib.sha256(src).hexdigest() + " ".join(GCC_FLAGS) + platform.node()
        return hashlib.sha256(text.encode()).hexdigest()[:20]


def loop_module():  # noqa: ANN201 - this module (its source is part of the cache key)
    return sys.modules[__name__]


def loop_parameters(p_dyn: np.ndarray, kp: np.ndarray, kv: np.ndarray, ki: np.ndarray, alpha: float,
                    encoder_resolution_rad: float, sample_time_s: float,
                    transmission: np.ndarray | None = None) -> np.ndarray:
    """Parameter vector of the step: plant numbers, gains, filter, encoder resolution, T_p and, for an
    elastic or Stribeck plant, the transmission numbers (``Transmission.loop_vector``)."""
    extra = [] if transmission is None else [np.asarray(transmission, float)]
    return np.concatenate([p_dyn, kp, kv, ki, [alpha, encoder_resolution_rad, sample_time_s], *extra])


def build_step(ls: LoopStructure) -> ca.Function:
    """``step(x, u, P) -> (x_next, y)``; layouts in the module docstring and :func:`unpack_output`."""
    n, nv_, ns = ls.nq, ls.velocity_samples_per_position_sample, ls.substeps_per_velocity_sample
    dm = ls.measurement_delay_samples
    fd = dynamics.forward_dynamics_function(ls.chain)
    x = ca.MX.sym("x", ls.n_state)
    u = ca.MX.sym("u", ls.n_input)
    P = ca.MX.sym("P", ls.n_loop_params)
    npd = ls.chain.n_params
    p_dyn = P[:npd]
    kp, kv, ki = P[npd:npd + n], P[npd + n:npd + 2 * n], P[npd + 2 * n:npd + 3 * n]
    alpha, res, Tp = P[npd + 3 * n], P[npd + 3 * n + 1], P[npd + 3 * n + 2]
    ptr = P[npd + 3 * n + 3:]
    Tv = Tp / nv_
    h = Tv / ns
    psym = ca.SX.sym("p", npd)
    effort = ca.Function("effort", [psym], [dynamics.effort_sx(psym, ls.chain)])(p_dyn)

    q, v, integ, q_prev, v_hat = (x[i * n:(i + 1) * n] for i in range(5))
    buf = [x[(5 + i) * n:(6 + i) * n] for i in range(dm)]  # buf[0] oldest
    th = w = None
    if ls.elastic:
        th, w = x[(5 + dm) * n:(6 + dm) * n], x[(6 + dm) * n:(7 + dm) * n]
        sub = elastic_dynamics.elastic_substep_function(ls.chain)
    elif ls.stribeck:
        sub = elastic_dynamics.rigid_stribeck_substep_function(ls.chain)
    q_d_fb = u[:n]
    v_ff = [u[(1 + j) * n:(2 + j) * n] for j in range(nv_)]
    tau_ff = [u[(1 + nv_ + j) * n:(2 + nv_ + j) * n] for j in range(nv_)]
    noise = [u[(1 + 2 * nv_ + j) * n:(2 + 2 * nv_ + j) * n] for j in range(nv_)]

    def encoder(qq, nn):
        return ca.floor((qq + nn) / res + 0.5) * res

    q_link0 = q
    q_enc0 = encoder(th if ls.elastic else q, noise[0])
    q_fb = buf[0] if dm > 0 else q_enc0
    e_p = kp * (q_d_fb - q_fb)
    tau_sum = ca.MX.zeros(n)
    ratio = ca.MX.zeros(n)
    for j in range(nv_):
        q_enc = q_enc0 if j == 0 else encoder(th if ls.elastic else q, noise[j])
        v_hat = v_hat + alpha * ((q_enc - q_prev) / Tv - v_hat)
        q_prev = q_enc
        e_v = v_ff[j] + e_p - v_hat
        integ_new = ca.fmin(ca.fmax(integ + ki * Tv * e_v, -effort), effort)
        tau_new = tau_ff[j] + kv * e_v + integ_new
        # anti-windup (conditional integration): hold I while the command is beyond the limit
        # and the error pushes it further out
        hold = ca.logic_and(ca.fabs(tau_new) > effort, e_v * tau_new > 0)
        integ = ca.if_else(hold, integ, integ_new)
        tau_cmd = tau_ff[j] + kv * e_v + integ
        tau_sum = tau_sum + tau_cmd
        ratio = ca.fmax(ratio, ca.fabs(tau_cmd) / effort)
        for _ in range(ns):
            if ls.elastic:
                q, v, th, w = sub(q, v, th, w, tau_cmd, p_dyn, ptr, h)
            elif ls.stribeck:
                q, v = sub(q, v, tau_cmd, p_dyn, ptr, h)
            else:
                a = fd(q, v, tau_cmd, p_dyn)
                v = v + h * a
                q = q + h * v
    new_buf = [*buf[1:], q_enc0] if dm > 0 else []
    motor = [th, w] if ls.elastic else []
    x_next = ca.vertcat(q, v, integ, q_prev, v_hat, *new_buf, *motor)
    y = ca.vertcat(q_enc0, v_hat, tau_sum / nv_, ratio, q_link0, *([x[(5 + dm) * n:(6 + dm) * n]] if ls.elastic
                                                                  else []))
    return ca.Function("step", [x, u, P], [x_next, y], ["x", "u", "P"], ["x_next", "y"])


def unpack_output(Y: np.ndarray, n: int) -> dict[str, np.ndarray]:
    """Rows of the stacked outputs (samples x 5n, elastic 6n) -> named arrays (samples x n).

    ``q_true`` is the link position at the start of the sample, ``q_motor_true`` (elastic) the motor's."""
    names = ("q_meas", "v_est", "tau_cmd", "torque_ratio", "q_true", "q_motor_true")
    return {k: Y[:, i * n:(i + 1) * n] for i, k in enumerate(names) if (i + 1) * n <= Y.shape[1]}


GCC_FLAGS = ("-O3", "-march=native")  # the .so is built for this machine (host name in the cache key)
_CACHE: dict[str, ca.Function] = {}
_BUFFERED: dict[tuple[str, int], BufferedFunction] = {}
_LOCK = threading.Lock()


def compiled_rollout(ls: LoopStructure) -> ca.Function:
    """``roll(x0, U (n_input x chunk), P) -> (X, Y)`` compiled with gcc, cached in memory and on disk.

    The disk cache is keyed by the loop structure (:meth:`LoopStructure.key`), so the costly
    code generation of the rolled-out step runs only when the library is missing."""
    key = ls.key()
    with _LOCK:
        if key in _CACHE:
            return _CACHE[key]
        library = codegen.build_library("roll", lambda: [build_step(ls).mapaccum("roll", ls.chunk_samples, [0], [0])],
                                        subdir="control", flags=GCC_FLAGS, key=key)
        f = ca.external("roll", str(library))
        _CACHE[key] = f
        return f


def buffered_rollout(ls: LoopStructure) -> BufferedFunction:
    """:func:`compiled_rollout` behind CasADi's buffer interface (numpy in and out), one per thread
    (the buffers are the function's own)."""
    key = (ls.key(), threading.get_ident())
    with _LOCK:
        roll = _BUFFERED.get(key)
    if roll is None:
        roll = BufferedFunction(compiled_rollout(ls))
        with _LOCK:
            _BUFFERED[key] = roll
    return roll


def rollout(ls: LoopStructure, x0: np.ndarray, U: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Run the compiled loop over all rows of ``U`` (samples x n_input) from state ``x0``.

    Returns the state after the last row and the outputs (samples x n_output). The last chunk is
    padded with the last input row and zero encoder noise (the padded samples are dropped). The
    numbers are those of a plain call of :func:`compiled_rollout` chunk after chunk (the same
    generated code)."""
    roll = buffered_rollout(ls)
    N, c = len(U), ls.chunk_samples
    n_chunks = -(-N // c)
    Upad = np.empty((n_chunks * c, ls.n_input))
    Upad[:N] = U
    Upad[N:] = U[-1]
    Upad[N:, (1 + 2 * ls.velocity_samples_per_position_sample) * ls.nq:] = 0.0
    Y = np.empty((n_chunks * c, ls.n_output))
    # mapaccum maps P with the samples: one column per sample, repeated once here (its transpose is
    # C-ordered, as the slices of U: the buffers take them without a copy)
    P_cols = np.repeat(np.asarray(P, float)[None, :], c, axis=0).T
    x = np.asarray(x0, float)
    for i in range(n_chunks):
        X, Yc = roll(x, Upad[i * c:(i + 1) * c].T, P_cols)   # (n_state x c), (n_output x c)
        x = X[:, min(c, N - i * c) - 1]
        Y[i * c:(i + 1) * c] = Yc.T
    return x, Y[:N]


def python_rollout(ls: LoopStructure, model: pin.Model, p_dyn: np.ndarray, x0: np.ndarray, U: np.ndarray,
                   P: np.ndarray, friction) -> tuple[np.ndarray, np.ndarray]:
    """The same loop as a plain Python loop with ``pin.aba`` and :class:`~pipeline.sim.servo_law.ServoLaw`
    (baseline for the speed-up and tests).

    ``friction(v, load)`` is the plant's friction torque; ``U`` is (samples x n_input). For an elastic
    loop ``model`` is the link chain without rotor inertia and ``P`` ends with the transmission numbers.
    """
    n, nv_, ns, dm = ls.nq, ls.velocity_samples_per_position_sample, ls.substeps_per_velocity_sample, \
        ls.measurement_delay_samples
    npd = ls.chain.n_params
    kp, kv, ki = P[npd:npd + n], P[npd + n:npd + 2 * n], P[npd + 2 * n:npd + 3 * n]
    alpha, res, Tp = P[npd + 3 * n:npd + 3 * n + 3]
    effort = np.array([p_dyn[i * dynamics.PARAMS_PER_JOINT + 25] for i in range(n)])
    Tv = Tp / nv_
    h = Tv / ns
    data = model.createData()
    x = np.array(x0, float)
    q, v = x[:n].copy(), x[n:2 * n].copy()
    state = CascadeState(x[2 * n:3 * n].copy(), x[3 * n:4 * n].copy(), x[4 * n:5 * n].copy(),
                         [x[(5 + i) * n:(6 + i) * n].copy() for i in range(dm)])
    law = ServoLaw(kp, kv, ki, alpha, res, Tv, effort)
    th, w = (x[(5 + dm + i) * n:(6 + dm + i) * n].copy() for i in range(2)) if ls.elastic else (q, v)
    tr = P[npd + 3 * n + 3:].reshape(n, TRANSMISSION_PARAMS_PER_JOINT) if ls.transmission else None
    Y = np.empty((len(U), ls.n_output))
    for k, u in enumerate(U):
        q_start, th_start = q.copy(), th.copy()
        noise = [u[(1 + 2 * nv_ + j) * n:(2 + 2 * nv_ + j) * n] for j in range(nv_)]
        q_enc0 = law.encoder(th if ls.elastic else q, noise[0])
        e_p = law.position_error(state, u[:n], q_enc0)
        tau_sum = np.zeros(n)
        ratio = np.zeros(n)
        for j in range(nv_):
            q_enc = q_enc0 if j == 0 else law.encoder(th if ls.elastic else q, noise[j])
            v_ff_j, tau_ff_j = u[(1 + j) * n:(2 + j) * n], u[(1 + nv_ + j) * n:(2 + nv_ + j) * n]
            tau_cmd = law.velocity_step(state, q_enc, v_ff_j, tau_ff_j, e_p)
            tau_sum += tau_cmd
            ratio = np.maximum(ratio, np.abs(tau_cmd) / effort)
            tau_sat = np.clip(tau_cmd, -effort, effort)
            for _ in range(ns):
                if ls.elastic:
                    tau_s = tr[:, 1] * (th - q) + tr[:, 2] * (w - v)
                    a = pin.aba(model, data, q, v, tau_s)
                    w = w + h * (tau_sat - tau_s - friction(w, tau_s)) / tr[:, 0]
                    v = v + h * a
                    th = th + h * w
                    q = q + h * v
                else:
                    a = pin.aba(model, data, q, v, tau_sat - friction(v, tau_sat))
                    v = v + h * a
                    q = q + h * v
        law.end_sample(state, q_enc0)
        Y[k] = np.concatenate([q_enc0, state.v_hat, tau_sum / nv_, ratio, q_start, *([th_start] if ls.elastic else [])])
    return np.concatenate([q, v, state.integral_Nm, state.q_enc_prev, state.v_hat, *state.buffer,
                           *([th, w] if ls.elastic else [])]), Y
