"""Inverse kinematics that stays inside the joint limits and reports failure.

Levenberg–Marquardt on the SE(3) log error ``e = log6(T(q)^-1 T_target)`` (local frame):
``(J^T J + λ I) dq = J^T e`` with ``J = Jlog6 · J_frame``; a step is kept only if it lowers
``|e|``, else λ grows. Steps are capped and projected onto the joint limits. From the given
start first, then from random starts inside the limits; a pose outside the tolerance is
never returned as a solution (``success=False`` with the best residual).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin


@dataclass
class IKResult:
    """Outcome of :meth:`RobotModel.ik`; ``q`` is only meaningful when ``success``."""

    q: np.ndarray
    success: bool
    position_error_m: float
    rotation_error_rad: float
    iterations: int
    message: str


def solve_ik(model: pin.Model, data: pin.Data, fid: int, target: pin.SE3, q0: np.ndarray, *,
             position_only: bool = False, tolerance_m: float = 1e-9, tolerance_rad: float = 1e-9,
             max_iterations: int = 200, restarts: int = 8, rng: np.random.Generator | None = None) -> IKResult:
    """Pose (or position) of frame ``fid`` at ``target``: from ``q0``, then up to ``restarts``
    random starts inside the limits (see the module docstring)."""
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    rng = rng if rng is not None else np.random.default_rng(0)
    best: IKResult | None = None
    starts = [np.clip(np.asarray(q0, float), lower, upper)]
    starts += [rng.uniform(lower, upper) for _ in range(restarts)]
    for start in starts:
        result = _ik_from(model, data, target, start, fid, position_only, tolerance_m, tolerance_rad,
                          max_iterations)
        if result.success:
            return result
        if best is None or result.position_error_m + result.rotation_error_rad < (
            best.position_error_m + best.rotation_error_rad
        ):
            best = result
    assert best is not None
    best.message = (f"IK did not reach the target within {tolerance_m:g} m / {tolerance_rad:g} rad inside the "
                    f"joint limits (best residual {best.position_error_m:.3g} m, "
                    f"{best.rotation_error_rad:.3g} rad)")
    return best

def _ik_from(model: pin.Model, data: pin.Data, target: pin.SE3, q: np.ndarray, fid: int, position_only: bool,
             tol_m: float, tol_rad: float, max_iterations: int) -> IKResult:
    """Levenberg–Marquardt from ``q``: a step is kept only if it lowers the error, else the
    damping grows; steps are capped at 0.5 rad and projected onto the joint limits."""
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit

    def residual(q_: np.ndarray) -> tuple[np.ndarray, pin.SE3, float, float]:
        pin.forwardKinematics(model, data, q_)
        current = pin.updateFramePlacement(model, data, fid).copy()
        if position_only:
            error = current.rotation.T @ (target.translation - current.translation)
            return error, current, float(np.linalg.norm(error)), 0.0
        error = pin.log6(current.actInv(target)).vector
        return (error, current, float(np.linalg.norm(target.translation - current.translation)),
                float(np.linalg.norm(error[3:])))

    damping = 1e-4
    error, current, pos_err, rot_err = residual(q)
    for iteration in range(max_iterations):
        if pos_err <= tol_m and rot_err <= tol_rad:
            return IKResult(q.copy(), True, pos_err, rot_err, iteration, "converged")
        jac = pin.computeFrameJacobian(model, data, q, fid, pin.ReferenceFrame.LOCAL)
        jac = jac[:3] if position_only else pin.Jlog6(current.actInv(target)) @ jac
        gradient, hessian = jac.T @ error, jac.T @ jac
        for _ in range(12):
            step = np.linalg.solve(hessian + damping * np.eye(model.nv), gradient)
            largest = np.max(np.abs(step))
            if largest > 0.5:
                step *= 0.5 / largest
            q_new = np.clip(q + step, lower, upper)
            error_new, current_new, pos_new, rot_new = residual(q_new)
            if error_new @ error_new < error @ error:
                q, error, current, pos_err, rot_err = q_new, error_new, current_new, pos_new, rot_new
                damping = max(damping / 10.0, 1e-12)
                break
            damping *= 10.0
        else:
            break  # no descent possible from here: a local minimum at the limits
    converged = pos_err <= tol_m and rot_err <= tol_rad
    return IKResult(q.copy(), converged, pos_err, rot_err, max_iterations,
                    "converged" if converged else "not converged")
