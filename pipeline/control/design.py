"""Servo design of the per-joint cascade with python-control (paper 004 §2.3, DESIGN.md "Control").

Per joint ``i`` the drive sees the reflected inertia ``J_i = M_ii(q_ref)`` (``M`` from CRBA,
including the rotor inertia ``model.armature``). For a velocity-loop bandwidth ``w_v`` and a
position-loop bandwidth ``w_p`` (rad/s)::

    Kv = J w_v,   Ki = Kv w_v / n_i   (PI zero a factor n_i below crossover),   Kp = w_p

Stick-slip floor (:func:`stick_slip_gains`): a Stribeck friction curve falls with speed by up to
``s = sqrt(2/e) f_s / v_s`` (:func:`pipeline.robot.friction.stribeck_slope_Nms_rad`), a negative
damping on the motor. Where ``Kv + f_v < s`` the velocity loop is unstable at low speed whatever the
feedforward: a joint creeping through zero speed sticks and then slips (Dupont, "Avoiding stick-slip
through PD control", IEEE Trans. Automatic Control 39(5), 1994: enough derivative gain removes it;
``benchmarks/bench_elastic_floor.py``). So ``Kv >= m s - f_v`` with a margin ``m``, and ``Ki`` scaled
by the same factor (the PI zero stays where it was; the crossover rises). The raised crossover
``Kv / J`` is capped at the velocity filter's corner (phase margin ~44 deg there with the 150 Hz
filter at 200 µs; ~64 deg at the 30 Hz design); where the cap binds the joint keeps some stick-slip.

Loop models for Bode plots and margins, at the velocity sample time ``T_v``:
    plant      q/tau = ZOH{1 / (J s^2)}
    velocity   v_hat = alpha / (1 - (1 - alpha) z^-1) * (1 - z^-1) / T_v * q
    PI         C_v(z) = Kv + Ki T_v z / (z - 1)
    L_v = C_v P D F (loop broken at the torque);  velocity loop closed: T_v(z) = v_hat / v_cmd
    position   L_p = Kp T_v / (z - 1) * T_v(z) * z^-(r d_m + r/2), r = T_p / T_v
               (the measurement delay of d_m position samples and half a position-loop hold).

The reference the servo follows (:func:`iso_reference`): the EN ISO 9283 path of ``control.iso``
with a ruckig speed profile and IK at every sample (paper 004 §2.3.3).
"""

from __future__ import annotations

import copy
import time
import warnings
from dataclasses import dataclass

import control as ct
import numpy as np
import pinocchio as pin

from pipeline.control.config import ControlConfig
from pipeline.core.errors import InfeasibleError
from pipeline.robot.defaults import ik_seeds_or_derived_rad, iso_or_derived, iso_rotation
from pipeline.robot.iso9283 import IsoPath, IsoPathConfig, iso9283_path
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import start_configuration
from pipeline.robot.reference import Reference, cartesian_reference, torque_time_scale


@dataclass
class ServoGains:
    kp: np.ndarray            # 1/s       position loop
    kv: np.ndarray            # N m s/rad velocity loop proportional
    ki: np.ndarray            # N m/rad   velocity loop integral
    inertia_kgm2: np.ndarray  # reflected inertia the design used

    def as_dict(self) -> dict[str, np.ndarray]:
        return {"kp": self.kp, "kv": self.kv, "ki": self.ki}


def reflected_inertia(robot: RobotModel, q_ref: np.ndarray) -> np.ndarray:
    """Diagonal of the joint-space inertia (CRBA incl. rotor inertia) at ``q_ref``."""
    data = robot.model.createData()
    M = pin.crba(robot.model, data, np.asarray(q_ref, float))
    return np.diag(M).copy()


def design_gains(inertia_kgm2: np.ndarray, position_bandwidth_rad_s: np.ndarray,
                 velocity_bandwidth_rad_s: np.ndarray, pi_zero_ratio: float = 4.0) -> ServoGains:
    J = np.asarray(inertia_kgm2, float)
    wv = np.broadcast_to(np.asarray(velocity_bandwidth_rad_s, float), J.shape)
    wp = np.broadcast_to(np.asarray(position_bandwidth_rad_s, float), J.shape)
    kv = J * wv
    return ServoGains(kp=wp.copy(), kv=kv, ki=kv * wv / pi_zero_ratio, inertia_kgm2=J.copy())


def stick_slip_gains(gains: ServoGains, slope_Nms_rad: np.ndarray, viscous_Nms_rad: np.ndarray,
                     margin: float, max_bandwidth_rad_s: float) -> ServoGains:
    """``Kv_i >= margin * slope_i - viscous_i`` per joint, at most ``J_i * max_bandwidth_rad_s`` (never
    below the design's ``Kv``), ``Ki`` scaled alike (module docstring)."""
    floor = margin * np.asarray(slope_Nms_rad, float) - np.asarray(viscous_Nms_rad, float)
    cap = np.maximum(gains.kv, gains.inertia_kgm2 * max_bandwidth_rad_s)
    kv = np.minimum(np.maximum(gains.kv, floor), cap)
    return ServoGains(kp=gains.kp.copy(), kv=kv, ki=gains.ki * kv / gains.kv, inertia_kgm2=gains.inertia_kgm2.copy())


