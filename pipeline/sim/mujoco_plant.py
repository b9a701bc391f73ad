"""The MuJoCo arm behind the drives: the interface of :class:`pipeline.sim.plant.Plant`, stepped by MuJoCo.

Per position sample ``T_p`` (400 µs) the drives run the cascade of :class:`pipeline.sim.servo_law.ServoLaw`
(the same code as the own plant's Python loop) with the measurement delay line; per velocity sample
``T_v`` the saturated torque command is the motors' control (``mjData.ctrl``) and MuJoCo integrates
``n_sub`` steps of ``T_v / n_sub`` (its semi-implicit Euler with implicit joint damping; the 10 kHz
minimum rate of the own plant: 2 steps per 200 µs). The encoders read ``qpos`` with noise and
quantisation, the torque reading is MuJoCo's actuator force, the TCP is a site position.

Engine: MuJoCo is rigid (no elastic joints, no Stribeck or load-dependent friction, no gear
transmission error); its ``frictionloss`` is a dry-friction constraint of the solver (true sticking,
softened by the solver's impedance), where the own plant uses ``coulomb tanh(v / width)``.

The friction constraint's softness: MuJoCo's soft constraint drives the joint towards the reference
acceleration ``-b v`` with ``b = 2 / (d_max * timeconst)``, so below the friction level the friction acts
like a damper of rate ``b``, and a joint sliding at ``|v| < a / b`` under an acceleration ``a`` gets less
than its Coulomb friction. MuJoCo's default time constant, 0.02 s, is ten of its default 2 ms steps
(``b`` about 105 / s: at 5 rad/s² a band of 0.05 rad/s, at a wrist's 20 rad/s² 0.2 rad/s, where the
constraint is then not Coulomb friction but its regularisation); stepped at 100 µs the arm keeps
MuJoCo's ratio, ten steps (:data:`FRICTION_TIMECONST_STEPS`: 1 ms, ``b`` about 2100 / s), set on
``dof_solref`` with the step in :meth:`MujocoPlant.run_servo`.
"""

from __future__ import annotations

import time

import mujoco
import numpy as np

from pipeline.core.errors import ConfigError
from pipeline.robot.model import RobotModel
from pipeline.sim.mujoco_model import MujocoArm
from pipeline.sim.plant import ServoRecord
from pipeline.sim.servo_law import CascadeState, ServoLaw

#: time constant of the dry-friction constraint (``frictionloss``'s ``solref``, ``mjModel.dof_solref``) in
#: integration steps: MuJoCo's default, 0.02 s, is ten of its default 2 ms steps; kept at ten of ours
#: (module docstring)
FRICTION_TIMECONST_STEPS = 10.0


def _as_slice(index: np.ndarray) -> slice | np.ndarray:
    """A run of consecutive indices as a slice (views instead of copies in the stepping loop)."""
    index = np.asarray(index)
    if index.size and np.array_equal(index, np.arange(index[0], index[0] + index.size)):
        return slice(int(index[0]), int(index[0]) + index.size)
    return index


