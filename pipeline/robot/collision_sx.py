"""Capsule clearances as CasADi expressions: the symbolic twin of :mod:`pipeline.robot.collision`.

Segment-segment distance by Ericson's closed form (*Real-Time Collision Detection* §5.1.9)
with the clamps written as ``if_else`` (continuous, piecewise smooth), and the robot's
self-pair and floor clearances built on :class:`pipeline.robot.symbolic.SymbolicRobot`'s
forward kinematics, so NLPs (excitation design, calibration configuration design) share one
collision model with the numeric filters.
"""

from __future__ import annotations

import casadi as ca

from pipeline.robot.model import RobotModel
from pipeline.robot.symbolic import SymbolicRobot


def segment_distance_sx(p0: ca.SX, p1: ca.SX, q0: ca.SX, q1: ca.SX) -> ca.SX:
    """Distance between segments p0p1 and q0q1 (Ericson, Real-Time Collision Detection §5.1.9,
    the clamps as ``if_else``); same formula as ``pipeline.robot.collision.segment_distances``."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = ca.dot(d1, d1), ca.dot(d2, d2), ca.dot(d2, r)
    c, b = ca.dot(d1, r), ca.dot(d1, d2)
    tiny = 1e-14
    denom = a * e - b * b

    def clip01(x: ca.SX) -> ca.SX:
        return ca.fmin(ca.fmax(x, 0), 1)

    s = ca.if_else(denom > tiny * ca.fmax(a * e, tiny), clip01((b * f - c * e) / (denom + tiny)), 0)
    s = ca.if_else(a > tiny, s, 0)
    t = ca.if_else(e > tiny, (b * s + f) / ca.if_else(e > tiny, e, 1), 0)
    tc = clip01(t)
    s_t = ca.if_else(a > tiny, clip01((tc * b - c) / ca.if_else(a > tiny, a, 1)), 0)
    s = ca.if_else(t != tc, s_t, s)
    diff = p0 + s * d1 - q0 - tc * d2
    return ca.sqrt(ca.dot(diff, diff) + 1e-12)


def capsule_clearance_function(robot: RobotModel, sym: SymbolicRobot) -> ca.Function:
    """``q -> (self-pair clearances, floor clearances of capsule end points)`` (SX), the symbolic
    twin of ``RobotModel.capsule_clearances`` (end points are exact for a plane)."""
    q = ca.SX.sym("q", robot.nq)
    p_kin = ca.DM(sym.nominal_kinematic_parameters())
    ends = []
    for cap in robot.capsules:
        pos, rot = sym.fk(cap.frame)(q, p_kin)
        ends.append((pos + ca.mtimes(rot, ca.DM(cap.p0)), pos + ca.mtimes(rot, ca.DM(cap.p1))))
    radii = [c.radius_m for c in robot.capsules]
    pairs = [
        segment_distance_sx(*ends[i], *ends[k]) - radii[i] - radii[k]
        for i, k in robot.self_collision_pairs
    ]
    fz = robot.spec.collision.floor_z_m
    floor = []
    for i in robot.floor_capsules:
        floor += [ends[i][0][2] - radii[i] - fz, ends[i][1][2] - radii[i] - fz]
    return ca.Function(
        "capsule_clearance", [q], [ca.vertcat(*pairs) if pairs else ca.SX(0, 1),
                                   ca.vertcat(*floor) if floor else ca.SX(0, 1)]
    )
