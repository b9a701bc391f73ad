"""The hidden robot of ``truth.engine: mujoco``: the same seeded deviations, a MuJoCo arm behind the sensors.

:meth:`MujocoRealRobot.create` draws the hidden robot exactly as :meth:`RealRobot.create` does (same
seed and ``truth`` section -> the same placements, zero offsets, inertias, rotor inertia and
friction) and compiles it into a MuJoCo model (:func:`pipeline.sim.mujoco_model.compile_hidden_arm`).
The stages see the interface of :class:`~pipeline.sim.truth.RealRobot`:

- ``plant``: :class:`~pipeline.sim.mujoco_plant.MujocoPlant` (the cascade closed around MuJoCo);
- ``execute_joint_trajectory``: the arm follows the commanded motion under its own drives
  (:mod:`pipeline.sim.drive`, feedforward ``M a + h + friction`` of the nominal model it was tuned on),
  stepped by MuJoCo; readings are the encoders (noise, quantisation) and MuJoCo's actuator torques plus
  the torque sensor's noise, at the requested sample times;
- ``tracker``: the laser tracker's noise model around MuJoCo's reflector site;
- ``transmission``: rigid joints and no Stribeck or load-dependent friction (what MuJoCo cannot express);
- ``dynamic_parameters`` (tests and truth scores only): read back from the compiled ``mjModel``.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pipeline.core.errors import ConfigError
from pipeline.robot.model import RobotModel
from pipeline.robot.payload import Payload
from pipeline.sim import mujoco_model
from pipeline.sim.drive import DriveSettings, drive_gains, drive_inputs
from pipeline.sim.mujoco_plant import MujocoPlant
from pipeline.sim.sensors import GrossErrors, LaserTracker
from pipeline.sim.transmission import Transmission, create_transmission
from pipeline.sim.truth import JointMeasurement, RealRobot, TruthConfig


class MujocoRealRobot(RealRobot):
    """:class:`RealRobot` whose arm is a MuJoCo model (module docstring)."""

    #: its torque readings are its drives' commands in closed loop (the servo's reaction to the encoder
    #: noise, which depends on the path, is in them) and its dry friction (``frictionloss``) holds a joint
    #: at rest: the identification's validation counts both (:mod:`pipeline.identification.validate`)
    torques_in_closed_loop = True
    dry_friction_sticks = True

    def __init__(self, drawn: RealRobot, nominal: RobotModel, drive: DriveSettings | None = None) -> None:
        config = drawn.config
        super().__init__(drawn.truth, drawn.kinematic_errors, drawn.transform_tracker_to_base, config,
                         None, None, None, drawn._seed, drawn.transform_camera_to_base)
        self._nominal = nominal
        self.drive = drive if drive is not None else DriveSettings()
        self.arm = mujoco_model.compile_hidden_arm(nominal, drawn.truth)
        self._mujoco_plant = MujocoPlant(self.arm, drawn.truth, encoder_noise_rad=config.encoder_noise_rad)
        gross = GrossErrors(config.tracker_outlier_rate, config.tracker_outlier_magnitude_m, config.tracker_stale_rate)
        self.tracker = LaserTracker(drawn.truth, drawn.transform_tracker_to_base, self.link_angles, gross,
                                    reflector_positions=self._reflector_sites)

    @classmethod
    def create(cls, nominal: RobotModel, seed: int, config: TruthConfig | None = None) -> MujocoRealRobot:
        return cls(RealRobot.create(nominal, seed, config), nominal)

    def _reflector_sites(self, Q: np.ndarray) -> np.ndarray:
        return self._mujoco_plant.measure_tcp(Q, self._truth.frame_reflector)

    # ------------------------------------------------------------ stage-facing
    @property
    def plant(self) -> MujocoPlant:   # type: ignore[override]
        """The MuJoCo arm behind the drives."""
        return self._mujoco_plant

    def link_angles(self, Q: np.ndarray, payload: Payload | None = None) -> np.ndarray:
        """MuJoCo's joints are rigid and its gears exact: the links stand at the encoder angles."""
        return np.atleast_2d(np.asarray(Q, float))

    @property
    def transmission(self) -> Transmission:
        """Rigid joints, viscous + Coulomb friction only (the numbers MuJoCo carries)."""
        if self._transmission is None:
            nq = self._truth.nq
            self._transmission = create_transmission(self._truth, self._seed, np.full(nq, np.inf), 0.0, 0.0, 0.0,
                                                     0.0, 0.0)
        return self._transmission

    def execute_joint_trajectory(self, t_s: np.ndarray, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                                 rng: np.random.Generator) -> JointMeasurement:
        """The arm follows ``(q, v, a)`` under its drives in MuJoCo; encoder and torque readings at ``t_s``."""
        q, v, a = (np.atleast_2d(np.asarray(x, float)) for x in (q, v, a))
        t_s = np.asarray(t_s, float)
        if not (len(t_s) == len(q) == len(v) == len(a)):
            raise ConfigError(None, "trajectory", f"t, q, v, a have different lengths "
                              f"({len(t_s)}, {len(q)}, {len(v)}, {len(a)})")
        nom = self._nominal
        tau_ff = np.array([nom.inverse_dynamics(qk, vk, ak) for qk, vk, ak in zip(q, v, a, strict=True)])
        s = self.drive
        inputs = drive_inputs(t_s, q, v, tau_ff, s)
        rec = self._mujoco_plant.run_servo(drive_gains(nom, np.mean(q, axis=0), s), s.sample_time_s, s.velocity_samples,
                                    s.measurement_delay_samples, s.alpha, inputs.q_d_fb, inputs.v_ff, inputs.tau_ff,
                                    inputs.q_d[0], rng, measure_tcp=False, v0=inputs.v0)
        grid = inputs.t_s
        tau_true = rec.actuator_torque_Nm
        if tau_true is None:
            raise ValueError("the MuJoCo plant returned no actuator torques")
        on_grid = np.abs((t_s - grid[0]) / s.sample_time_s - np.round((t_s - grid[0]) / s.sample_time_s)) < 1e-6
        if np.all(on_grid):
            idx = np.clip(np.round((t_s - grid[0]) / s.sample_time_s).astype(int), 0, len(grid) - 1)
            q_read, tau = rec.q_meas[idx], tau_true[idx]
        else:   # readings between the drive's samples: interpolated (a logger on its own clock)
            q_read = np.stack([np.interp(t_s, grid, rec.q_meas[:, j]) for j in range(q.shape[1])], axis=1)
            tau = np.stack([np.interp(t_s, grid, tau_true[:, j]) for j in range(q.shape[1])], axis=1)
        sensor = self.torque_sensor
        return JointMeasurement(t_s.copy(), q_read, sensor.read(tau, rng), sensor.sigma_Nm.copy(),
                                self.encoders.noise_rad)

    # -------------------------------------------------------------- tests only
    @property
    def dynamic_parameters(self) -> np.ndarray:
        """Tests and truth scores only: ``p_dyn`` read back from the compiled ``mjModel``."""
        return mujoco_model.dynamic_parameters(self.arm)

    @property
    def joint_placements(self) -> list[pin.SE3]:
        """Tests only: the joint placements read back from the compiled ``mjModel``."""
        return mujoco_model.joint_placements(self.arm)


def create_hidden_robot(nominal: RobotModel, seed: int, config: TruthConfig | None = None) -> RealRobot:
    """The hidden robot of the run: the own simulator (``truth.engine: pipeline``) or MuJoCo (``mujoco``)."""
    config = config if config is not None else TruthConfig()
    if config.engine == "mujoco":
        return MujocoRealRobot.create(nominal, seed, config)
    return RealRobot.create(nominal, seed, config)
