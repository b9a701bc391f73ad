"""CasADi SX pieces of the elastic-joint plant and of the truth's non-linear friction.

Two-mass model per joint (joint side; rotor inertia ``J_m`` reflected through the gear, link chain
without rotor inertia; paper ``004_abbe750b8bbcc3aa.txt`` §2.3, §5 "gear elasticities")::

    tau_s  = k (theta - q) + d (omega - v)                         spring + damper torque
    qdd    = ABA_link(q, v, tau_s)                                  link side (armature 0)
    J_m omega_dot = sat(tau_cmd) - tau_s - f(omega, tau_s)          motor side, friction on the motor

with ``f`` the Stribeck friction of :mod:`pipeline.sim.transmission`. One semi-implicit
(symplectic) Euler substep of length ``h`` updates the velocities first and the positions with the
new velocities; it is stable for ``h omega_n < 2`` on the undamped resonances ``omega_n`` (the plant
picks ``h`` for ``h omega_max <= 1``, :meth:`pipeline.sim.plant.Plant.substeps_for`).
Transmission numbers per joint in the loop parameter vector: ``(J_m, k, d, F_s - F_c, w_s, mu)``.
"""

from __future__ import annotations

import casadi as ca

from pipeline.sim import dynamics
from pipeline.sim.dynamics import ChainStructure

TRANSMISSION_PARAMS_PER_JOINT = 6


def _transmission(ptr: ca.SX, i: int) -> dict[str, ca.SX]:
    b = ptr[i * TRANSMISSION_PARAMS_PER_JOINT:(i + 1) * TRANSMISSION_PARAMS_PER_JOINT]
    return {"jm": b[0], "k": b[1], "d": b[2], "fs_excess": b[3], "ws": b[4], "mu": b[5]}


def stribeck_friction_sx(w: ca.SX, load: ca.SX, p: ca.SX, ptr: ca.SX, s: ChainStructure) -> ca.SX:
    """``viscous w + (F_c + (F_s - F_c) exp(-(w/w_s)^2)) tanh(w/width)``, ``F_c`` grown by the load."""
    joints, _, width = dynamics._unpack(p, s)
    out = []
    for i, jt in enumerate(joints):
        tr = _transmission(ptr, i)
        grow = 1.0 + tr["mu"] * ca.fabs(load[i]) / jt["effort"]
        fc = jt["coulomb"] * grow
        static = tr["fs_excess"] * grow * ca.exp(-(w[i] / tr["ws"]) ** 2)
        out.append(jt["viscous"] * w[i] + (fc + static) * ca.tanh(w[i] / width[i]))
    return ca.vertcat(*out)


def rigid_stribeck_substep_function(s: ChainStructure) -> ca.Function:
    """``(q, v, tau_cmd, p, ptr, h) -> (q, v)``: rigid joint with the Stribeck friction (load = |sat tau|)."""
    q, v, tau = ca.SX.sym("q", s.nq), ca.SX.sym("v", s.nq), ca.SX.sym("tau", s.nq)
    p, ptr, h = ca.SX.sym("p", s.n_params), ca.SX.sym("ptr", TRANSMISSION_PARAMS_PER_JOINT * s.nq), ca.SX.sym("h")
    eff = dynamics.effort_sx(p, s)
    tau_sat = ca.fmin(ca.fmax(tau, -eff), eff)
    a = dynamics.aba_sx(q, v, tau_sat - stribeck_friction_sx(v, tau_sat, p, ptr, s), p, s)
    v1 = v + h * a
    return ca.Function("rigid_substep", [q, v, tau, p, ptr, h], [q + h * v1, v1])


def elastic_substep_function(s: ChainStructure) -> ca.Function:
    """``(q, v, theta, omega, tau_cmd, p_link, ptr, h) -> (q, v, theta, omega)``: one substep of the
    two-mass model (module docstring); ``p_link`` has zero armature (the rotor is the motor mass)."""
    n = s.nq
    q, v, th, w, tau = (ca.SX.sym(k, n) for k in ("q", "v", "theta", "omega", "tau"))
    p, ptr, h = ca.SX.sym("p", s.n_params), ca.SX.sym("ptr", TRANSMISSION_PARAMS_PER_JOINT * n), ca.SX.sym("h")
    eff = dynamics.effort_sx(p, s)
    tau_sat = ca.fmin(ca.fmax(tau, -eff), eff)
    tr = [_transmission(ptr, i) for i in range(n)]
    tau_s = ca.vertcat(*[tr[i]["k"] * (th[i] - q[i]) + tr[i]["d"] * (w[i] - v[i]) for i in range(n)])
    a_link = dynamics.aba_sx(q, v, tau_s, p, s)
    fric = stribeck_friction_sx(w, tau_s, p, ptr, s)
    w_dot = ca.vertcat(*[(tau_sat[i] - tau_s[i] - fric[i]) / tr[i]["jm"] for i in range(n)])
    w1 = w + h * w_dot
    v1 = v + h * a_link
    return ca.Function("elastic_substep", [q, v, th, w, tau, p, ptr, h], [q + h * v1, v1, th + h * w1, w1])
