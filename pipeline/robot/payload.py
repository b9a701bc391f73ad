"""A known payload (point mass) mounted on the flange, and the gravity torques it adds.

The payload is a point mass ``mass_kg`` at ``com_m`` (flange frame). It is added to the inertia
of the last joint's body (``pin.Inertia`` of a point mass moved into the joint frame through the
flange frame's placement), so Pinocchio's ``computeGeneralizedGravity`` gives the joint torques
holding arm + payload still (static poses of a tracker measurement).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin


@dataclass(frozen=True)
class Payload:
    """Point-mass payload on the flange: mass (kg) and centre of mass in the flange frame (m)."""

    mass_kg: float
    com_m: tuple[float, float, float] = (0.0, 0.0, 0.0)


def with_payload(model: pin.Model, flange_frame: str, payload: Payload | None) -> pin.Model:
    """Copy of ``model`` whose last body carries ``payload`` (``model`` itself when None)."""
    if payload is None or payload.mass_kg == 0.0:
        return model
    out = model.copy()
    frame = out.frames[out.getFrameId(flange_frame)]
    com_joint = frame.placement.act(np.asarray(payload.com_m, float))
    out.inertias[frame.parentJoint] = out.inertias[frame.parentJoint] + pin.Inertia(
        float(payload.mass_kg), com_joint, np.zeros((3, 3)))
    return out


def gravity_torques_Nm(model: pin.Model, Q: np.ndarray) -> np.ndarray:
    """``(N, nq)`` generalized gravity ``g(q)`` (the joint torques holding each pose still)."""
    Q = np.atleast_2d(np.asarray(Q, float))
    data = model.createData()
    return np.array([pin.computeGeneralizedGravity(model, data, q).copy() for q in Q]).reshape(len(Q), model.nv)
