"""The hidden "real" robot: a seeded perturbed copy of the nominal model, seen only through sensors.

Perturbations (DESIGN.md, "Truth perturbations", 1-sigma): joint placements 0.5 mm in
translation and 0.3 mrad in rotation (6 per joint, applied as ``M_i exp6(delta_i)``), joint
zero offsets 1 mrad (joint 1's placement and zero, and joint 2's along/about axis 1, are the
base-frame convention: zero), the
tool as a rigid body carrying TCP and reflector 0.5 mm and 0.3 mrad, tracker placement a few cm and
degrees away from its nominal pose; inertial parameters 10–20 % (mass log-normal, centre of
mass shifted, second moments scaled and rotated so every link stays physically consistent),
rotor inertia and friction 20 %.

Beyond the calibrated parameters (what a real arm adds; paper 000 Outlook), each
settable to 0 to get the ideal robot back bit for bit:

- joint elasticity: per-joint torsional stiffness ``k_i = k_nom_i exp(s z_i) / scale``
  (``k_nom`` from :func:`pipeline.robot.stiffness.nominal_joint_stiffness_Nm_rad`, log-normal
  spread ``s = joint_stiffness_relative_sigma`` = 30 %, ``scale = joint_compliance_scale``); for
  a static tracker pose the link-side angle is ``q_link = q - g(q_link) / k`` with ``g`` the
  true gravity torque of arm + mounted payload (fixed point, 3 iterations);
- a cyclic gear transmission error ``A sin(n_i q_i + phi_i)`` (``A`` a few µrad, ``n_i`` 2..6
  cycles per joint revolution, random phase): an unmodelled remainder no calibration reaches;
- tracker gross errors: a rate of readings off by ``tracker_outlier_magnitude_m`` in a random
  direction (a beam that hit the wrong surface) and a rate of stale readings (the previous
  reading repeated after a blocked beam).

These draws come from a second stream (salt + 1) so the first stream, and therefore every
geometric and inertial deviation, is the same as for the ideal robot. A robot whose robot.yaml
declares an ``optical_tracker`` (:mod:`pipeline.sim.optical_tracker`) gets one at a camera pose
perturbed with the tracker sigmas, drawn from a third stream (salt + 2): nothing else changes.

Stage code may use only :attr:`RealRobot.tracker`, :attr:`RealRobot.encoders`,
:attr:`RealRobot.torque_sensor`, :meth:`RealRobot.execute_joint_trajectory` and
:attr:`RealRobot.plant`. The attributes documented "tests only" open the truth.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin
from scipy.linalg import expm

from pipeline.core.errors import ConfigError
from pipeline.robot.model import RobotModel
from pipeline.robot.parameters import (
    KinematicLayout,
    apply_kinematic_errors,
    joint_infos,
    pinocchio_dynamic_parameters,
)
from pipeline.robot.payload import Payload, gravity_torques_Nm, with_payload
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad
from pipeline.sim.optical_tracker import OpticalTracker
from pipeline.sim.plant import Plant
from pipeline.sim.sensors import Encoders, GrossErrors, LaserTracker, TorqueSensor
from pipeline.sim.transmission import Transmission, create_transmission

#: fixed salt so the truth stream is independent of every stage's stream
_TRUTH_SALT = 0x74727574
#: engines of the hidden arm (TruthConfig.engine)
ENGINES = ("pipeline", "mujoco")
#: fixed-point iterations of the load-dependent friction in the measured torque (error ~ (mu F_c/tau_max)^k)
_LOAD_ITERATIONS = 5


@dataclass
class TruthConfig:
    """Magnitudes (1-sigma) of the hidden robot's deviations and of the sensor noise."""

    placement_translation_sigma_m: float = 0.5e-3
    placement_rotation_sigma_rad: float = 0.3e-3
    joint_offset_sigma_rad: float = 1.0e-3
    tool_translation_sigma_m: float = 0.5e-3
    tool_rotation_sigma_rad: float = 0.3e-3
    tracker_translation_sigma_m: float = 0.05
    tracker_rotation_sigma_rad: float = 0.03
    mass_relative_sigma: float = 0.15
    com_shift_sigma_m: float = 0.02
    second_moment_relative_sigma: float = 0.15
    rotor_inertia_relative_sigma: float = 0.2
    friction_relative_sigma: float = 0.2
    encoder_noise_rad: float = 2.0e-6
    torque_noise_fraction_of_limit: float = 0.01
    # -- beyond the geometric model (module docstring); 0 -> the ideal robot
    #: multiplies the nominal joint compliance 1/k (0: rigid joints)
    joint_compliance_scale: float = 1.0
    #: log-normal spread of each joint's stiffness around the nominal value (per seed)
    joint_stiffness_relative_sigma: float = 0.3
    #: amplitude of the cyclic gear transmission error (rad, joint side)
    transmission_error_amplitude_rad: float = 3.0e-6
    #: fraction of tracker readings off by tracker_outlier_magnitude_m (random direction)
    tracker_outlier_rate: float = 0.0
    tracker_outlier_magnitude_m: float = 2.0e-3
    #: fraction of tracker readings that repeat the previous reading (blocked beam)
    tracker_stale_rate: float = 0.0

    # --- transmission block (pipeline/sim/transmission.py): Stribeck friction, load-dependent
    # Coulomb friction and the damping of the elastic joints; every value 0 -> today's friction
    stribeck_excess_relative: float = 0.4   # static friction = Coulomb (1 + x) (Armstrong-Helouvry 1994: 1.2-2)
    stribeck_velocity_rad_s: float = 0.05   # joint side (a few rad/s on the motor through a gear of 50-100)
    coulomb_load_coefficient: float = 0.1   # Coulomb grows by this fraction at rated load (Bittencourt 2012)
    joint_damping_ratio: float = 0.05       # of the motor-link resonance (structural damping of gears: a few %)
    #: the engine of the hidden arm: "pipeline" (this module's own plant) or "mujoco" (the same deviations
    #: in a MuJoCo model, :mod:`pipeline.sim.mujoco_robot`; no elasticity, Stribeck or transmission error)
    engine: str = "pipeline"

    @classmethod
    def ideal(cls, **overrides: float) -> TruthConfig:
        """The ideal robot of the geometric and rigid-body models: rigid joints, no transmission error,
        no gross tracker errors, viscous + Coulomb friction only (no Stribeck, no load dependence)."""
        fields = dict(joint_compliance_scale=0.0, transmission_error_amplitude_rad=0.0,
                      tracker_outlier_rate=0.0, tracker_stale_rate=0.0,
                      stribeck_excess_relative=0.0, coulomb_load_coefficient=0.0)
        return replace(cls(), **(fields | overrides))

    def validate(self, source: str = "truth") -> None:
        if self.engine not in ENGINES:
            raise ConfigError(source, "truth.engine", f"one of {', '.join(ENGINES)}, got {self.engine!r}")
        for name, value in vars(self).items():
            if name == "engine":
                continue
            if not isinstance(value, int | float) or not np.isfinite(value) or value < 0:
                raise ConfigError(source, f"truth.{name}", f"must be a non-negative number, got {value!r}")
        for name in ("tracker_outlier_rate", "tracker_stale_rate"):
            if getattr(self, name) > 0.5:
                raise ConfigError(source, f"truth.{name}", f"a rate in [0, 0.5], got {getattr(self, name)!r}")



