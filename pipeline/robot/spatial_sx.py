"""Rigid-body and spatial algebra on CasADi ``SX`` for the symbolic bridge.

``pinocchio.casadi`` is not part of the PyPI wheel, so the few operations the bridge needs are
written here on plain CasADi expressions. Conventions follow Pinocchio exactly:

- an SE(3) element is a pair ``(R, p)`` (3x3, 3x1) mapping child coordinates to parent
  coordinates, ``x_parent = R x_child + p``; composition ``(R1, p1) * (R2, p2) = (R1 R2, R1 p2 + p1)``;
- a spatial motion is ``(v, w)`` (linear first, like ``pin.Motion.vector``), a spatial force
  ``(f, n)`` (force first, like ``pin.Force.vector``);
- a twist ``xi = [v, w]`` (6,) is mapped to SE(3) by ``exp6`` (``pin.exp6``).

Every function accepts ``casadi.SX`` or numpy inputs; numeric constants (joint placements, axes)
stay numbers so CasADi folds structural zeros away when the graph is built.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

SXLike = ca.SX | np.ndarray | float

# Below this squared rotation angle exp6 switches to Taylor series of its coefficients, so the
# expression and its derivatives stay finite and exact (truncation error < 1e-17) at zero.
_SMALL_ANGLE_SQ = 1e-4


def _as_sx_vector(x: SXLike) -> ca.SX:
    """A 3-vector as a column ``SX`` (numeric values become SX constants)."""
    if isinstance(x, ca.SX):
        return x
    return ca.SX(np.asarray(x, dtype=float).reshape(-1, 1))


def skew(w: SXLike) -> ca.SX:
    """Skew-symmetric matrix ``[w]x`` with ``[w]x u = w x u``."""
    w = _as_sx_vector(w)
    return ca.vertcat(
        ca.horzcat(0, -w[2], w[1]),
        ca.horzcat(w[2], 0, -w[0]),
        ca.horzcat(-w[1], w[0], 0),
    )


def cross(a: SXLike, b: SXLike) -> ca.SX:
    """Cross product of two 3-vectors (SX or numeric)."""
    a = _as_sx_vector(a)
    b = _as_sx_vector(b)
    return ca.vertcat(
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    )


def exp_coefficients(theta_sq: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Coefficients of the SE(3) exponential as functions of ``theta^2``.

    ``A = sin t / t``, ``B = (1 - cos t) / t^2``, ``C = (t - sin t) / t^3``; below
    ``t^2 < 1e-4`` their Taylor series are used (no 0/0 and exact derivatives at zero).
    """
    small = theta_sq < _SMALL_ANGLE_SQ
    safe_sq = ca.if_else(small, 1.0, theta_sq)
    t = ca.sqrt(safe_sq)
    s, c = ca.sin(t), ca.cos(t)
    ts = theta_sq
    a_series = 1 - ts / 6 + ts**2 / 120 - ts**3 / 5040
    b_series = 0.5 - ts / 24 + ts**2 / 720 - ts**3 / 40320
    c_series = 1.0 / 6 - ts / 120 + ts**2 / 5040 - ts**3 / 362880
    a_coef = ca.if_else(small, a_series, s / t)
    b_coef = ca.if_else(small, b_series, (1 - c) / safe_sq)
    c_coef = ca.if_else(small, c_series, (t - s) / (safe_sq * t))
    return a_coef, b_coef, c_coef


def exp6(xi: SXLike) -> tuple[ca.SX, ca.SX]:
    """SE(3) exponential of a twist ``xi = [v (3), w (3)]`` (same convention as ``pin.exp6``).

    ``R = I + A [w] + B [w]^2``, ``p = (I + B [w] + C [w]^2) v`` (Murray, Li & Sastry,
    A Mathematical Introduction to Robotic Manipulation, 1994, eq. 2.36).
    """
    xi = ca.SX(xi) if not isinstance(xi, ca.SX) else xi
    v = xi[0:3]
    w = xi[3:6]
    a_coef, b_coef, c_coef = exp_coefficients(ca.dot(w, w))
    wx = skew(w)
    wx2 = ca.mtimes(wx, wx)
    eye = ca.SX.eye(3)
    rot = eye + a_coef * wx + b_coef * wx2
    trans = ca.mtimes(eye + b_coef * wx + c_coef * wx2, v)
    return rot, trans


