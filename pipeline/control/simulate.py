"""Execute a joint trajectory with the cascaded drives on the real robot's plant.

Paper 004 §2.3 (DESIGN.md "Control"): set points ``q_d`` and ``v_d`` go to the P position loop
with velocity feedforward; the feedforward torque ``tau_ff`` of the chosen variant is added to
the current set value::

    none           tau_ff = 0
    gravity        tau_ff = g(q_d)
    full           tau_ff = M(q_d) a_d + h(q_d, v_d)            (rotor inertia included)
    full_friction  tau_ff = M(q_d) a_d + h(q_d, v_d) + viscous v_d + coulomb tanh(v_d / width)
                   (+ the identified Stribeck and load-dependent terms, same width)
    elastic_static / elastic_flat   motor set points leading the link by the joint deflection
                   (:mod:`pipeline.control.elastic_feedforward`)

Set points reach the drives ``setpoint_delay_samples`` late; with ``advance_feedforward`` they are
sent that many samples early so they arrive on time. The drive aligns its set point with the
measurement, which is ``measurement_delay_samples`` old. Within a position sample the velocity
loop gets its own set points: ``v_d`` delayed by the known group delay of the differenced and
low-passed encoder velocity, and ``tau_ff`` at the middle of each 200 µs hold (both interpolated);
without that a held 400 µs set point lags by 100 µs on average, which alone leaves a lag error
``~ a * 100 µs / Kp`` (measured: 1.3 mdeg on axis 1 of the ISO path with the exact model).

The friction feedforward's Coulomb width (:func:`feedforward_coulomb_width`). The model's ``width``
(0.01 rad/s by default) is the identification's smoothing of the sign of measured, noisy speeds. On an
arm with that smooth law (the own simulator's) the feedforward takes it as it is. On an arm whose dry
friction sticks (``real.dry_friction_sticks``: the friction opposes the joint's velocity with its full
Coulomb level at any speed and holds it at rest) ``tanh(v_d / width)`` would feed forward less than the
arm's friction wherever the joint moves slower than about ``2 width``: at 0.003 rad/s 29 % of it, and
the servo must build the rest from a lag (RX130L in MuJoCo, ISO path: axis 5 creeping through a slow
stretch at t = 3.17 s, 731 µrad). The reference velocity is exact (no noise to smooth), so there the
sign switches with ``control.sticking_friction_width_rad_s`` (1e-3 rad/s; the model's width where that
is narrower), above the joint's own velocity jitter about its set point under the encoder noise
(1-3e-4 rad/s on that path), below which the sign of its velocity is the noise's.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin
from scipy.interpolate import CubicHermiteSpline

from pipeline.control.config import FEEDFORWARD_VARIANTS, ControlConfig
from pipeline.control.design import ServoGains, design_gains, filter_alpha, reflected_inertia, stick_slip_gains
from pipeline.control.elastic_feedforward import ELASTIC_VARIANTS, elastic_feedforward
from pipeline.core.errors import ConfigError, InfeasibleError, SolverError
from pipeline.robot.friction import has_stribeck, joint_friction_torque, load_friction_torque, stribeck_slope_Nms_rad
from pipeline.robot.model import RobotModel


@dataclass
class ClosedLoopResult:
    t_s: np.ndarray             # (N,) sample times of the trajectory (control grid)
    q: np.ndarray               # (N, nq) encoder positions
    v: np.ndarray               # (N, nq) drive velocity estimate
    q_d: np.ndarray             # (N, nq) desired positions
    tau_cmd: np.ndarray         # (N, nq) torque command (mean over the velocity samples)
    tau_ff: np.ndarray          # (N, nq) feedforward torque
    lag_error_rad: np.ndarray   # (N, nq) q_d - q
    max_torque_ratio: np.ndarray  # (nq,) max |tau_cmd| / tau_max
    realtime_factor: float      # simulated time / wall time of the loop
    tcp_position_m: np.ndarray | None = None   # (N, 3) measured TCP (ideal tracker, base frame)
    q_link: np.ndarray | None = None           # (N, nq) true link positions (tests / hidden-robot studies)
    q_motor: np.ndarray | None = None          # (N, nq) true motor positions, joint side (elastic plant)
    q_set: np.ndarray | None = None            # (N, nq) the drive's position set point (motor side)
    wall_time_s: float = 0.0
    gains: ServoGains | None = None
    torque_ratio: np.ndarray | None = None     # (N, nq) per-sample max |tau_cmd| / tau_max
    realtime_factor_cpu: float = 0.0           # simulated time / CPU time of the loop thread


def feedforward_coulomb_width(real, model: RobotModel, config: ControlConfig) -> np.ndarray | None:
    """The Coulomb switching width (rad/s, per joint) of the friction feedforward on ``real``: on an arm whose
    dry friction sticks (``real.dry_friction_sticks``) ``min(config.sticking_friction_width_rad_s, w)``, ``w``
    the model's smoothing width of the joint; None (the model's own law) on an arm with smooth Coulomb friction
    (module docstring)."""
    if not getattr(real, "dry_friction_sticks", False):
        return None
    return np.minimum(float(config.sticking_friction_width_rad_s), model.spec.actuation.coulomb_smoothing_rad_s)


def feedforward_torque(model, q_d: np.ndarray, v_d: np.ndarray, a_d: np.ndarray, variant: str,
                       coulomb_width_rad_s: np.ndarray | None = None) -> np.ndarray:
    """Feedforward torques (N, nq) of a variant from ``model`` (RobotModel); the friction's smooth sign
    ``tanh(v_d / w)`` with ``w = coulomb_width_rad_s`` (None: the model's width,
    :func:`feedforward_coulomb_width`)."""
    if variant not in FEEDFORWARD_VARIANTS:
        raise ConfigError(None, "feedforward", f"unknown variant {variant!r}; one of {FEEDFORWARD_VARIANTS}")
    N, n = q_d.shape
    if variant == "none":
        return np.zeros((N, n))
    data = model.model.createData()
    zero = np.zeros(n)
    out = np.empty((N, n))
    for k in range(N):
        if variant == "gravity":
            out[k] = pin.rnea(model.model, data, q_d[k], zero, zero)
        else:
            out[k] = pin.rnea(model.model, data, q_d[k], v_d[k], a_d[k])
    if variant in ("full_friction", *ELASTIC_VARIANTS):
        if coulomb_width_rad_s is None:
            out += model.friction_torque(v_d)
            out += model.load_friction_torque(out, v_d)   # load: the model's torque without that term
        else:
            act = replace(model.spec.actuation, coulomb_smoothing_rad_s=np.broadcast_to(
                np.asarray(coulomb_width_rad_s, float), (n,)).copy())
            out += joint_friction_torque(act, v_d)
            out += load_friction_torque(act, out, v_d)
    return out


def resample(t_s: np.ndarray, q: np.ndarray, v: np.ndarray, a: np.ndarray, dt: float):
    """Onto the uniform control grid: cubic Hermite for q (with v), linear for v and a."""
    t_s = np.asarray(t_s, float)
    if len(t_s) < 2 or np.any(np.diff(t_s) <= 0):
        raise ConfigError(None, "t_s", "trajectory times must be strictly increasing (>= 2 samples)")
    n_grid = int(np.floor((t_s[-1] - t_s[0]) / dt + 1e-9)) + 1
    grid = t_s[0] + dt * np.arange(n_grid)
    if len(t_s) == n_grid and np.allclose(t_s, grid, atol=1e-9 * max(1.0, abs(t_s[-1]))):
        return grid, q, v, a
    qs = CubicHermiteSpline(t_s, q, v, axis=0)(grid)
    vs = np.stack([np.interp(grid, t_s, v[:, j]) for j in range(q.shape[1])], axis=1)
    acc = np.stack([np.interp(grid, t_s, a[:, j]) for j in range(q.shape[1])], axis=1)
    return grid, qs, vs, acc


def drive_inputs(q_d, v_d, tau_ff, setpoint_delay: int, measurement_delay: int, advance: bool):
    """What reaches the drive at each sample: (q_d aligned with the delayed measurement, v_ff, tau_ff).

    Set points travel ``setpoint_delay`` samples. With ``advance`` the PC sends the reference of
    sample ``k + d`` at sample ``k`` (it knows the delay), so the drive sees ``ref[k]`` on time;
    without, it sees ``ref[k - d]``. The drive compares the measurement, ``measurement_delay``
    samples old, with its set point of that same sample.
    """
    N = len(q_d)
    k = np.arange(N)
    shift = 0 if advance else setpoint_delay
    idx = np.clip(k - shift, 0, N - 1)
    idx_fb = np.clip(k - shift - measurement_delay, 0, N - 1)
    return q_d[idx_fb], v_d[idx], tau_ff[idx]


def _interp_rows(t_new: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Linear interpolation of every column of X (held constant outside t)."""
    return np.stack([np.interp(t_new, t, X[:, j]) for j in range(X.shape[1])], axis=1)


