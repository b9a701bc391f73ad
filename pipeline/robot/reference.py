"""Reference generation: TCP path -> jerk-limited speed profile -> IK -> consistent q_d, v_d, a_d.

Paper 004 §2.3.2: "every sample step the inverse kinematic problem is solved numerically to
transform the desired end-effector movement into joint positions, velocities and accelerations".

* Each segment of the path (pieces with a continuous tangent) gets a rest-to-rest, jerk-limited
  profile ``s(t)`` from ruckig (max speed, tangential acceleration, jerk); on curved pieces the
  speed is also capped by the normal acceleration, ``s_dot <= sqrt(a_max / kappa_max)``.
* ``p_dot = p'(s) s_dot``, ``p_ddot = p''(s) s_dot^2 + p'(s) s_ddot``; the orientation is constant.
* IK at every sample warm-started from the previous one (:func:`pipeline.robot.paths.ik_track`),
  then ``v_d = J^+ [p_dot; 0]`` and ``a_d = J^+ ([p_ddot; 0] - Jdot v_d)`` with ``Jdot v_d`` the
  classical frame acceleration at zero joint acceleration.
* Redundancy (7 or more axes): ``J^+ = J^T (J J^T)^-1`` is the right pseudo-inverse, i.e. the
  minimum-norm joint motion (no null-space motion at all), the same resolution as the IK of
  :func:`pipeline.robot.paths.ik_track` (damped least squares with a 1e-12 damping) used for the CP
  joint path, so control and trajectory move a redundant arm the same way. For 6 axes ``J^+ = J^-1``.
  Undamped on purpose: ``v_d`` and ``a_d`` must be the exact derivatives of the path; singular
  points are refused (``cond(J) > 1e6``) instead of being damped.

Time scaling to the torque limits (:func:`torque_time_scale`): slowing a reference by ``s <= 1``
(speed ``s v``, acceleration ``s^2 a``, jerk ``s^3 j``; the curvature cap scales alike) keeps its path
``q(s t)`` and gives ``v -> s v``, ``a -> s^2 a``, so the rigid-body torque is exactly
``tau(s) = s^2 (rnea(q, v, a) - g(q)) + g(q)`` (``C(q, v) v`` is quadratic in ``v``) plus the friction
at ``s v``. The largest ``s`` with every joint within ``PATH_TORQUE_SHARE`` of its torque limit is
found by bisection on that closed form; no ``s`` helps where gravity and friction at rest already
exceed it (the ISO cube search caps the static torques, :mod:`pipeline.robot.iso_search`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from ruckig import InputParameter, Result, Ruckig, Trajectory

from pipeline.core.errors import InfeasibleError, SolverError
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import CartesianPath, check_within_limits, limiting_joint, pose_error

#: the share of each joint's torque limit a derived reference may ask of the model's inverse
#: dynamics; the rest is for the servo's corrections and the model's errors
PATH_TORQUE_SHARE = 0.9
TIME_SCALE_BISECTIONS = 40


@dataclass
class Reference:
    t_s: np.ndarray          # (N,)
    q_d: np.ndarray          # (N, nq)
    v_d: np.ndarray
    a_d: np.ndarray
    tcp_d_m: np.ndarray      # (N, 3) desired TCP position
    tcp_speed_m_s: np.ndarray  # (N,)
    segment: np.ndarray      # (N,) index of the segment
    segment_labels: list[str]
    s_m: np.ndarray          # (N,) arc length along the whole path


def _ruckig_profile(length_m: float, v_max: float, a_max: float, j_max: float) -> Trajectory:
    """Rest-to-rest jerk-limited ruckig profile of one axis over ``length_m``."""
    otg = Ruckig(1)
    inp = InputParameter(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [0.0], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [float(length_m)], [0.0], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [float(v_max)], [float(a_max)], [float(j_max)]
    traj = Trajectory(1)
    res = otg.calculate(inp, traj)
    if res not in (Result.Working, Result.Finished):
        raise SolverError(None, "ruckig", f"speed profile failed ({res}) for length {length_m} m")
    return traj


def speed_profile(length_m: float, v_max: float, a_max: float, j_max: float, t_s: np.ndarray) -> np.ndarray:
    """(len(t_s), 3) arrays of s, s_dot, s_ddot of a rest-to-rest ruckig profile sampled at t_s."""
    traj = _ruckig_profile(length_m, v_max, a_max, j_max)
    out = np.empty((len(t_s), 3))
    for k, t in enumerate(t_s):
        p, v, a = traj.at_time(float(min(t, traj.duration)))
        out[k] = (p[0], v[0], a[0])
    return out


def profile_duration(length_m: float, v_max: float, a_max: float, j_max: float) -> float:
    return float(_ruckig_profile(length_m, v_max, a_max, j_max).duration)


def cartesian_reference(robot: RobotModel, path: CartesianPath, sample_time_s: float, speed_m_s: float,
                        acceleration_m_s2: float, jerk_m_s3: float, q_start: np.ndarray, frame: str = "tcp",
                        ik_tolerance_m: float = 1e-9) -> Reference:
    """Sampled joint reference along ``path`` (its segments each rest-to-rest)."""
    segs = path.segments()
    vmax = []
    for sg in segs:
        kappa = sg.max_curvature_1_m()
        vmax.append(min(speed_m_s, np.sqrt(acceleration_m_s2 / kappa)) if kappa > 1e-9 else speed_m_s)
    durations = [profile_duration(sg.length_m, v, acceleration_m_s2, jerk_m_s3) for sg, v in zip(segs, vmax,
                                                                                                  strict=True)]
    starts = np.concatenate([[0.0], np.cumsum(durations)])
    n = int(np.floor(starts[-1] / sample_time_s)) + 1
    t = sample_time_s * np.arange(n)
    seg = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(segs) - 1)
    P, Pd, Pdd = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    s_all = np.empty(n)
    speed = np.empty(n)
    offset = np.concatenate([[0.0], np.cumsum([sg.length_m for sg in segs])])
    for i, sg in enumerate(segs):
        m = seg == i
        prof = speed_profile(sg.length_m, vmax[i], acceleration_m_s2, jerk_m_s3, t[m] - starts[i])
        s, sd, sdd = prof.T
        s = np.clip(s, 0.0, sg.length_m)
        d1, d2 = sg.derivatives(s)
        P[m] = sg.position(s)
        Pd[m] = d1 * sd[:, None]
        Pdd[m] = d2 * sd[:, None] ** 2 + d1 * sdd[:, None]
        s_all[m] = offset[i] + s
        speed[m] = sd
    q, v, a = track(robot, path.rotation, P, Pd, Pdd, q_start, frame, t, ik_tolerance_m)
    return Reference(t, q, v, a, P, speed, seg, [sg.label for sg in segs], s_all)


def resolved_rate(J: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Minimum-norm ``dq`` with ``J dq = x``: ``J^T (J J^T)^-1 x`` (``J^-1 x`` for a square ``J``)."""
    if J.shape[0] == J.shape[1]:
        return np.linalg.solve(J, x)
    return J.T @ np.linalg.solve(J @ J.T, x)