@dataclass
class JointMeasurement:
    """Sampled joint positions and torques of the real robot (joint side)."""

    t_s: np.ndarray
    q_rad: np.ndarray
    tau_Nm: np.ndarray
    tau_sigma_Nm: np.ndarray
    q_sigma_rad: float


def _without_base_components(nominal: RobotModel, error_2: np.ndarray) -> np.ndarray:
    """Joint 2's placement error less its translation along and rotation about axis 1.

    For an arm whose axis 2 meets axis 1 (the RX130L and TX40), moving joint 2 along axis 1 or
    turning it about axis 1 is the same as moving the base frame, so under the convention
    "base frame = axes 1 and 2" these two components are zero (the calibration's
    identifiability analysis finds them combined with the tracker pose). First order in the
    error, which is what ``exp6`` of a sub-millimetre error is.
    """
    model = nominal.model
    axis_1 = joint_infos(model)[0].s_angular
    axis_1 = axis_1 / np.linalg.norm(axis_1)
    in_joint_2 = model.jointPlacements[2].rotation.T @ axis_1  # axis 1 in joint 2's placement frame
    translation, rotation = error_2[:3].copy(), error_2[3:].copy()
    translation -= (translation @ in_joint_2) * in_joint_2
    rotation -= (rotation @ in_joint_2) * in_joint_2
    return np.concatenate([translation, rotation])