def servo_gains(model, q_ref: np.ndarray, config: ControlConfig) -> ServoGains:
    """Gains from ``model``'s reflected inertia at ``q_ref``; with an identified Stribeck term and
    ``config.stick_slip_margin > 0``, ``Kv`` raised to the stick-slip floor (:mod:`pipeline.control.design`)."""
    J = reflected_inertia(model, q_ref)
    gains = design_gains(J, 2 * np.pi * config.position_bandwidth_hz, 2 * np.pi * config.velocity_bandwidth_hz,
                         config.pi_zero_ratio)
    act = model.spec.actuation
    if config.stick_slip_margin > 0 and has_stribeck(act):
        slope = stribeck_slope_Nms_rad(act.static_friction_excess_Nm, act.stribeck_velocity_rad_s)
        gains = stick_slip_gains(gains, slope, act.viscous_Nms_rad, config.stick_slip_margin,
                                 2 * np.pi * config.velocity_filter_hz)
    return gains


def simulate_joint_trajectory(real, model, t_s, q_d, v_d, a_d, config: ControlConfig | None = None,
                              feedforward: str = "full_friction", rng: np.random.Generator | None = None,
                              gains: ServoGains | None = None, tcp_frame: str = "tcp",
                              hold_end_s: float = 0.0) -> ClosedLoopResult:
    """Run the trajectory (t_s (N,), q_d/v_d/a_d (N, nq)) on ``real.plant`` and return the record.

    ``model`` (RobotModel) gives the feedforward and the servo design (reflected inertia at the
    mean of ``q_d``). The trajectory is resampled to the control grid if needed. A trajectory that
    starts at rest is preceded by ``config.settle_time_s`` of holding ``q_d[0]`` (not part of the
    result); one that starts moving starts with the plant on ``(q_d[0], v_d[0])``.
    ``hold_end_s`` > 0 appends that long a hold of the last set point (residual vibration after a
    move; the result then covers it). The lag error is the drive's: set point (motor side for the
    elastic variants) minus encoder. Raises InfeasibleError naming time and joint if the torque
    command saturates (``config.on_saturation == "error"``).
    """
    config = config or ControlConfig()
    rng = rng if rng is not None else np.random.default_rng(0)
    q_d, v_d, a_d = (np.atleast_2d(np.asarray(x, float)) for x in (q_d, v_d, a_d))
    if not (q_d.shape == v_d.shape == a_d.shape) or q_d.shape[1] != model.model.nq or len(q_d) != len(t_s):
        raise ConfigError(None, "q_d/v_d/a_d", f"shapes {q_d.shape}, {v_d.shape}, {a_d.shape} do not match "
                          f"t_s ({len(t_s)},) and nq = {model.model.nq}")
    dt = config.sample_time_s
    t, q_d, v_d, a_d = resample(np.asarray(t_s, float), q_d, v_d, a_d, dt)
    n_hold = int(round(hold_end_s / dt))
    if n_hold > 0:
        t = np.concatenate([t, t[-1] + dt * np.arange(1, n_hold + 1)])
        q_d = np.vstack([q_d, np.repeat(q_d[-1:], n_hold, 0)])
        v_d, a_d = (np.vstack([x, np.zeros((n_hold, x.shape[1]))]) for x in (v_d, a_d))
    moving = bool(np.abs(v_d[0]).max() > 1e-9)
    # a trajectory that starts at rest is preceded by a hold (integrators settle on gravity); one that
    # starts moving starts on its state directly
    n_settle = 0 if moving else int(round(config.settle_time_s / dt))
    pad = lambda x, first: np.vstack([np.repeat(first[None], n_settle, 0), x])  # noqa: E731
    zero = np.zeros_like(q_d[0])
    Q, V, A = pad(q_d, q_d[0]), pad(v_d, zero), pad(a_d, zero)
    tau_ff = feedforward_torque(model, Q, V, A, feedforward, feedforward_coulomb_width(real, model, config))
    Q_set, V_set = Q, V
    if feedforward in ELASTIC_VARIANTS:
        Q_set, V_set, tau_ff = elastic_feedforward(model, dt, Q, V, A, feedforward, tau_ff)
    if gains is None:
        gains = servo_gains(model, np.mean(q_d, axis=0), config)
    d_s, d_m = config.setpoint_delay_samples, config.measurement_delay_samples
    nv = config.velocity_samples_per_position_sample
    Tv = dt / nv
    alpha = filter_alpha(config.velocity_filter_hz, Tv)
    tt = dt * np.arange(len(Q))
    # v_hat is the backward difference (delay T_v/2) low-passed (delay (1-alpha)/alpha T_v): the
    # velocity set point of each sub-sample is delayed alike (the drive knows its own filter)
    v_delay = Tv / 2 + (1 - alpha) / alpha * Tv if config.compensate_velocity_estimate_delay else 0.0
    V_sub, T_sub = [], []
    for j in range(nv):
        V_sub.append(_interp_rows(tt + j * Tv - v_delay, tt, V_set))
        T_sub.append(_interp_rows(tt + (j + 0.5) * Tv, tt, tau_ff))  # torque held over the sub-sample
    q_fb, v_ff, tau_drive = drive_inputs(Q_set, np.hstack(V_sub), np.hstack(T_sub), d_s, d_m,
                                         config.advance_feedforward)
    plant = real.plant
    rec = plant.run_servo(gains.as_dict(), dt, nv, d_m, alpha,
                          q_fb, v_ff, tau_drive, Q[0], rng, engine=config.engine,
                          chunk_samples=config.chunk_samples, tcp_frame=tcp_frame, v0=V[0])
    check_finite(dt * (np.arange(len(Q)) - n_settle), rec.q_meas, model, np.mean(q_d, axis=0))
    s = slice(n_settle, None)
    q_meas = rec.q_meas[s]
    ratio = rec.torque_ratio[s]
    result = ClosedLoopResult(
        t_s=t, q=q_meas, v=rec.v_est[s], q_d=q_d, tau_cmd=rec.tau_cmd[s], tau_ff=tau_ff[s],
        lag_error_rad=Q_set[s] - q_meas, max_torque_ratio=ratio.max(axis=0),
        realtime_factor=float(len(Q) * dt / max(rec.wall_time_s, 1e-12)),
        tcp_position_m=None if rec.tcp_position_m is None else rec.tcp_position_m[s],
        wall_time_s=rec.wall_time_s, gains=gains, torque_ratio=ratio,
        realtime_factor_cpu=float(len(Q) * dt / max(rec.cpu_time_s, 1e-12)),
        q_link=None if rec.q_link is None else rec.q_link[s], q_motor=None if rec.q_motor is None else rec.q_motor[s],
        q_set=Q_set[s])
    check_saturation(result, config)
    return result