def loop_models(J: float, kp: float, kv: float, ki: float, sample_time_s: float, velocity_samples: int,
                measurement_delay_samples: int, velocity_filter_alpha: float) -> dict[str, ct.TransferFunction]:
    """Discrete loop transfer functions of one joint at the velocity sample time (see module doc)."""
    Tv = sample_time_s / velocity_samples
    plant = ct.sample_system(ct.tf([1.0], [J, 0.0, 0.0]), Tv, method="zoh")
    z = ct.tf([1.0, 0.0], [1.0], Tv)
    a = velocity_filter_alpha
    diff = (z - 1) / (Tv * z)
    filt = a * z / (z - (1 - a))
    pi = kv + ki * Tv * z / (z - 1)
    L_v = ct.minreal(pi * plant * diff * filt, verbose=False)
    # closed velocity loop from v_cmd to v_hat:  pi*P*D*F / (1 + pi*P*D*F)
    T_vel = ct.minreal(ct.feedback(L_v, 1), verbose=False)
    r = velocity_samples
    n_delay = r * measurement_delay_samples + r // 2
    delay = ct.tf([1.0], [1.0] + [0.0] * n_delay, Tv) if n_delay > 0 else ct.tf([1.0], [1.0], Tv)
    integ = ct.tf([Tv], [1.0, -1.0], Tv)
    L_p = ct.minreal(kp * integ * T_vel * delay, verbose=False)
    T_pos = ct.minreal(ct.feedback(L_p, 1), verbose=False)
    return {"velocity_open": L_v, "velocity_closed": T_vel, "position_open": L_p, "position_closed": T_pos}


def margins(sys: ct.TransferFunction) -> dict[str, float]:
    """Gain margin (dB), phase margin (deg), crossover frequencies (Hz), closed-loop stability."""
    with warnings.catch_warnings():  # python-control falls back to FRD margins near z = 1: expected
        warnings.simplefilter("ignore", UserWarning)
        gm, pm, _sm, wpc, wgc, _ws = ct.stability_margins(sys)
    closed = ct.feedback(sys, 1)
    stable = bool(np.all(np.abs(closed.poles()) < 1.0))
    return {"gain_margin_db": float(20 * np.log10(gm)) if np.isfinite(gm) and gm > 0 else float("inf"),
            "phase_margin_deg": float(pm), "phase_crossover_hz": float(wpc / 2 / np.pi),
            "gain_crossover_hz": float(wgc / 2 / np.pi), "closed_loop_stable": stable}


def bandwidth_hz(closed: ct.TransferFunction) -> float:
    """-3 dB bandwidth of a closed loop (Hz)."""
    w = np.logspace(-1, np.log10(np.pi / closed.dt) - 0.01, 2000)
    mag = np.abs(closed(np.exp(1j * w * closed.dt)))
    below = np.nonzero(mag < mag[0] / np.sqrt(2))[0]
    return float(w[below[0]] / 2 / np.pi) if len(below) else float("nan")


def servo_report(gains: ServoGains, sample_time_s: float, velocity_samples: int, measurement_delay_samples: int,
                 velocity_filter_alpha: float) -> list[dict]:
    """Margins and bandwidths of every joint's velocity and position loops."""
    rows = []
    for i in range(len(gains.kp)):
        lm = loop_models(gains.inertia_kgm2[i], gains.kp[i], gains.kv[i], gains.ki[i], sample_time_s,
                         velocity_samples, measurement_delay_samples, velocity_filter_alpha)
        mv, mp = margins(lm["velocity_open"]), margins(lm["position_open"])
        rows.append({"joint": i + 1, "inertia_kgm2": float(gains.inertia_kgm2[i]),
                     "kp_1_s": float(gains.kp[i]), "kv_Nms_rad": float(gains.kv[i]), "ki_Nm_rad": float(gains.ki[i]),
                     "velocity": mv, "position": mp,
                     "velocity_bandwidth_hz": bandwidth_hz(lm["velocity_closed"]),
                     "position_bandwidth_hz": bandwidth_hz(lm["position_closed"])})
    return rows


def filter_alpha(cutoff_hz: float, velocity_sample_time_s: float) -> float:
    """First-order low-pass coefficient: alpha = 1 - exp(-2 pi f_c T_v)."""
    return float(1.0 - np.exp(-2 * np.pi * cutoff_hz * velocity_sample_time_s))