def _perturb_inertia(inertia: pin.Inertia, rng: np.random.Generator, cfg: TruthConfig) -> pin.Inertia:
    """A physically consistent random neighbour of ``inertia``.

    The second-moment matrix about the COM, ``Sigma = tr(I)/2 * 1 - I``, is positive definite
    for any physical body; it is perturbed as ``L Sigma L^T`` with ``L = expm(S)`` (S a small
    random matrix), which keeps it positive definite, so the new ``I = tr(Sigma) 1 - Sigma``
    is physically consistent (triangle inequalities hold).
    """
    mass = inertia.mass * float(np.exp(cfg.mass_relative_sigma * rng.standard_normal()))
    com = inertia.lever + cfg.com_shift_sigma_m * rng.standard_normal(3)
    sigma = 0.5 * np.trace(inertia.inertia) * np.eye(3) - inertia.inertia
    scale = expm(cfg.second_moment_relative_sigma / 2 * rng.standard_normal((3, 3)))
    sigma = scale @ sigma @ scale.T * (mass / inertia.mass)
    rotational = np.trace(sigma) * np.eye(3) - sigma
    return pin.Inertia(mass, com, 0.5 * (rotational + rotational.T))


class RealRobot:
    """A perturbed copy of the nominal robot with its sensors (see the module docstring)."""

    #: its torque readings are its drives' commands in closed loop (False: this simulator's arm follows
    #: the commanded motion exactly) and its dry friction holds a joint at rest (False: smooth Coulomb);
    #: the identification's validation counts both (:mod:`pipeline.identification.validate`)
    torques_in_closed_loop: bool = False
    dry_friction_sticks: bool = False

    def __init__(self, truth: RobotModel, kinematic_errors: np.ndarray, transform_tracker_to_base: pin.SE3,
                 config: TruthConfig, joint_stiffness_Nm_rad: np.ndarray | None = None,
                 transmission_cycles: np.ndarray | None = None, transmission_phase_rad: np.ndarray | None = None,
                 seed: int = 0, transform_camera_to_base: pin.SE3 | None = None) -> None:
        self._seed = int(seed)
        self._truth = truth
        self._kinematic_errors = kinematic_errors
        self._transform_tracker_to_base = transform_tracker_to_base
        self.config = config
        nq = truth.nq
        self._stiffness = (np.full(nq, np.inf) if joint_stiffness_Nm_rad is None
                           else np.asarray(joint_stiffness_Nm_rad, float))
        self._cycles = np.zeros(nq) if transmission_cycles is None else np.asarray(transmission_cycles, float)
        self._phase = np.zeros(nq) if transmission_phase_rad is None else np.asarray(transmission_phase_rad, float)
        gross = GrossErrors(config.tracker_outlier_rate, config.tracker_outlier_magnitude_m, config.tracker_stale_rate)
        self.tracker = LaserTracker(truth, transform_tracker_to_base, self.link_angles, gross)
        #: the optical 6-D tracker when robot.yaml declares one (pipeline.sim.optical_tracker), else None
        self.optical_tracker = (OpticalTracker(truth, transform_camera_to_base, self.link_angles)
                                if transform_camera_to_base is not None else None)
        self.encoders = Encoders(config.encoder_noise_rad)
        self.torque_sensor = TorqueSensor(config.torque_noise_fraction_of_limit * truth.limits.effort_Nm)
        self._plant: Plant | None = None
        self._transmission: Transmission | None = None

    @classmethod
    def create(cls, nominal: RobotModel, seed: int, config: TruthConfig | None = None) -> RealRobot:
        """The hidden robot of run seed ``seed``: same seed and config, same robot, bit for bit."""
        config = config if config is not None else TruthConfig()
        config.validate()
        rng = np.random.default_rng([int(seed), _TRUTH_SALT])
        nq = nominal.nq
        layout = KinematicLayout(nq)
        errors = np.zeros(layout.size)
        for i in range(1, nq + 1):
            errors[layout.placement(i)] = np.concatenate([
                config.placement_translation_sigma_m * rng.standard_normal(3),
                config.placement_rotation_sigma_rad * rng.standard_normal(3),
            ])
        errors[layout.joint_offsets] = config.joint_offset_sigma_rad * rng.standard_normal(nq)
        # The base frame is defined by axis 1 and its zero (the convention a tracker calibration
        # can realise: any placement error of joint 1 is indistinguishable from the unknown
        # tracker pose), so joint 1's placement and zero-offset errors are a choice of frame,
        # not robot errors: they are zero in the truth. Drawn anyway to keep the stream layout.
        errors[layout.placement(1)] = 0.0
        errors[layout.joint_offsets.start] = 0.0
        errors[layout.placement(2)] = _without_base_components(nominal, errors[layout.placement(2)])
        errors[layout.tool] = np.concatenate([config.tool_translation_sigma_m * rng.standard_normal(3),
                                              config.tool_rotation_sigma_rad * rng.standard_normal(3)])
        model = apply_kinematic_errors(nominal.model, errors, nominal.frame_flange,
                                       (nominal.frame_tcp, nominal.frame_reflector))
        for j in range(1, model.njoints):
            model.inertias[j] = _perturb_inertia(nominal.model.inertias[j], rng, config)
        spec = copy.deepcopy(nominal.spec)
        act = spec.actuation
        act.rotor_inertia_kgm2 = act.rotor_inertia_kgm2 * np.exp(
            config.rotor_inertia_relative_sigma * rng.standard_normal(nq))
        act.viscous_Nms_rad = act.viscous_Nms_rad * np.exp(config.friction_relative_sigma * rng.standard_normal(nq))
        act.coulomb_Nm = act.coulomb_Nm * np.exp(config.friction_relative_sigma * rng.standard_normal(nq))
        model.armature = act.rotor_inertia_kgm2.copy()
        truth = nominal.with_model(model, spec)
        tracker_error = np.concatenate([config.tracker_translation_sigma_m * rng.standard_normal(3),
                                        config.tracker_rotation_sigma_rad * rng.standard_normal(3)])
        tracker_pose = nominal.tracker.transform_tracker_to_base * pin.exp6(tracker_error)
        rng2 = np.random.default_rng([int(seed), _TRUTH_SALT + 1])
        spread = np.exp(config.joint_stiffness_relative_sigma * rng2.standard_normal(nq))
        cycles = rng2.integers(2, 7, nq).astype(float)
        phase = rng2.uniform(0.0, 2.0 * np.pi, nq)
        stiffness = (nominal_joint_stiffness_Nm_rad(nominal) * spread / config.joint_compliance_scale
                     if config.joint_compliance_scale > 0 else np.full(nq, np.inf))
        camera_pose = None
        if nominal.spec.optical_tracker is not None:   # own stream: nothing else changes
            rng3 = np.random.default_rng([int(seed), _TRUTH_SALT + 2])
            camera_pose = nominal.spec.optical_tracker.transform_camera_to_base * pin.exp6(np.concatenate([
                config.tracker_translation_sigma_m * rng3.standard_normal(3),
                config.tracker_rotation_sigma_rad * rng3.standard_normal(3)]))
        return cls(truth, errors, tracker_pose, config, stiffness, cycles, phase, seed, camera_pose)

    # ------------------------------------------------------------ stage-facing
    def execute_joint_trajectory(self, t_s: np.ndarray, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                                 rng: np.random.Generator) -> JointMeasurement:
        """Ideal tracking of ``(q, v, a)``: encoder readings and joint torques (motor currents
        through the gear matrix) with sensor noise. Torque saturation is not modelled here;
        use :attr:`plant` for a closed-loop experiment.

        The torque is the rigid-body torque plus the transmission's friction, the same function
        the plant integrates (:meth:`Transmission.friction_torque`: Stribeck excess and Coulomb
        friction growing with the transmitted torque); like the rigid plant, the load is the motor
        torque itself, ``tau = rnea(q, v, a) + f(v, |tau|)``, solved by fixed-point iteration
        (a contraction: ``mu F_c / tau_max`` is far below 1). With the Stribeck numbers at 0 this
        is ``truth.inverse_dynamics`` bit for bit."""
        q, v, a = (np.atleast_2d(np.asarray(x, float)) for x in (q, v, a))
        if not (len(t_s) == len(q) == len(v) == len(a)):
            raise ConfigError(None, "trajectory", f"t, q, v, a have different lengths "
                              f"({len(t_s)}, {len(q)}, {len(v)}, {len(a)})")
        model, data = self._truth.model, self._truth.model.createData()
        rigid = np.array([pin.rnea(model, data, qk, vk, ak) for qk, vk, ak in zip(q, v, a, strict=True)])
        tr = self.transmission
        tau = rigid + tr.friction_torque(v)
        if np.any(tr.coulomb_load_coefficient > 0):
            for _ in range(_LOAD_ITERATIONS):
                tau = rigid + tr.friction_torque(v, tau)
        return JointMeasurement(np.asarray(t_s, float).copy(), self.encoders.read(q, rng),
                                self.torque_sensor.read(tau, rng), self.torque_sensor.sigma_Nm.copy(),
                                self.encoders.noise_rad)

    @property
    def plant(self) -> Plant:
        """The physical arm behind the drives (closed-loop simulation, stage 3)."""
        if self._plant is None:
            self._plant = Plant(self._truth, encoder_noise_rad=self.config.encoder_noise_rad,
                                transmission=self.transmission)
        return self._plant

    def link_angles(self, Q: np.ndarray, payload: Payload | None = None) -> np.ndarray:
        """Link-side joint angles of static poses commanded at encoder angles ``Q`` (module docstring):
        ``q_link = q - g(q_link) / k + A sin(n q + phi)``; ``Q`` itself for the ideal robot."""
        Q = np.atleast_2d(np.asarray(Q, float))
        amplitude = self.config.transmission_error_amplitude_rad
        rigid = not np.any(np.isfinite(self._stiffness))
        if rigid and amplitude == 0.0:
            return Q
        Q_link = Q + amplitude * np.sin(self._cycles * Q + self._phase) if amplitude > 0 else Q.copy()
        if not rigid:
            model = with_payload(self._truth.model, self._truth.frame_flange, payload)
            base = Q_link.copy()
            for _ in range(3):
                Q_link = base - gravity_torques_Nm(model, Q_link) / self._stiffness
        return Q_link

    @property
    def joint_stiffness_Nm_rad(self) -> np.ndarray:
        """Tests and the plant only: the true torsional joint stiffness (np.inf: rigid)."""
        return self._stiffness.copy()

    @property
    def transmission(self) -> Transmission:
        """Tests and the plant only: stiffness, damping and friction of the hidden joints."""
        if self._transmission is None:
            c = self.config
            self._transmission = create_transmission(
                self._truth, self._seed, self._stiffness, c.joint_damping_ratio,
                c.stribeck_excess_relative, c.stribeck_velocity_rad_s, c.coulomb_load_coefficient,
                c.friction_relative_sigma)
        return self._transmission

    # -------------------------------------------------------------- tests only
    @property
    def truth(self) -> RobotModel:
        """Tests only: the hidden robot model."""
        return self._truth

    @property
    def kinematic_errors(self) -> np.ndarray:
        """Tests only: the kinematic error vector (SymbolicRobot layout) of the truth."""
        return self._kinematic_errors.copy()

    @property
    def transform_tracker_to_base(self) -> pin.SE3:
        """Tests only: the true tracker placement."""
        return self._transform_tracker_to_base.copy()

    @property
    def transform_camera_to_base(self) -> pin.SE3 | None:
        """Tests only: the true optical-tracker camera-bar placement (None: no optical tracker)."""
        return None if self.optical_tracker is None else self.optical_tracker._transform_camera_to_base.copy()

    @property
    def reflector_offset_m(self) -> np.ndarray:
        """Tests only: the true reflector position in the flange frame."""
        model = self._truth.model
        flange = model.frames[model.getFrameId(self._truth.frame_flange)].placement
        reflector = model.frames[model.getFrameId(self._truth.frame_reflector)].placement
        return (flange.inverse() * reflector).translation.copy()

    @property
    def dynamic_parameters(self) -> np.ndarray:
        """Tests only: the true ``p_dyn`` (SymbolicRobot layout, offsets zero)."""
        act = self._truth.actuation
        return pinocchio_dynamic_parameters(self._truth.model, act.viscous_Nms_rad, act.coulomb_Nm)