class MujocoPlant:
    """The MuJoCo arm with its encoders and motors (``RealRobot.plant`` of ``truth.engine: mujoco``)."""

    elastic = False
    stribeck = False
    transmission = None

    def __init__(self, arm: MujocoArm, truth: RobotModel, encoder_noise_rad: float = 2e-6,
                 encoder_resolution_rad: float = 2 * np.pi / 2**26, integration_rate_hz: float = 10000.0) -> None:
        if encoder_resolution_rad <= 0 or encoder_noise_rad < 0:
            raise ConfigError(None, "plant.encoder", "resolution must be > 0 and noise >= 0")
        self.arm = arm
        self._truth = truth
        self.model = arm.model
        self.data = mujoco.MjData(arm.model)
        self.encoder_noise_rad = float(encoder_noise_rad)
        self.encoder_resolution_rad = float(encoder_resolution_rad)
        self.integration_rate_hz = float(integration_rate_hz)
        self.nq = len(arm.joint_names)
        self.effort_Nm = np.asarray(truth.limits.effort_Nm, float).copy()
        self.friction_timeconst_steps = FRICTION_TIMECONST_STEPS

    # --- static readings -----------------------------------------------------------------------
    def _kinematics(self, q: np.ndarray) -> None:
        self.data.qpos[self.arm.qpos_address] = q
        mujoco.mj_kinematics(self.model, self.data)

    def measure_tcp(self, Q: np.ndarray, frame: str = "tcp") -> np.ndarray:
        """Positions (N, 3) of the site ``frame`` at joint positions ``Q`` (ideal tracker, base frame)."""
        site = self.arm.site(frame)
        out = np.empty((len(np.atleast_2d(Q)), 3))
        for k, q in enumerate(np.atleast_2d(np.asarray(Q, float))):
            self._kinematics(q)
            out[k] = self.data.site_xpos[site]
        return out

    def measure_tcp_pose(self, Q: np.ndarray, frame: str = "tcp") -> tuple[np.ndarray, np.ndarray]:
        """Positions (N, 3) and rotations (N, 3, 3) of the site ``frame`` at ``Q``."""
        site = self.arm.site(frame)
        Q = np.atleast_2d(np.asarray(Q, float))
        pos, rot = np.empty((len(Q), 3)), np.empty((len(Q), 3, 3))
        for k, q in enumerate(Q):
            self._kinematics(q)
            pos[k] = self.data.site_xpos[site]
            rot[k] = self.data.site_xmat[site].reshape(3, 3)
        return pos, rot

    def read_encoders(self, q_true: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        noisy = q_true + self.encoder_noise_rad * rng.standard_normal(np.shape(q_true))
        return np.floor(noisy / self.encoder_resolution_rad + 0.5) * self.encoder_resolution_rad

    def substeps_for(self, velocity_sample_time_s: float) -> int:
        """MuJoCo steps per velocity sample: at least the integration rate."""
        return max(1, int(np.ceil(velocity_sample_time_s * self.integration_rate_hz - 1e-9)))

    # --- closed loop ------------------------------------------------------------------------------
    def run_servo(self, gains: dict[str, np.ndarray], sample_time_s: float, velocity_samples: int,
                  measurement_delay_samples: int, velocity_filter_alpha: float,
                  q_d_fb: np.ndarray, v_ff: np.ndarray, tau_ff: np.ndarray, q0: np.ndarray,
                  rng: np.random.Generator, engine: str = "mujoco", chunk_samples: int = 250,
                  measure_tcp: bool = True, tcp_frame: str = "tcp", v0: np.ndarray | None = None,
                  motor_offset0: np.ndarray | None = None) -> ServoRecord:
        """:meth:`pipeline.sim.plant.Plant.run_servo` on the MuJoCo arm (``engine``, ``chunk_samples`` and
        ``motor_offset0`` have no meaning here: one engine, no chunks, rigid joints).

        ``actuator_torque_Nm`` (N, nq): MuJoCo's actuator force in the first velocity sample of
        each position sample (what the drive's current reads right after the encoder sample)."""
        n, N, nv = self.nq, len(q_d_fb), int(velocity_samples)
        Tv = sample_time_s / nv
        n_sub = self.substeps_for(Tv)
        m, d = self.model, self.data
        m.opt.timestep = Tv / n_sub
        m.dof_solref[:] = [self.friction_timeconst_steps * m.opt.timestep, 1.0]   # the dry friction's softness
        law = ServoLaw(np.asarray(gains["kp"], float), np.asarray(gains["kv"], float),
                       np.asarray(gains["ki"], float), float(velocity_filter_alpha), self.encoder_resolution_rad,
                       Tv, self.effort_Nm)
        noise = self.encoder_noise_rad * rng.standard_normal((N, nv * n))
        v0 = np.zeros(n) if v0 is None else np.asarray(v0, float)
        q0 = np.asarray(q0, float)
        mujoco.mj_resetData(m, d)
        qa, va, act = (_as_slice(x) for x in (self.arm.qpos_address, self.arm.dof_address, self.arm.actuator_ids))
        d.qpos[qa], d.qvel[va] = q0, v0
        mujoco.mj_forward(m, d)
        res = self.encoder_resolution_rad
        q_enc_start = np.floor(q0 / res + 0.5) * res
        q_prev = np.floor((q0 - v0 * Tv) / res + 0.5) * res          # a consistent first velocity estimate
        state = CascadeState(np.zeros(n), q_prev, v0.copy(), [q_enc_start.copy()
                                                              for _ in range(measurement_delay_samples)])
        q_meas, v_est, tau_mean, ratio_out, q_true, tau_act = (np.empty((N, n)) for _ in range(6))
        t0, c0 = time.perf_counter(), time.thread_time()
        for k in range(N):
            q = d.qpos[qa].copy()
            q_true[k] = q
            q_enc0 = law.encoder(q, noise[k, :n])
            e_p = law.position_error(state, q_d_fb[k], q_enc0)
            tau_sum, ratio = np.zeros(n), np.zeros(n)
            for j in range(nv):
                q_enc = q_enc0 if j == 0 else law.encoder(d.qpos[qa], noise[k, j * n:(j + 1) * n])
                tau_cmd = law.velocity_step(state, q_enc, v_ff[k, j * n:(j + 1) * n], tau_ff[k, j * n:(j + 1) * n], e_p)
                tau_sum += tau_cmd
                ratio = np.maximum(ratio, np.abs(tau_cmd) / self.effort_Nm)
                d.ctrl[act] = np.clip(tau_cmd, -self.effort_Nm, self.effort_Nm)
                mujoco.mj_step(m, d, n_sub)
                if j == 0:
                    tau_act[k] = d.actuator_force[act]
            law.end_sample(state, q_enc0)
            q_meas[k], v_est[k], tau_mean[k], ratio_out[k] = q_enc0, state.v_hat, tau_sum / nv, ratio
        wall, cpu = time.perf_counter() - t0, time.thread_time() - c0
        tcp = self.measure_tcp(q_true, tcp_frame) if measure_tcp else None
        return ServoRecord(q_meas, v_est, tau_mean, ratio_out, tcp, wall, cpu,
                           {"substeps_per_velocity_sample": n_sub, "engine": "mujoco"}, q_true, None,
                           actuator_torque_Nm=tau_act)