@dataclass
class IsoReference:
    """The reference the stage follows (:func:`iso_reference`): the joint reference, the path, its frame,
    the IK seeds and start, the ISO settings it ran (None fields derived from the robot, a derived path
    slowed), the seconds it took, whether the cube was derived (``control.iso`` gave no centre or edge)
    and the time scale ``s`` of the slowing (1: none)."""

    ref: Reference
    path: IsoPath
    frame: str
    seeds: np.ndarray
    q_start: np.ndarray
    iso: IsoPathConfig
    time_s: float
    derived_cube: bool = True
    time_scale: float = 1.0


def iso_reference(robot: RobotModel, cfg: ControlConfig) -> IsoReference:
    """The EN ISO 9283 path of ``cfg.iso`` (None fields derived from ``robot``) and its joint reference
    (:class:`IsoReference`), from ruckig + IK at every sample with ``robot``'s kinematics. A derived
    cube's path is slowed (:func:`slowed_reference`) until ``robot``'s inverse dynamics asks at most
    ``PATH_TORQUE_SHARE`` of every torque limit (:func:`pipeline.robot.reference.torque_time_scale`); a
    cube given in the config runs as given. Raises InfeasibleError naming ``control.iso`` when the path
    leaves the workspace."""
    t0 = time.perf_counter()
    iso = iso_or_derived(robot, cfg.iso)
    frame = robot.frame_reflector if cfg.path_frame == "reflector" else robot.frame_tcp
    rotation = iso_rotation(robot, iso.plane, iso.tool_orientation)
    path = iso9283_path(robot, iso.edge_m, iso.centre_m, iso.plane, rotation, iso.corner_fraction,
                        iso.large_circle_fraction, iso.small_circle_fraction, tuple(iso.segments))
    seeds = ik_seeds_or_derived_rad(robot, cfg.ik_seeds_deg)
    derived_cube = cfg.iso.centre_m is None or cfg.iso.edge_m is None
    try:
        q_start = start_configuration(robot, path.poses(np.array([0.0]))[0], seeds, frame)
        ref = cartesian_reference(robot, path, cfg.sample_time_s, iso.speed_m_s, iso.acceleration_m_s2,
                                  iso.jerk_m_s3, q_start, frame, cfg.ik_tolerance_m)
    except InfeasibleError as exc:
        raise InfeasibleError(exc.file, "control.iso", f"{exc.field}: {exc.problem}; the ISO path (cube centre "
                              f"{iso.centre_m} m, edge {iso.edge_m} m) must lie in this robot's workspace: set "
                              "control.iso.centre_m / edge_m in the run config, or run_defaults in its robot.yaml"
                              ) from None
    out = IsoReference(ref, path, frame, seeds, q_start, iso, 0.0, derived_cube)
    scale = torque_time_scale(robot, ref) if derived_cube else 1.0
    if scale < 1.0:
        out = slowed_reference(robot, cfg, out, scale)
    out.time_s = time.perf_counter() - t0
    return out


def slowed_reference(robot: RobotModel, cfg: ControlConfig, iso: IsoReference, scale: float) -> IsoReference:
    """``iso`` slowed by ``scale`` (rounded down to whole percent): the same path and start, speed,
    acceleration and jerk times ``s``, ``s^2``, ``s^3`` (exactly the time-scaled motion
    ``q(s t)``, :mod:`pipeline.robot.reference`), IK at every sample again; ``time_scale`` multiplies."""
    scale = float(np.floor(100 * scale) / 100)
    settings = copy.copy(iso.iso)
    settings.speed_m_s, settings.acceleration_m_s2, settings.jerk_m_s3 = (
        settings.speed_m_s * scale, settings.acceleration_m_s2 * scale**2, settings.jerk_m_s3 * scale**3)
    ref = cartesian_reference(robot, iso.path, cfg.sample_time_s, settings.speed_m_s, settings.acceleration_m_s2,
                              settings.jerk_m_s3, iso.q_start, iso.frame, cfg.ik_tolerance_m)
    return IsoReference(ref, iso.path, iso.frame, iso.seeds, iso.q_start, settings, iso.time_s, iso.derived_cube,
                        iso.time_scale * scale)


@dataclass
class ServoDesign:
    """The servo every run shares: gains, velocity samples per position sample, the velocity filter's
    ``alpha`` and the margins and bandwidths of each joint (:func:`servo_report`)."""

    gains: ServoGains
    velocity_samples: int
    alpha: float
    report: list[dict]

    def loop_models(self, joints: int, sample_time_s: float, measurement_delay_samples: int
                    ) -> list[dict[str, ct.TransferFunction]]:
        """:func:`loop_models` of the first ``joints`` joints (the Bode figure)."""
        g = self.gains
        return [loop_models(g.inertia_kgm2[i], g.kp[i], g.kv[i], g.ki[i], sample_time_s, self.velocity_samples,
                            measurement_delay_samples, self.alpha) for i in range(joints)]
