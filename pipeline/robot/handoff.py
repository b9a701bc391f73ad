"""What one stage hands the next, as typed records below the stages (stages never import each other).

Each record maps to the arrays a stage saves in ``results.npz`` (:meth:`to_arrays`) and back
(:meth:`from_arrays`); the keys are those runs have always been saved with, so a saved run loads.

- :class:`ElastostaticRecord`: calibration -> control. The static torques the elastostatic fit
  used, so a later gravity model can re-express the identified joint stiffness
  (:func:`pipeline.robot.stiffness.stiffness_for_gravity_model`).
- :class:`JointFriction`: identification -> every later stage, through the identified model's
  actuation (viscous and Coulomb friction, and the Stribeck term when one was fitted).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from pipeline.robot.spec import ActuationSpec

__all__ = ["ElastostaticRecord", "JointFriction"]


@dataclass(frozen=True)
class ElastostaticRecord:
    """Static torques of an elastostatic calibration, per measured configuration (n of them).

    ``torques_Nm`` are the joint torques ``tau = g(q)`` (payload included where mounted) that the
    compliance fit ``dq = C tau`` used; ``payload_torques_Nm`` their payload share. A joint whose
    compliance was not identified keeps its nominal stiffness (``stiffness_identified`` False,
    ``compliance_std_rad_Nm`` NaN). The torque arrays are None in records saved before they were.
    """

    stiffness_identified: np.ndarray                 # (nq,) bool
    compliance_std_rad_Nm: np.ndarray                # (nq,) standard deviation of each compliance
    configurations_rad: np.ndarray | None = None     # (n, nq)
    torques_Nm: np.ndarray | None = None             # (n, nq)
    payload_torques_Nm: np.ndarray | None = None     # (n, nq)

    KEYS = {"stiffness_identified": "joint_stiffness_identified",
            "compliance_std_rad_Nm": "joint_compliance_std",
            "configurations_rad": "elastostatic_configurations_rad",
            "torques_Nm": "elastostatic_torques_Nm",
            "payload_torques_Nm": "elastostatic_payload_torques_Nm"}

    @property
    def has_torques(self) -> bool:
        return self.configurations_rad is not None and self.torques_Nm is not None

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The ``results.npz`` entries of the record (the torque arrays only when present)."""
        return {key: np.asarray(getattr(self, name)) for name, key in self.KEYS.items()
                if getattr(self, name) is not None}

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray], nq: int) -> ElastostaticRecord | None:
        """The record in a stage's arrays; None when they hold none (a rigid calibration, or a run
        saved before the record existed). A missing standard deviation reads as 0 (significant)."""
        if cls.KEYS["stiffness_identified"] not in arrays:
            return None

        def optional(name: str) -> np.ndarray | None:
            key = cls.KEYS[name]
            return np.asarray(arrays[key], float) if key in arrays else None

        std = optional("compliance_std_rad_Nm")
        configurations, torques, payload = (optional(name) for name in
                                            ("configurations_rad", "torques_Nm", "payload_torques_Nm"))
        if torques is not None and payload is None:
            payload = np.zeros_like(torques)
        return cls(stiffness_identified=np.asarray(arrays[cls.KEYS["stiffness_identified"]], bool),
                   compliance_std_rad_Nm=np.zeros(nq) if std is None else std,
                   configurations_rad=configurations, torques_Nm=torques, payload_torques_Nm=payload)


@dataclass(frozen=True)
class JointFriction:
    """Identified joint friction ``tau_f = fv v + fc sign(v) + fs exp(-(v/vs)^2) sign(v)
    + fl |tau_load| sign(v)`` per joint.

    ``viscous_Nms_rad`` (fv) and ``coulomb_Nm`` (fc) always; the Stribeck excess ``static_excess_Nm``
    (fs) and velocity ``stribeck_velocity_rad_s`` (vs) only when a Stribeck term was fitted
    (Armstrong-Helouvry et al. 1994), else both None; the load-dependent Coulomb coefficient
    ``load_coefficient`` (fl, Bittencourt & Gunnarsson 2012; the load torque is the model's torque
    without this term, :func:`pipeline.robot.friction.load_friction_torque`) only when fitted, else None.
    """

    viscous_Nms_rad: np.ndarray
    coulomb_Nm: np.ndarray
    static_excess_Nm: np.ndarray | None = None
    stribeck_velocity_rad_s: np.ndarray | None = None
    load_coefficient: np.ndarray | None = None

    KEYS = {"viscous_Nms_rad": "friction_viscous_Nms_rad",
            "coulomb_Nm": "friction_coulomb_Nm",
            "static_excess_Nm": "friction_static_excess_Nm",
            "stribeck_velocity_rad_s": "friction_stribeck_velocity_rad_s",
            "load_coefficient": "friction_coulomb_load_coefficient"}

    def __post_init__(self) -> None:
        if (self.static_excess_Nm is None) != (self.stribeck_velocity_rad_s is None):
            raise ValueError("static_excess_Nm and stribeck_velocity_rad_s come together")

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {key: np.asarray(getattr(self, name), float) for name, key in self.KEYS.items()
                if getattr(self, name) is not None}

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> JointFriction:
        values = {name: np.asarray(arrays[key], float) for name, key in cls.KEYS.items() if key in arrays}
        return cls(**values)

    @classmethod
    def of_actuation(cls, actuation: ActuationSpec) -> JointFriction:
        """The friction a robot model carries (``robot.spec.actuation``)."""
        def copy(x: np.ndarray | None) -> np.ndarray | None:
            return None if x is None else np.array(x, float)

        return cls(np.array(actuation.viscous_Nms_rad, float), np.array(actuation.coulomb_Nm, float),
                   copy(actuation.static_friction_excess_Nm), copy(actuation.stribeck_velocity_rad_s),
                   copy(actuation.coulomb_load_coefficient))

    def apply_to(self, actuation: ActuationSpec) -> None:
        """Write the friction into ``actuation`` (how the identified model hands it on)."""
        actuation.viscous_Nms_rad = self.viscous_Nms_rad.copy()
        actuation.coulomb_Nm = self.coulomb_Nm.copy()
        actuation.static_friction_excess_Nm = None if self.static_excess_Nm is None else self.static_excess_Nm.copy()
        actuation.stribeck_velocity_rad_s = (None if self.stribeck_velocity_rad_s is None
                                             else self.stribeck_velocity_rad_s.copy())
        actuation.coulomb_load_coefficient = None if self.load_coefficient is None else self.load_coefficient.copy()
