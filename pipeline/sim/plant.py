"""The physical robot behind the drives: what ``RealRobot.plant`` returns.

A :class:`Plant` wraps the hidden robot model (only the truth side constructs it) and offers
the hardware's interfaces: ``integrate`` (one open-loop step of the rigid-body dynamics at
>= 10 kHz internal rate) and ``run_servo`` (the drives' cascaded loops closed around the robot,
sampled at the position-loop rate, returning what the encoders, the current loop and an ideal
laser tracker registered in the base frame would record). Stage code passes gains and set
points in and gets sensor records out; it never sees the model inside.

Dynamics (paper 004 §2.3, DESIGN.md "Control"): ``qdd = ABA(q, v, sat(tau) - friction(v))`` with
rotor inertia in ``model.armature``, integrated by semi-implicit Euler substeps. With a
:class:`~pipeline.sim.transmission.Transmission` of finite stiffness the joints are two-mass
systems (:mod:`pipeline.sim.elastic_dynamics`): the rotor (armature) drives the link through a
spring and damper, friction acts on the rotor, the encoders read the rotor and the tracker sees the
links. The substep is chosen so that ``h omega_max <= 1`` for the fastest joint resonance: semi-implicit
Euler is stable up to 2 and its frequency error is ``(h omega)^2 / 24`` (<= 4 % on that fastest mode,
far above the servo bandwidth). ``omega_max`` is the larger of the per-joint estimate
``k (1/J_m + 1/(J_l/2))`` (``J_l = M_ii(0)`` of the link chain, halved for the poses where it is
smaller) and the fastest mode of the coupled joints (:func:`deflection_rates`, with ``A = M(q)^-1 +
J_m^-1``) over ``WORKSPACE_POSES`` poses spread over the joint ranges (scrambled Sobol, fixed seed):
where joints are coupled (a light wrist link beside nearly aligned axes) ``(M^-1)_ii`` exceeds
``1 / M_ii`` and the coupled mode is several times faster than the per-joint estimate (TIAGo's
wrist: about 3.5 kHz against 1.5 kHz, beyond the stability limit of the 100 µs substep the
estimate alone gives). The damper's fastest rate ``c_max`` (``2 zeta omega`` of a joint) is kept at
``h c_max <= 0.5`` as the explicit friction is; one mode then needs ``(h omega)^2 < 4 - 2 h c``.
The sampled maximum may miss a peak by a few per cent: the factor 2 to the stability limit covers it.
On the RX130L the per-joint estimate is the larger one.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from scipy.stats import qmc

from pipeline.core.errors import ConfigError
from pipeline.robot.friction import smooth_sign
from pipeline.robot.model import RobotModel
from pipeline.sim import dynamics, loop
from pipeline.sim.transmission import Transmission, link_inertia_kgm2

#: poses over the joint ranges on which the coupled elastic modes are evaluated (Plant.substeps_for)
WORKSPACE_POSES = 1024
#: the substep keeps h omega_max <= this (semi-implicit Euler: stable below 2)
MODE_STEP = 1.0
#: the substep keeps h c_max (the fastest damper rate) and h x the explicit friction slope <= this
DAMPING_STEP = 0.5


def deflection_rates(link_model: pin.Model, q: np.ndarray, transmission: Transmission) -> tuple[float, float]:
    """The fastest rates of the two-mass joints linearised at link pose ``q``: ``omega_max`` (rad/s)
    of the springs and ``c_max`` (1/s) of the dampers.

    The deflections ``delta = theta - q`` obey ``delta'' = -A (K delta + D delta')`` with
    ``A = M(q)^-1 + diag(1 / J_m)`` (``M`` of ``link_model``, no armature), so
    ``omega_max^2 = lambda_max(K^1/2 A K^1/2)`` and ``c_max = lambda_max(D^1/2 A D^1/2)`` (``2 zeta omega``
    of a single joint): the non-zero eigenvalues of the 2 nq masses (links and rotors) joined by
    springs ``K`` and dampers ``D``; the other nq modes are rigid."""
    data = link_model.createData()
    pin.computeMinverse(link_model, data, np.asarray(q, float))
    m_inv = np.triu(data.Minv) + np.triu(data.Minv, 1).T
    a = m_inv + np.diag(1.0 / np.asarray(transmission.motor_inertia_kgm2, float))
    sk = np.sqrt(np.asarray(transmission.stiffness_Nm_rad, float))
    sd = np.sqrt(np.asarray(transmission.damping_Nms_rad, float))
    omega2 = float(np.linalg.eigvalsh(sk[:, None] * a * sk[None, :]).max())
    return float(np.sqrt(max(omega2, 0.0))), float(np.linalg.eigvalsh(sd[:, None] * a * sd[None, :]).max())


def workspace_poses(model: pin.Model, n: int = WORKSPACE_POSES, seed: int = 0) -> np.ndarray:
    """``n`` poses (n, nq) spread over the joint ranges (scrambled Sobol; unbounded joints over
    ``[-pi, pi]``) and the zero pose clipped into the ranges (first row)."""
    lo = np.maximum(np.asarray(model.lowerPositionLimit, float), -np.pi)
    hi = np.minimum(np.asarray(model.upperPositionLimit, float), np.pi)
    hi = np.maximum(hi, lo)
    sobol = qmc.Sobol(model.nq, scramble=True, seed=seed).random(n)
    return np.vstack([np.clip(np.zeros(model.nq), lo, hi), lo + sobol * (hi - lo)])


@dataclass
class ServoRecord:
    """Per position sample: encoder positions, velocity estimate, torque command (mean over the
    velocity samples), max |tau_cmd| / tau_max within the sample, TCP position from the tracker."""

    q_meas: np.ndarray
    v_est: np.ndarray
    tau_cmd: np.ndarray
    torque_ratio: np.ndarray
    tcp_position_m: np.ndarray | None
    wall_time_s: float
    cpu_time_s: float = 0.0
    extra: dict[str, int | str] = field(default_factory=dict)   # the engine's facts (substeps, name)
    q_link: np.ndarray | None = None     # (N, nq) true link positions (tests, TCP)
    q_motor: np.ndarray | None = None    # (N, nq) true motor positions (joint side; elastic plant)
    #: (N, nq) the actuator's force right after each encoder sample (MuJoCo; None: the own loop, whose
    #: torque rows are means over the sample)
    actuator_torque_Nm: np.ndarray | None = None


class Plant:
    """Hidden-robot dynamics + encoders. ``model`` is a RobotModel (the truth, when built by RealRobot)."""

    def __init__(self, model: RobotModel, encoder_noise_rad: float = 2e-6,
                 encoder_resolution_rad: float = 2 * np.pi / 2**26, integration_rate_hz: float = 10000.0,
                 transmission: Transmission | None = None) -> None:
        if encoder_resolution_rad <= 0 or encoder_noise_rad < 0:
            raise ConfigError(None, "plant.encoder", "resolution must be > 0 and noise >= 0")
        if integration_rate_hz < 10000.0:
            raise ConfigError(None, "plant.integration_rate_hz", f"{integration_rate_hz} < 10 kHz")
        self._model = model
        self._chain = dynamics.chain_structure(model.model)
        self._p = dynamics.parameter_vector(model)
        self._data = model.model.createData()
        self.encoder_noise_rad = float(encoder_noise_rad)
        self.encoder_resolution_rad = float(encoder_resolution_rad)
        self.integration_rate_hz = float(integration_rate_hz)
        self.nq = model.model.nq
        self.transmission = transmission
        k = None if transmission is None else np.asarray(transmission.stiffness_Nm_rad, float)
        if k is not None and np.any(np.isfinite(k)) and not np.all(np.isfinite(k)):
            raise ConfigError(None, "truth.joint_stiffness", "either every joint is elastic or none (inf)")
        self.elastic = transmission is not None and transmission.elastic
        self.stribeck = transmission is not None and not self.elastic and transmission.nonlinear_friction
        self._link_model = model.model
        if self.elastic:
            self._link_model = model.model.copy()
            self._link_model.armature = np.zeros(self.nq)
            self._p = self._p.copy()
            self._p[22:self.nq * dynamics.PARAMS_PER_JOINT:dynamics.PARAMS_PER_JOINT] = 0.0  # armature -> motor mass
            self._data = self._link_model.createData()
        self._coupled_rates: tuple[float, float] | None = None

    # --- open-loop interface of the contract -------------------------------------------------
    def _friction(self, v: np.ndarray, load_Nm: np.ndarray | float = 0.0) -> np.ndarray:
        if self.transmission is not None:
            return self.transmission.friction_torque(v, load_Nm)
        a = self._model.actuation
        return a.viscous_Nms_rad * v + a.coulomb_Nm * smooth_sign(v, a.coulomb_smoothing_rad_s)

    def integrate(self, q: np.ndarray, v: np.ndarray, tau_cmd: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Hold ``tau_cmd`` (saturated) for ``dt`` seconds; semi-implicit Euler at >= the integration rate.

        Rigid joints only (the contract's open-loop step); an elastic plant is run by :meth:`run_servo`."""
        if self.elastic:
            raise ConfigError(None, "plant.integrate", "the elastic plant has motor states: use run_servo")
        n_sub = max(1, int(np.ceil(dt * self.integration_rate_hz - 1e-9)))
        h = dt / n_sub
        eff = self._model.limits.effort_Nm
        tau = np.clip(tau_cmd, -eff, eff)
        q, v = np.array(q, float), np.array(v, float)
        for _ in range(n_sub):
            a = pin.aba(self._model.model, self._data, q, v, tau - self._friction(v, tau))
            v = v + h * a
            q = q + h * v
        return q, v

    def measure_tcp(self, Q: np.ndarray, frame: str = "tcp") -> np.ndarray:
        """TCP positions (N, 3) of the robot standing at joint positions ``Q``, as an ideal laser
        tracker registered to the base frame reads them (paper 004 §2.3.3 measures the TCP with a
        Leica LTD600)."""
        return self._model.positions(np.atleast_2d(Q), frame=frame)

    def measure_tcp_pose(self, Q: np.ndarray, frame: str = "tcp") -> tuple[np.ndarray, np.ndarray]:
        """Positions (N, 3) and rotations (N, 3, 3) of ``frame`` at link positions ``Q`` (ideal 6-D
        measurement, for the settling time of :func:`pipeline.control.validate.settling_time`)."""
        poses = [self._model.fk(q, frame=frame) for q in np.atleast_2d(Q)]
        return np.array([p.translation for p in poses]), np.array([p.rotation for p in poses])

    def read_encoders(self, q_true: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        noisy = q_true + self.encoder_noise_rad * rng.standard_normal(np.shape(q_true))
        return np.floor(noisy / self.encoder_resolution_rad + 0.5) * self.encoder_resolution_rad

    def substeps_for(self, velocity_sample_time_s: float) -> int:
        """Substeps per velocity sample: >= the integration rate and stable for the smooth Coulomb
        slope ``coulomb / (width * J_rotor)`` of explicit friction (h * slope <= 0.5)."""
        a = self._model.actuation
        slope = np.max(a.coulomb_Nm / a.coulomb_smoothing_rad_s / np.maximum(self._model.model.armature, 1e-3)
                       + a.viscous_Nms_rad / np.maximum(self._model.model.armature, 1e-3))
        n_rate = int(np.ceil(velocity_sample_time_s * self.integration_rate_hz - 1e-9))
        n_stab = int(np.ceil(velocity_sample_time_s * slope / DAMPING_STEP))
        tr = self.transmission
        if tr is not None and (self.elastic or self.stribeck):
            jm = np.maximum(tr.motor_inertia_kgm2, 1e-3)
            slope_s = np.max((tr.coulomb_Nm * (1 + tr.coulomb_load_coefficient) + tr.static_excess_Nm)
                             / tr.smoothing_rad_s / jm + tr.viscous_Nms_rad / jm)
            n_stab = max(n_stab, int(np.ceil(velocity_sample_time_s * slope_s / DAMPING_STEP)))
        if self.elastic:
            tr_e = self._elastic_transmission()
            jl = 0.5 * link_inertia_kgm2(self._model)
            w_max = np.max(np.sqrt(tr_e.stiffness_Nm_rad * (1 / tr_e.motor_inertia_kgm2 + 1 / jl)))
            w_coupled, c_coupled = self.coupled_rates()
            n_stab = max(n_stab, int(np.ceil(velocity_sample_time_s * max(w_max, w_coupled) / MODE_STEP)),
                         int(np.ceil(velocity_sample_time_s * c_coupled / DAMPING_STEP)))
        return max(n_rate, n_stab, 1)

    def _elastic_transmission(self) -> Transmission:
        """The transmission of an elastic plant's joints (:class:`ConfigError` on rigid joints)."""
        if not self.elastic or self.transmission is None:
            raise ConfigError(None, "plant.transmission", "the plant's joints are rigid")
        return self.transmission

    def coupled_rates(self) -> tuple[float, float]:
        """The fastest spring and damper rates of the elastic joints (:func:`deflection_rates`) over
        :func:`workspace_poses` of the link chain (computed once): ``(omega_max rad/s, c_max 1/s)``."""
        transmission = self._elastic_transmission()
        if self._coupled_rates is None:
            rates = np.array([deflection_rates(self._link_model, q, transmission)
                              for q in workspace_poses(self._link_model)])
            self._coupled_rates = (float(rates[:, 0].max()), float(rates[:, 1].max()))
        return self._coupled_rates

    # --- closed loop ------------------------------------------------------------------------
    def run_servo(self, gains: dict[str, np.ndarray], sample_time_s: float, velocity_samples: int,
                  measurement_delay_samples: int, velocity_filter_alpha: float,
                  q_d_fb: np.ndarray, v_ff: np.ndarray, tau_ff: np.ndarray, q0: np.ndarray,
                  rng: np.random.Generator, engine: str = "compiled", chunk_samples: int = 250,
                  measure_tcp: bool = True, tcp_frame: str = "tcp", v0: np.ndarray | None = None,
                  motor_offset0: np.ndarray | None = None) -> ServoRecord:
        """Close the drives' loops around the robot for ``len(q_d_fb)`` position samples.

        ``q_d_fb`` (N, nq): set point aligned with the delayed measurement; ``v_ff``, ``tau_ff``
        (N, velocity_samples * nq): velocity and torque feedforward for each velocity-loop sub-sample
        as they reach the drive. Starts at ``q0`` with velocity ``v0`` (default: at rest).
        ``engine``: "compiled" (CasADi/gcc, cached) or "python" (plain loop with pin.aba).
        Elastic plant: the links start at ``q0``, the motors at ``q0 + motor_offset0`` (default: the
        static deflection under gravity, ``g(q0) / k``), both with velocity ``v0``; ``q0`` is the link side.
        """
        n, N = self.nq, len(q_d_fb)
        ls = loop.LoopStructure(self._chain, velocity_samples, self.substeps_for(sample_time_s / velocity_samples),
                                measurement_delay_samples, chunk_samples, self.elastic, self.stribeck)
        tr_vec = self.transmission.loop_vector() if ls.transmission and self.transmission is not None else None
        P = loop.loop_parameters(self._p, gains["kp"], gains["kv"], gains["ki"], velocity_filter_alpha,
                                 self.encoder_resolution_rad, sample_time_s, tr_vec)
        noise = self.encoder_noise_rad * rng.standard_normal((N, velocity_samples * n))
        U = np.hstack([q_d_fb, v_ff, tau_ff, noise])
        v0 = np.zeros(n) if v0 is None else np.asarray(v0, float)
        th0 = q0
        if self.elastic:
            stiffness_Nm_rad = self._elastic_transmission().stiffness_Nm_rad
            off = (self._model.gravity_torque(q0) / stiffness_Nm_rad if motor_offset0 is None
                   else np.asarray(motor_offset0, float))
            th0 = q0 + off
        res = self.encoder_resolution_rad
        q_enc0 = np.floor(th0 / res + 0.5) * res
        q_prev = np.floor((th0 - v0 * sample_time_s / velocity_samples) / res + 0.5) * res  # consistent v_hat
        x0 = np.concatenate([q0, v0, np.zeros(n), q_prev, v0, np.tile(q_enc0, measurement_delay_samples),
                             *([th0, v0] if self.elastic else [])])
        t0, c0 = time.perf_counter(), time.thread_time()
        if engine == "python":
            _, Y = loop.python_rollout(ls, self._link_model, self._p, x0, U, P, self._friction)
        elif engine == "compiled":
            loop.buffered_rollout(ls)
            t0, c0 = time.perf_counter(), time.thread_time()  # compile/cache load is not loop time
            _, Y = loop.rollout(ls, x0, U, P)
        else:
            raise ConfigError(None, "control.engine", f"unknown engine {engine!r} (compiled|python)")
        wall, cpu = time.perf_counter() - t0, time.thread_time() - c0
        out = loop.unpack_output(Y, n)
        tcp = self._model.positions(out["q_true"], frame=tcp_frame) if measure_tcp else None
        return ServoRecord(out["q_meas"], out["v_est"], out["tau_cmd"], out["torque_ratio"], tcp, wall, cpu,
                           {"substeps_per_velocity_sample": ls.substeps_per_velocity_sample},
                           out["q_true"], out.get("q_motor_true"))