def check_finite(t_s: np.ndarray, q_meas: np.ndarray, model: RobotModel, q_mean: np.ndarray) -> None:
    """Raise SolverError when the closed loop's measured positions ``q_meas`` (N, nq) at times ``t_s`` are not
    all finite (the loop diverged): the first time, the joints not finite there and the joint of least
    inertia in the model at ``q_mean``, which the servo gains come from (:func:`servo_gains`); a model with
    next to no inertia on a joint (rotor inertia fitted to its bound on a record) gives gains no drive runs."""
    bad = ~np.isfinite(q_meas)
    if not bad.any():
        return
    k = int(np.argwhere(bad.any(axis=1))[0, 0])
    joints = ", ".join(str(j + 1) for j in np.flatnonzero(bad[k]))
    inertia = np.diag(model.mass_matrix(q_mean))
    j = int(np.argmin(inertia))
    raise SolverError(None, "control", f"the closed loop diverged at t = {t_s[k]:.4f} s (joint(s) {joints} not "
                      f"finite); the servo gains come from the model's inertia, least on joint {j + 1}: "
                      f"{inertia[j]:.3g} kg m² (rotor inertia {float(model.model.armature[j]):.3g} kg m²): check "
                      "the robot's rotor and link inertias (robot.yaml)")


def first_saturation(result: ClosedLoopResult, ratio_limit: float = 1.0) -> dict | None:
    """Time, joint (1-based) and ratio of the first sample where |tau_cmd| > ratio_limit * tau_max."""
    if result.torque_ratio is None:
        return None
    over = result.torque_ratio > ratio_limit
    if not over.any():
        return None
    k, j = np.argwhere(over)[0]
    return {"t_s": float(result.t_s[k]), "joint": int(j + 1), "ratio": float(result.torque_ratio[k, j]),
            "max_ratio": float(result.max_torque_ratio[j])}


def check_saturation(result: ClosedLoopResult, config: ControlConfig) -> None:
    """Raise InfeasibleError naming the first time and joint where |tau_cmd| > ratio * tau_max."""
    if config.on_saturation != "error":
        return
    sat = first_saturation(result, config.saturation_ratio)
    if sat is not None:
        raise InfeasibleError(None, "control", f"torque saturation at t = {sat['t_s']:.4f} s on joint {sat['joint']}: "
                              f"|tau_cmd| = {sat['ratio']:.2f} x tau_max (max over the run {sat['max_ratio']:.2f}); "
                              "slow the trajectory down or set control.on_saturation = clip")
