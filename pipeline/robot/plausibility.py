"""Plausibility of a robot's data against data-sheet scaling of serial arms: warnings, not errors.

Placeholder data (every link 2 kg, every joint 300 N·m and 10 rad/s) passes every check of the
robot files and still yields good-looking figures. These checks compare the model with the
published figures of serial industrial arms and cobots (:data:`DATA_SHEET_ARMS`, from the
vendors' data sheets: Universal Robots e-Series (UR3e, UR5e, UR10e, UR20), Franka Emika Panda,
KUKA LBR iiwa 7 R800 / 14 R820, UFactory xArm 7, Unitree Z1, Kinova Gen3, FANUC CRX-10iA/L and
M-20iA, KUKA KR 6 R900 sixx, KR 16-2 and KR 210 R2700, ABB IRB 120, IRB 140 and IRB 6700-200/2.60,
Stäubli RX160L; reach, rated payload, arm mass, axis 1 speed, and the largest joint torque where
the vendor states it). Each law reduces an arm to one dimensionless-ish figure; the band it must
lie in is the data sheets' range of that figure widened by a stated factor (the numbers live
here only, no robot is named in the checks):

* **mass vs reach**: ``m / L^2.5`` (kg/m^2.5; data sheets 8.7 (Unitree Z1) to 166 (ABB IRB 140)).
  The model's moving mass leaves out the fixed base that the data sheets include, hence the
  lower band's factor 2 (``MASS_LOW_FACTOR``).
* **mass vs payload**: ``m / P`` >= the data sheets' smallest (2.05, Kinova Gen3 / Unitree Z1)
  over the same factor: an arm lighter than what it is rated to carry is a placeholder.
* **torque vs size**: the largest torque limit over the torque that holds the stretched-out arm,
  ``g L (P + m / 2)`` (payload at the reach, the moving mass at half of it); vendors that state
  joint torques (UR, Panda, iiwa) lie at 0.86–1.37. Wide band (``TORQUE_FACTOR``): URDFs of
  real arms carry generous or borrowed limits (example-robot-data's UR3 has the UR10's 330 N·m).
* **speed vs size**: the flange speed that axis 1 alone gives at full reach, ``omega_1 L``;
  data sheets 1.2 m/s (iiwa 14) to 7.0 m/s (RX160L).
* **identical limits**: the same torque limit on every joint (real wrists carry far less than
  shoulders), or the same mass on every moving link. The same speed limit on every joint alone is
  no sign: xArm 7 and Z1 state 180 °/s for every joint.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from pipeline.robot.model import RobotModel
from pipeline.robot.reflector_check import capsules_holding, describe, marker_points

GRAVITY_M_S2 = 9.81
#: mass-vs-reach law: mass / reach^REACH_EXPONENT (the data sheets' spread is smallest near 2.5)
REACH_EXPONENT = 2.5
#: factors by which a figure may lie outside the data sheets' range before it is flagged
MASS_LOW_FACTOR, MASS_HIGH_FACTOR = 2.0, 3.0
TORQUE_FACTOR = 15.0
SPEED_FACTOR = 3.0
#: relative spread under which limits or masses count as identical on every joint
IDENTICAL_RELATIVE = 1e-6
#: joints (or moving links) from which identical values are a sign of placeholders
MIN_JOINTS_FOR_IDENTICAL = 3


@dataclass(frozen=True)
class DataSheetArm:
    """Published figures of one arm: reach (m), rated payload (kg), arm mass incl. base (kg),
    axis 1 speed (deg/s), largest joint torque (N·m) where the vendor states one."""

    name: str
    reach_m: float
    payload_kg: float
    mass_kg: float
    axis1_speed_deg_s: float
    max_torque_Nm: float | None = None


DATA_SHEET_ARMS: tuple[DataSheetArm, ...] = (
    DataSheetArm("Universal Robots UR3e", 0.500, 3.0, 11.2, 180.0, 56.0),
    DataSheetArm("Universal Robots UR5e", 0.850, 5.0, 20.6, 180.0, 150.0),
    DataSheetArm("Universal Robots UR10e", 1.300, 12.5, 33.5, 120.0, 330.0),
    DataSheetArm("Universal Robots UR20", 1.750, 20.0, 64.0, 120.0),
    DataSheetArm("Franka Emika Panda", 0.855, 3.0, 18.0, 150.0, 87.0),
    DataSheetArm("KUKA LBR iiwa 7 R800", 0.800, 7.0, 23.9, 98.0, 176.0),
    DataSheetArm("KUKA LBR iiwa 14 R820", 0.820, 14.0, 29.9, 85.0, 320.0),
    DataSheetArm("UFactory xArm 7", 0.700, 3.5, 13.7, 180.0),
    DataSheetArm("Unitree Z1", 0.740, 2.0, 4.1, 180.0),
    DataSheetArm("Kinova Gen3", 0.902, 4.0, 8.2, 80.0),
    DataSheetArm("FANUC CRX-10iA/L", 1.418, 10.0, 40.0, 120.0),
    DataSheetArm("FANUC M-20iA", 1.811, 20.0, 250.0, 195.0),
    DataSheetArm("KUKA KR 6 R900 sixx", 0.901, 6.0, 52.0, 360.0),
    DataSheetArm("KUKA KR 16-2", 1.611, 16.0, 235.0, 200.0),
    DataSheetArm("KUKA KR 210 R2700", 2.696, 210.0, 1068.0, 105.0),
    DataSheetArm("ABB IRB 120", 0.580, 3.0, 25.0, 250.0),
    DataSheetArm("ABB IRB 140", 0.810, 6.0, 98.0, 200.0),
    DataSheetArm("ABB IRB 6700-200/2.60", 2.600, 200.0, 1170.0, 110.0),
    DataSheetArm("Staubli RX160L", 2.010, 14.0, 248.0, 200.0),
)


# ------------------------------------------------------------------------------ the scaling laws
def mass_per_reach(mass_kg: float, reach_m: float) -> float:
    """``m / L^2.5`` (kg/m^2.5)."""
    return mass_kg / reach_m**REACH_EXPONENT


def holding_torque_Nm(reach_m: float, payload_kg: float, moving_mass_kg: float) -> float:
    """Torque that holds the stretched-out arm: ``g L (P + m / 2)``."""
    return GRAVITY_M_S2 * reach_m * (payload_kg + 0.5 * moving_mass_kg)


def axis1_flange_speed_m_s(axis1_speed_rad_s: float, reach_m: float) -> float:
    """Flange speed from axis 1 alone at full reach: ``omega_1 L``."""
    return axis1_speed_rad_s * reach_m


@dataclass(frozen=True)
class Band:
    """Range of a figure over the data sheets and the widened range outside which it is flagged."""

    data_low: float
    data_high: float
    low: float
    high: float

    @classmethod
    def widened(cls, values: list[float], low_factor: float, high_factor: float | None = None) -> Band:
        lo, hi = float(min(values)), float(max(values))
        return cls(lo, hi, lo / low_factor, hi * (low_factor if high_factor is None else high_factor))


MASS_PER_REACH = Band.widened([mass_per_reach(a.mass_kg, a.reach_m) for a in DATA_SHEET_ARMS],
                              MASS_LOW_FACTOR, MASS_HIGH_FACTOR)
MASS_PER_PAYLOAD = Band.widened([a.mass_kg / a.payload_kg for a in DATA_SHEET_ARMS], MASS_LOW_FACTOR, np.inf)
TORQUE_PER_HOLDING = Band.widened(
    [a.max_torque_Nm / holding_torque_Nm(a.reach_m, a.payload_kg, a.mass_kg)
     for a in DATA_SHEET_ARMS if a.max_torque_Nm is not None], TORQUE_FACTOR)
AXIS1_FLANGE_SPEED = Band.widened(
    [axis1_flange_speed_m_s(float(np.deg2rad(a.axis1_speed_deg_s)), a.reach_m) for a in DATA_SHEET_ARMS], SPEED_FACTOR)


# ------------------------------------------------------------------------------ the checks
@dataclass(frozen=True)
class ArmFigures:
    """What the checks read from a robot: reach (axis 1 to flange), moving mass (every link that
    moves), rated payload, limits per joint, mass per moving link."""

    reach_m: float
    moving_mass_kg: float
    payload_kg: float
    effort_Nm: np.ndarray
    velocity_rad_s: np.ndarray
    link_masses_kg: np.ndarray

    @classmethod
    def of(cls, robot: RobotModel, summary: Mapping[str, object] | None = None) -> ArmFigures:
        """The figures of a :class:`~pipeline.robot.model.RobotModel` (``summary``: its
        ``summary()`` when already computed; it holds the reach)."""
        summary = robot.summary() if summary is None else summary
        masses = np.array([robot.model.inertias[j].mass for j in range(1, robot.model.njoints)])
        reach_m = summary["reach_m"]
        assert isinstance(reach_m, float | int)
        return cls(float(reach_m), float(masses.sum()), float(robot.payload_kg),
                   np.asarray(robot.limits.effort_Nm, float), np.asarray(robot.limits.velocity_rad_s, float),
                   masses)


def _identical(values: np.ndarray) -> bool:
    values = np.asarray(values, float)
    scale = float(np.max(np.abs(values))) if values.size else 0.0
    return values.size >= MIN_JOINTS_FOR_IDENTICAL and scale > 0 and float(np.ptp(values)) <= IDENTICAL_RELATIVE * scale


def _mass_warnings(arm: ArmFigures) -> list[str]:
    out: list[str] = []
    ratio = mass_per_reach(arm.moving_mass_kg, arm.reach_m)
    band = MASS_PER_REACH
    if ratio < band.low:
        out.append(f"moving mass {arm.moving_mass_kg:.3g} kg is implausibly light for a {arm.reach_m:.2f} m reach: "
                   f"data-sheet arms of that reach weigh at least {band.data_low * arm.reach_m**REACH_EXPONENT:.0f} kg "
                   f"(mass / reach^2.5 = {ratio:.3g}, data sheets {band.data_low:.3g}-{band.data_high:.3g} kg/m^2.5); "
                   "placeholder link masses?")
    elif ratio > band.high:
        out.append(f"moving mass {arm.moving_mass_kg:.4g} kg is implausibly heavy for a {arm.reach_m:.2f} m reach: "
                   f"data-sheet arms of that reach weigh at most {band.data_high * arm.reach_m**REACH_EXPONENT:.0f} kg "
                   f"(mass / reach^2.5 = {ratio:.3g}, data sheets {band.data_low:.3g}-{band.data_high:.3g} kg/m^2.5); "
                   "masses in grams?")
    if arm.payload_kg > 0 and arm.moving_mass_kg / arm.payload_kg < MASS_PER_PAYLOAD.low:
        out.append(f"moving mass {arm.moving_mass_kg:.3g} kg is implausibly light for a {arm.payload_kg:.3g} kg "
                   f"payload: data-sheet arms weigh at least {MASS_PER_PAYLOAD.data_low:.2g} times their payload; "
                   "placeholder link masses?")
    if _identical(arm.link_masses_kg):
        out.append(f"every moving link weighs {arm.link_masses_kg[0]:.4g} kg: placeholder link masses?")
    return out


def _limit_warnings(arm: ArmFigures) -> list[str]:
    out: list[str] = []
    holding = holding_torque_Nm(arm.reach_m, arm.payload_kg, arm.moving_mass_kg)
    max_effort = float(np.max(arm.effort_Nm)) if arm.effort_Nm.size else 0.0
    if holding > 0 and max_effort > 0:
        ratio = max_effort / holding
        band = TORQUE_PER_HOLDING
        if not band.low <= ratio <= band.high:
            side = "far above" if ratio > band.high else "far below"
            out.append(f"largest torque limit {max_effort:.4g} N·m is {side} arms of this size: holding the "
                       f"stretched-out arm ({arm.reach_m:.2f} m, {arm.moving_mass_kg:.3g} kg, payload "
                       f"{arm.payload_kg:.3g} kg) takes about {holding:.3g} N·m, data sheets state "
                       f"{band.data_low:.2g}-{band.data_high:.2g} times that")
    if arm.velocity_rad_s.size:
        speed = axis1_flange_speed_m_s(float(arm.velocity_rad_s[0]), arm.reach_m)
        band = AXIS1_FLANGE_SPEED
        if not band.low <= speed <= band.high:
            side = "fast" if speed > band.high else "slow"
            out.append(f"axis 1 speed limit {arm.velocity_rad_s[0]:.3g} rad/s is implausibly {side}: it moves the "
                       f"flange at {speed:.3g} m/s at {arm.reach_m:.2f} m reach, data-sheet arms "
                       f"{band.data_low:.2g}-{band.data_high:.2g} m/s")
    if _identical(arm.effort_Nm):
        same_speed = (f" and the same speed limit {arm.velocity_rad_s[0]:.4g} rad/s"
                      if _identical(arm.velocity_rad_s) else "")
        out.append(f"every joint has the same torque limit {arm.effort_Nm[0]:.4g} N·m{same_speed}: placeholder "
                   "limits? (real wrists carry a fraction of the shoulder's torque)")
    return out


def plausibility_warnings(arm: ArmFigures) -> list[str]:
    """One line per figure outside the data-sheet scaling (module docstring); empty when plausible."""
    if not (np.isfinite(arm.reach_m) and arm.reach_m > 0):
        return []
    return [*_mass_warnings(arm), *_limit_warnings(arm)]


def marker_warnings(robot: RobotModel) -> list[str]:
    """A reflector or probe diode that robot.yaml gives (measured or calibrated, not assumed) inside a
    collision capsule: the marker is real, so the capsule is larger than the arm there, and a simulated
    measurement design rejects every pose in which it holds the marker."""
    spec = robot.spec
    out = []
    for field, what, point in marker_points(spec):
        holding = capsules_holding(robot.model, spec.flange_frame, point, spec.capsules)
        if holding:
            out.append(f"{what} ({field}) lies inside {describe(holding)}: the capsules are larger than the arm "
                       "there (edit capsules in robot.yaml), or the offset is wrong")
    return out


def robot_warnings(robot: RobotModel, summary: Mapping[str, object] | None = None) -> list[str]:
    """:func:`plausibility_warnings` of a :class:`~pipeline.robot.model.RobotModel`, and
    :func:`marker_warnings`."""
    return [*plausibility_warnings(ArmFigures.of(robot, summary)), *marker_warnings(robot)]


#: which stages' results rest on each kind of placeholder (:mod:`pipeline.robot.vendor_urdf`): the
#: inertials give calibration its gravity deflection, identification its nominal model and torque
#: limits check, control its nominal feedforward, trajectory its dynamics; the limits bound the
#: excitation, the servo loop's saturation and every plan
PLACEHOLDER_STAGES = {
    "inertials": ("calibration", "identification", "control", "trajectory"),
    "effort limits": ("identification", "control", "trajectory"),
    "velocity limits": ("identification", "control", "trajectory"),
}


#: a robot.yaml value robot init wrote as a placeholder (still unedited): its assumption line's start
_YAML_PLACEHOLDERS = {"limits.effort_Nm: PLACEHOLDER": "effort limits",
                      "limits.velocity_rad_s: PLACEHOLDER": "velocity limits"}


def placeholder_kind(line: str) -> str | None:
    """What an assumption line says is a placeholder (``inertials``, ``effort limits`` ...): a
    ``PLACEHOLDER <kind> (...)`` line of :mod:`pipeline.robot.vendor_urdf`, or a robot.yaml limit
    robot init wrote as one and no one edited since; None for any other line."""
    if line.startswith("PLACEHOLDER "):
        return line[len("PLACEHOLDER "):].split(" (")[0].split(":")[0].strip() or None
    return next((kind for start, kind in _YAML_PLACEHOLDERS.items() if line.startswith(start)), None)


#: the most characters of an assumption a placeholder warning repeats (the whole line is in the report)
WARNING_DETAIL_CHARS = 200


def placeholder_warnings(robot: RobotModel, stages: list[str]) -> list[str]:
    """One line per placeholder of ``robot`` that a result of ``stages`` depends on."""
    out = []
    for line in robot.assumptions:
        kind = placeholder_kind(line)
        if kind is None:
            continue
        using = [s for s in PLACEHOLDER_STAGES.get(kind, ("identification", "control", "trajectory")) if s in stages]
        if using:
            detail = textwrap.shorten(line.split(": ", 1)[-1], WARNING_DETAIL_CHARS, placeholder=" …")
            out.append(f"placeholder {kind} ({detail}): the results of "
                       f"{', '.join(using)} depend on them; give the real values in the URDF or robot.yaml")
    return out