def rotation_about_axis(axis: np.ndarray, angle: ca.SX) -> ca.SX:
    """Rotation by ``angle`` about the unit ``axis`` (numeric); exact forms for x, y, z."""
    c, s = ca.cos(angle), ca.sin(angle)
    ax = np.asarray(axis, dtype=float)
    if np.allclose(ax, [1, 0, 0], atol=0, rtol=0):
        return ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, c, -s), ca.horzcat(0, s, c))
    if np.allclose(ax, [0, 1, 0], atol=0, rtol=0):
        return ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))
    if np.allclose(ax, [0, 0, 1], atol=0, rtol=0):
        return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
    kx = ca.SX(skew(ax))
    return ca.SX.eye(3) + s * kx + (1 - c) * ca.mtimes(kx, kx)


def compose(a: tuple[SXLike, SXLike], b: tuple[SXLike, SXLike]) -> tuple[ca.SX, ca.SX]:
    """SE(3) product ``a * b``."""
    ra, pa = a
    rb, pb = b
    return ca.mtimes(ca.SX(ra), ca.SX(rb)), ca.mtimes(ca.SX(ra), ca.SX(pb)) + ca.SX(pa)


def inverse(a: tuple[SXLike, SXLike]) -> tuple[ca.SX, ca.SX]:
    """SE(3) inverse ``(R^T, -R^T p)``."""
    r, p = a
    rt = ca.SX(r).T
    return rt, -ca.mtimes(rt, ca.SX(p))


def se3_numeric(m) -> tuple[np.ndarray, np.ndarray]:
    """``(R, p)`` of a ``pin.SE3`` as numpy arrays."""
    return np.array(m.rotation, dtype=float), np.array(m.translation, dtype=float).reshape(3, 1)


# --- spatial motion / force algebra (Featherstone, Rigid Body Dynamics Algorithms, ch. 2) ---


def motion_act_inv(r: SXLike, p: SXLike, v: ca.SX, w: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``M.actInv(m)``: motion ``(v, w)`` in the parent frame expressed in the child frame."""
    rt = ca.SX(r).T
    return ca.mtimes(rt, v - cross(p, w)), ca.mtimes(rt, w)


def force_act(r: SXLike, p: SXLike, f: ca.SX, n: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``M.act(f)``: force ``(f, n)`` in the child frame expressed in the parent frame."""
    rf = ca.mtimes(ca.SX(r), f)
    return rf, ca.mtimes(ca.SX(r), n) + cross(p, rf)


def motion_cross(v1: ca.SX, w1: ca.SX, v2: ca.SX, w2: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Spatial motion cross product ``m1 x m2``."""
    return cross(w1, v2) + cross(v1, w2), cross(w1, w2)


def force_cross(v: ca.SX, w: ca.SX, f: ca.SX, n: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Dual cross product ``m x* f``."""
    return cross(w, f), cross(w, n) + cross(v, f)


def inertia_apply(pi: ca.SX, v: ca.SX, w: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Spatial inertia times motion, linear in the 10 dynamic parameters.

    ``pi = [m, hx, hy, hz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (``pin.Inertia.toDynamicParameters``
    order, ``h = m c``, ``I`` the rotational inertia about the frame origin):
    ``f = m v - h x w``, ``n = I w + h x v``.
    """
    m = pi[0]
    h = pi[1:4]
    ixx, ixy, iyy, ixz, iyz, izz = pi[4], pi[5], pi[6], pi[7], pi[8], pi[9]
    iw = ca.vertcat(
        ixx * w[0] + ixy * w[1] + ixz * w[2],
        ixy * w[0] + iyy * w[1] + iyz * w[2],
        ixz * w[0] + iyz * w[1] + izz * w[2],
    )
    return m * v - cross(h, w), iw + cross(h, v)