def track(robot: RobotModel, rotation: np.ndarray, P: np.ndarray, Pd: np.ndarray, Pdd: np.ndarray, q_start: np.ndarray,
          frame: str, t_s: np.ndarray, tolerance_m: float = 1e-9,
          max_iterations: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IK + joint velocities/accelerations at every sample in one pass.

    Warm start ``q_k^0 = q_{k-1} + dt v_{k-1} + dt^2/2 a_{k-1}``; Newton ``dq = J^+ e`` with
    ``e = [p* - p, log3(R* R^T)]``; then ``v = J^+ [p_dot; 0]``,
    ``a = J^+ ([p_ddot; 0] - Jdot v)`` (``J^+``: :func:`resolved_rate`; ``Jdot v``: classical frame
    acceleration at zero ``a``).
    Raises InfeasibleError naming the time, point and joint on failure, singularity or limits.
    """
    model = robot.model
    data = model.createData()
    fid = model.getFrameId(frame)
    rmap = robot.residual_map_of(frame)
    nq = model.nq
    N = len(P)
    q_out, v_out, a_out = np.empty((N, nq)), np.empty((N, nq)), np.empty((N, nq))
    vlim = robot.limits.velocity_rad_s
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    zero = np.zeros(nq)
    q = np.array(q_start, float)
    v_prev = np.zeros(nq)
    a_prev = np.zeros(nq)
    rhs_v, rhs_a = np.zeros(6), np.zeros(6)    # [p_dot; 0] and [p_ddot; 0]
    for k in range(N):
        if k > 0:
            dt = t_s[k] - t_s[k - 1]
            q = q + dt * v_prev + 0.5 * dt * dt * a_prev
        err = np.inf
        target = pin.SE3(rotation, P[k])
        for _ in range(max_iterations):
            e, J = pose_error(robot, model, data, fid, frame, q, target)
            err = float(np.sqrt(e.dot(e)))
            if err < tolerance_m:
                break
            q = q + resolved_rate(J, e)
        def where(k: int = k) -> str:
            return f"TCP point {np.array2string(P[k], precision=4)} m at t = {t_s[k]:.4f} s"

        cond = np.linalg.cond(J) if (k % 25 == 0 or err >= tolerance_m) else 1.0  # singularity watch
        if err >= tolerance_m or not np.isfinite(cond) or cond > 1e6:
            raise InfeasibleError(None, "ik", f"{where()} not reached (error {err:.1e} m, cond(J) {cond:.1e}; "
                                  f"{limiting_joint(robot, q)})")
        if np.any(q < lo) or np.any(q > hi):
            check_within_limits(robot, q, where())
        rhs_v[:3], rhs_a[:3] = Pd[k], Pdd[k]
        v = resolved_rate(J, rhs_v)
        pin.forwardKinematics(model, data, q, v, zero)
        drift = pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED).vector
        if rmap is not None:      # the residual map's share of J_dot v (pipeline.robot.residual_map)
            drift[:3] += rmap.drift(q, v)
        a = resolved_rate(J, rhs_a - drift)
        over = np.nonzero(np.abs(v) > vlim)[0]
        if len(over):
            j = int(over[0])
            raise InfeasibleError(None, "reference", f"{where()}: joint {j + 1} velocity {v[j]:.2f} rad/s exceeds "
                                  f"{vlim[j]:.2f} rad/s")
        q_out[k], v_out[k], a_out[k] = q, v, a
        v_prev, a_prev = v, a
    return q_out, v_out, a_out


def _torque_ratio(robot: RobotModel, dynamic_Nm: np.ndarray, gravity_Nm: np.ndarray, v: np.ndarray,
                  scale: float) -> float:
    """Largest ``|tau(s)| / tau_max`` over samples and joints of the reference slowed by ``scale``."""
    sv = scale * v
    tau = scale**2 * dynamic_Nm + gravity_Nm + robot.friction_torque(sv)
    if robot.spec.actuation.coulomb_load_coefficient is not None:
        tau = tau + robot.load_friction_torque(tau, sv)
    return float(np.max(np.abs(tau) / robot.limits.effort_Nm))


def torque_time_scale(robot: RobotModel, ref: Reference, share: float = PATH_TORQUE_SHARE) -> float:
    """The largest time scale ``s`` in (0, 1] for which ``ref`` slowed by ``s`` asks at most ``share``
    of every joint's torque limit of ``robot``'s inverse dynamics (module docstring); 1 when ``ref``
    already does, or when no slowing can (gravity and friction at rest above ``share``)."""
    data = robot.model.createData()
    rigid = np.array([pin.rnea(robot.model, data, q, v, a) for q, v, a in zip(ref.q_d, ref.v_d, ref.a_d, strict=True)])
    gravity = np.array([robot.gravity_torque(q) for q in ref.q_d])
    dynamic = rigid - gravity
    if _torque_ratio(robot, dynamic, gravity, ref.v_d, 1.0) <= share:
        return 1.0
    if _torque_ratio(robot, dynamic, gravity, ref.v_d, 0.0) > share:
        return 1.0
    low, high = 0.0, 1.0
    for _ in range(TIME_SCALE_BISECTIONS):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if _torque_ratio(robot, dynamic, gravity, ref.v_d, mid) <= share else (low, mid)
    return low
