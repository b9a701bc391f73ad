"""``robot.yaml``: the robot facts a URDF does not carry, parsed strictly.

Every problem raises :class:`~pipeline.core.errors.RobotFileError` naming the file and the field
(``robot.yaml: actuation.viscous_Nms_rad: expected 6 numbers, got 5``). Unknown keys are
errors, so a typo never silently falls back to a default.
"""

from __future__ import annotations

from collections.abc import Set
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pipeline.core.errors import RobotFileError
from pipeline.core.typed_config import unknown_key
from pipeline.core.yaml12 import YAMLError, load_yaml, yaml_problem
from pipeline.robot.assumed_values import TORQUE_SIDES, assumed_in_force, locked_joints


@dataclass
class Capsule:
    """A capsule (segment ``p0``–``p1`` swept by a sphere) fixed in ``frame``."""

    name: str
    frame: str
    p0: np.ndarray
    p1: np.ndarray
    radius_m: float


@dataclass
class ToolSpec:
    transform_tcp_to_flange: pin.SE3
    reflector_offset_m: np.ndarray
    reflector_axis: np.ndarray


@dataclass
class ActuationSpec:
    """Drive train facts, joint side. ``gear_matrix`` K: ``q_motor = K q``, ``tau_joint = K^T tau_motor``."""

    gear_ratio: np.ndarray
    gear_matrix: np.ndarray
    rotor_inertia_kgm2: np.ndarray
    viscous_Nms_rad: np.ndarray
    coulomb_Nm: np.ndarray
    #: (nv,) width ``w`` of the smoothed sign ``tanh(v / w)`` of the Coulomb friction, per joint (rad/s)
    coulomb_smoothing_rad_s: np.ndarray
    #: torsional joint stiffness (joint side, N m/rad); None: derived (pipeline.robot.stiffness)
    joint_stiffness_Nm_rad: np.ndarray | None = None
    #: Stribeck friction (identified, ``friction_model: stribeck``): static excess over Coulomb
    #: ``f_s`` (N m) and Stribeck velocity ``v_s`` (rad/s) per joint; None: viscous + Coulomb only
    static_friction_excess_Nm: np.ndarray | None = None
    stribeck_velocity_rad_s: np.ndarray | None = None
    #: load-dependent Coulomb friction (identified): ``fl`` per joint, the friction grows by
    #: ``fl |tau_load| tanh(v / w)`` (pipeline.robot.friction); None: no load dependence
    coulomb_load_coefficient: np.ndarray | None = None
    #: where logged torques are measured: "motor" (from motor currents: rotor inertia and drive
    #: friction are in them) or "link" (joint torque sensors after the gear: they are not)
    torque_side: str = "motor"


@dataclass
class TrackerSpec:
    """Nominal laser-tracker placement and noise model (DESIGN.md, "Sensors")."""

    transform_tracker_to_base: pin.SE3
    noise_const_m: float
    noise_per_m: float
    max_incidence_rad: float

    def sigma_m(self, range_m: np.ndarray) -> np.ndarray:
        """Isotropic 1-sigma position noise at the given range."""
        return self.noise_const_m + self.noise_per_m * np.asarray(range_m)


@dataclass
class OpticalTrackerSpec:
    """A camera-based 6-D tracker: a probe of infrared diodes on the tool seen by several cameras
    (paper 004 §3.4: 3D-Creator, 4 diodes, three CCD cameras, pose by stereovision). Model in
    :mod:`pipeline.sim.optical_tracker`; numbers of a particular system go in its robot.yaml.

    Camera-bar frame: ``p_base = transform_camera_to_base p_bar``; every camera looks along the bar's
    +z axis. Probe: diode positions in the marker frame (the reflector frame of ``tool``: flange
    orientation at ``reflector_offset_m``), all emitting along ``diode_axis`` (flange frame).
    """

    transform_camera_to_base: pin.SE3
    camera_positions_m: np.ndarray          # (k, 3) in the bar frame
    field_of_view_half_angle_rad: float     # cone about +z of each camera
    range_m: np.ndarray                     # (2,) nearest and farthest diode distance from a camera
    probe_diodes_m: np.ndarray              # (d, 3) in the marker frame
    diode_axis: np.ndarray                  # (3,) unit, flange frame
    emission_half_angle_rad: float          # a camera sees a diode within this angle of its axis
    min_diodes: int                         # diodes every camera must see for a pose (>= 3)
    noise_const_m: float                    # per-diode isotropic 1-sigma
    noise_per_m: float                      # ... growing with the distance from the bar origin


@dataclass
class CollisionSpec:
    floor_z_m: float
    floor_check_from_joint: int
    #: capsule name pairs left out of the self-collision check
    ignore_pairs: list[tuple[str, str]] = field(default_factory=list)


@dataclass
class RobotSpec:
    """Everything in ``robot.yaml``, validated."""

    path: Path
    name: str
    urdf: Path
    flange_frame: str
    payload_kg: float
    tool: ToolSpec
    actuation: ActuationSpec
    acceleration_rad_s2: np.ndarray
    limit_overrides: dict[str, np.ndarray]
    tracker: TrackerSpec
    collision: CollisionSpec
    capsules: list[Capsule] = field(default_factory=list)
    #: False when robot.yaml has no tracker section (``tracker`` is then a placeholder, never measured)
    has_tracker: bool = True
    #: optional camera-based 6-D tracker (robot.yaml ``optical_tracker``); None: none declared
    optical_tracker: OpticalTrackerSpec | None = None
    #: what was assumed about this robot (kept when a stage saves the model)
    assumptions: list[str] = field(default_factory=list)
    #: first link of the arm chain (None: the URDF's root)
    base_link: str | None = None
    #: joints off the arm chain held at these positions (rad or m; others at 0 or mid-range)
    locked_joints: dict[str, float] = field(default_factory=dict)
    #: values robot.yaml marks as assumed and the user has not edited (:mod:`pipeline.robot.assumed_values`)
    assumed: dict[str, dict] = field(default_factory=dict)
    #: ISO 9283 pose repeatability RP of the arm (m; 1-sigma per axis RP / 3.616,
    #: :mod:`pipeline.robot.repeatability`); None: not stated (calibration leaves it to the remainder)
    repeatability_m: float | None = None


_TOP_KEYS = {
    "name", "urdf", "flange_frame", "payload_kg", "tool", "actuation", "limits", "tracker",
    "collision", "capsules", "assumptions", "optical_tracker", "base_link", "locked_joints", "assumed",
    "repeatability_m",
    # robot-specific defaults of the run configuration (test path placement, moves); read and
    # checked by pipeline.core.config.load_config, which layers them under the config file
    "run_defaults",
}
_REQUIRED_TOP = {"urdf", "flange_frame", "tool", "actuation", "limits"}


def _is_number(value: object) -> bool:
    """An int or float from YAML; ``true``/``false`` are not numbers (a bool is an int in Python)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _optional_list(reader: _Reader, key: str, what: str) -> list[Any]:
    """A list that may be absent or ``null`` (empty); anything else but a list is an error."""
    value = reader.data.get(key)
    if value is None:
        return []
    if not isinstance(value, list):
        raise reader.error(key, f"expected {what}, got {value!r}")
    return value


class _Reader:
    """Typed access to a YAML mapping that reports ``file: field: problem``."""

    def __init__(self, path: Path, data: dict[str, Any], prefix: str = "") -> None:  # YAML values
        self.path, self.data, self.prefix = path, data, prefix

    def error(self, key: str, problem: str) -> RobotFileError:
        return RobotFileError(self.path, f"{self.prefix}{key}", problem)

    def check_keys(self, allowed: set[str], required: Set[str] = frozenset()) -> None:
        for key in self.data:
            if key not in allowed:
                raise self.error(str(key), unknown_key(key, sorted(allowed)))
        for key in sorted(required):
            if key not in self.data:
                raise self.error(key, "missing")

    def sub(self, key: str) -> _Reader:
        value = self.data.get(key)
        if not isinstance(value, dict):
            raise self.error(key, "expected a mapping")
        return _Reader(self.path, value, f"{self.prefix}{key}.")

    def number(self, key: str, *, positive: bool = False, nonnegative: bool = False,
               default: float | None = None) -> float:
        if key not in self.data:
            if default is None:
                raise self.error(key, "missing")
            return float(default)
        value = self.data[key]
        if not _is_number(value) or not np.isfinite(value):
            raise self.error(key, f"expected a finite number, got {value!r}")
        if positive and value <= 0:
            raise self.error(key, f"must be positive, got {value}")
        if nonnegative and value < 0:
            raise self.error(key, f"must not be negative, got {value}")
        return float(value)

    def number_or_vector(self, key: str, length: int, *, positive: bool = False, default: float) -> np.ndarray:
        """(length,) values: one number for every entry or a list of ``length`` numbers."""
        if isinstance(self.data.get(key), list):
            return self.vector(key, length, positive=positive)
        return np.full(length, self.number(key, positive=positive, default=default))

    def integer(self, key: str, *, minimum: int | None = None, maximum: int | None = None,
                default: int | None = None) -> int:
        if key not in self.data:
            if default is None:
                raise self.error(key, "missing")
            return int(default)
        value = self.data[key]
        if not _is_int(value):
            raise self.error(key, f"expected an integer, got {value!r}")
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            bounds = f"{'' if minimum is None else minimum}..{'' if maximum is None else maximum}"
            raise self.error(key, f"must be in {bounds}, got {value}")
        return int(value)

    def vector(self, key: str, length: int | None, *, nonnegative: bool = False,
               positive: bool = False, default: npt.ArrayLike | None = None) -> np.ndarray:
        if key not in self.data:
            if default is None:
                raise self.error(key, "missing")
            return np.asarray(default, dtype=float)
        value = self.data[key]
        if not isinstance(value, list) or not all(_is_number(v) for v in value):
            raise self.error(key, f"expected a list of numbers, got {value!r}")
        array = np.asarray(value, dtype=float)
        if length is not None and array.shape != (length,):
            raise self.error(key, f"expected {length} numbers, got {len(value)}")
        if not np.all(np.isfinite(array)):
            raise self.error(key, "contains a non-finite number")
        if nonnegative and np.any(array < 0):
            raise self.error(key, f"must not be negative, got {value}")
        if positive and np.any(array <= 0):
            raise self.error(key, f"must be positive, got {value}")
        return array

    def text(self, key: str, default: str | None = None) -> str:
        value = self.data.get(key, default)
        if not isinstance(value, str) or not value:
            raise self.error(key, f"expected a non-empty string, got {value!r}")
        return value

    def transform(self, key: str) -> pin.SE3:
        reader = self.sub(key)
        reader.check_keys({"xyz", "rpy"}, {"xyz", "rpy"})
        xyz = reader.vector("xyz", 3)
        rpy = reader.vector("rpy", 3)
        return pin.SE3(pin.rpy.rpyToMatrix(rpy), xyz)


def load_robot_spec(path: Path, nq: int | None = None) -> RobotSpec:
    """Parse and validate ``robot.yaml``; ``nq`` checks per-joint list lengths when known."""
    path = Path(path)
    if not path.is_file():
        raise RobotFileError(path, "robot.yaml", "file not found")
    try:
        data = load_yaml(path.read_text(encoding="utf-8"))
    except YAMLError as exc:
        raise RobotFileError(path, *yaml_problem(exc)) from None
    if not isinstance(data, dict):
        raise RobotFileError(path, "top level", "expected a mapping")
    top = _Reader(path, data)
    top.check_keys(_TOP_KEYS, _REQUIRED_TOP)
    if "run_defaults" in data and not isinstance(data["run_defaults"], dict):
        raise top.error("run_defaults", "expected a mapping of run-configuration sections")

    tool = top.sub("tool")
    tool.check_keys({"transform_tcp_to_flange", "reflector_offset_m", "reflector_axis"},
                    {"transform_tcp_to_flange", "reflector_offset_m"})
    axis = tool.vector("reflector_axis", 3, default=[0.0, 0.0, 1.0])
    if np.linalg.norm(axis) < 1e-9:
        raise tool.error("reflector_axis", "must not be the zero vector")

    act = top.sub("actuation")
    act.check_keys(
        {"gear_ratio", "gear_coupling", "rotor_inertia_kgm2", "viscous_Nms_rad", "coulomb_Nm",
         "coulomb_smoothing_rad_s", "joint_stiffness_Nm_rad", "static_friction_excess_Nm",
         "stribeck_velocity_rad_s", "torque_side", "coulomb_load_coefficient"},
        {"gear_ratio", "rotor_inertia_kgm2", "viscous_Nms_rad", "coulomb_Nm"},
    )
    per_joint = [len(v) for k in ("gear_ratio", "rotor_inertia_kgm2", "viscous_Nms_rad", "coulomb_Nm")
                 if isinstance(v := act.data.get(k), list)]      # nq unknown: blame the odd list out
    gear_ratio = act.vector("gear_ratio", nq if nq is not None else max(set(per_joint), key=per_joint.count))
    if np.any(gear_ratio == 0):
        raise act.error("gear_ratio", "a gear ratio must not be zero")
    n = len(gear_ratio)
    gear_matrix = np.diag(gear_ratio)
    coupling = _optional_list(act, "gear_coupling", "a list of [row, col, value]")
    seen: dict[tuple[int, int], int] = {}
    for k, entry in enumerate(coupling):
        where = f"gear_coupling[{k}]"
        if not isinstance(entry, list) or len(entry) != 3:
            raise act.error(where, f"expected [row, col, value], got {entry!r}")
        row, col, value = entry
        for label, index in (("row", row), ("col", col)):
            if not _is_int(index) or not 0 <= index < n:
                raise act.error(where, f"{label} must be an integer joint index 0..{n - 1}, got {index!r}")
        if row == col:
            raise act.error(where, f"row and col must differ (the diagonal is gear_ratio), got [{row}, {col}]")
        if not _is_number(value) or not np.isfinite(value):
            raise act.error(where, f"value must be a finite number, got {value!r}")
        if (row, col) in seen:
            raise act.error(where, f"[{row}, {col}] is already set by gear_coupling[{seen[row, col]}]")
        seen[row, col] = k
        gear_matrix[row, col] = float(value)
    if abs(np.linalg.det(gear_matrix)) < 1e-12:
        raise act.error("gear_coupling", "the gear matrix is singular")
    actuation = ActuationSpec(
        gear_ratio=gear_ratio,
        gear_matrix=gear_matrix,
        rotor_inertia_kgm2=act.vector("rotor_inertia_kgm2", n, nonnegative=True),
        viscous_Nms_rad=act.vector("viscous_Nms_rad", n, nonnegative=True),
        coulomb_Nm=act.vector("coulomb_Nm", n, nonnegative=True),
        coulomb_smoothing_rad_s=act.number_or_vector("coulomb_smoothing_rad_s", n, positive=True, default=0.01),
        joint_stiffness_Nm_rad=(act.vector("joint_stiffness_Nm_rad", n, positive=True)
                                if "joint_stiffness_Nm_rad" in act.data else None),
        torque_side=act.text("torque_side", default="motor"),
    )
    if actuation.torque_side not in TORQUE_SIDES:
        raise act.error("torque_side", f"must be one of {', '.join(TORQUE_SIDES)}, got {actuation.torque_side!r}")
    if ("static_friction_excess_Nm" in act.data) != ("stribeck_velocity_rad_s" in act.data):
        raise act.error("stribeck_velocity_rad_s", "give static_friction_excess_Nm and stribeck_velocity_rad_s "
                        "together (the Stribeck friction term) or neither")
    if "static_friction_excess_Nm" in act.data:
        actuation.static_friction_excess_Nm = act.vector("static_friction_excess_Nm", n, nonnegative=True)
        actuation.stribeck_velocity_rad_s = act.vector("stribeck_velocity_rad_s", n, positive=True)
    if "coulomb_load_coefficient" in act.data:
        actuation.coulomb_load_coefficient = act.vector("coulomb_load_coefficient", n, nonnegative=True)

    lim = top.sub("limits")
    overridable = ("lower_rad", "upper_rad", "velocity_rad_s", "effort_Nm")
    lim.check_keys({"acceleration_rad_s2", *overridable}, {"acceleration_rad_s2"})
    overrides = {key: lim.vector(key, n) for key in overridable if key in lim.data}
    for key in ("velocity_rad_s", "effort_Nm"):
        if key in overrides and np.any(overrides[key] <= 0):
            raise lim.error(key, "must be positive")

    has_tracker = data.get("tracker") is not None
    trk = top.sub("tracker") if has_tracker else _Reader(path, {"transform_tracker_to_base":
                                                                {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}},
                                                         "tracker.")
    trk.check_keys({"transform_tracker_to_base", "noise_const_m", "noise_per_m", "max_incidence_deg"},
                   {"transform_tracker_to_base"})
    tracker = TrackerSpec(
        transform_tracker_to_base=trk.transform("transform_tracker_to_base"),
        noise_const_m=trk.number("noise_const_m", nonnegative=True, default=8e-6),
        noise_per_m=trk.number("noise_per_m", nonnegative=True, default=3e-6),
        max_incidence_rad=np.deg2rad(trk.number("max_incidence_deg", positive=True, default=30.0)),
    )

    collision = CollisionSpec(0.0, 2)
    if "collision" in data:
        col = top.sub("collision")
        col.check_keys({"floor_z_m", "floor_check_from_joint", "ignore_pairs"})
        ignore = _optional_list(col, "ignore_pairs", "a list of [capsule name, capsule name]")
        for k, pair in enumerate(ignore):
            if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(n, str) for n in pair)):
                raise col.error(f"ignore_pairs[{k}]", f"expected [capsule name, capsule name], got {pair!r}")
        collision = CollisionSpec(col.number("floor_z_m", default=0.0),
                                  col.integer("floor_check_from_joint", minimum=0, maximum=nq, default=2),
                                  [tuple(pair) for pair in ignore])

    capsules = []
    raw_capsules = _optional_list(top, "capsules", "a list of capsules")
    for k, raw in enumerate(raw_capsules):
        if not isinstance(raw, dict):
            raise top.error(f"capsules[{k}]", "expected a mapping")
        cap = _Reader(path, raw, f"capsules[{k}].")
        cap.check_keys({"name", "frame", "p0", "p1", "radius_m"}, {"name", "frame", "p0", "p1", "radius_m"})
        capsules.append(Capsule(cap.text("name"), cap.text("frame"), cap.vector("p0", 3), cap.vector("p1", 3),
                                cap.number("radius_m", positive=True)))

    optical = _optical_tracker(top.sub("optical_tracker")) if data.get("optical_tracker") is not None else None

    return RobotSpec(
        path=path,
        name=top.text("name", default=path.parent.name),
        urdf=path.parent / top.text("urdf"),
        flange_frame=top.text("flange_frame"),
        payload_kg=top.number("payload_kg", nonnegative=True, default=0.0),
        tool=ToolSpec(tool.transform("transform_tcp_to_flange"), tool.vector("reflector_offset_m", 3),
                      axis / np.linalg.norm(axis)),
        actuation=actuation,
        acceleration_rad_s2=lim.vector("acceleration_rad_s2", n, positive=True),
        limit_overrides=overrides,
        tracker=tracker,
        collision=collision,
        capsules=capsules,
        has_tracker=has_tracker,
        assumptions=[str(a) for a in _optional_list(top, "assumptions", "a list of sentences")],
        optical_tracker=optical,
        base_link=top.text("base_link") if data.get("base_link") is not None else None,
        locked_joints=locked_joints(path, data),
        assumed=assumed_in_force(path, data),
        repeatability_m=(top.number("repeatability_m", nonnegative=True)
                         if data.get("repeatability_m") is not None else None),
    )



def _points(reader: _Reader, key: str, minimum: int) -> np.ndarray:
    value = reader.data.get(key)
    if not isinstance(value, list) or len(value) < minimum or not all(
            isinstance(v, list) and len(v) == 3 and all(_is_number(c) for c in v) for v in value):
        raise reader.error(key, f"expected a list of at least {minimum} [x, y, z] points, got {value!r}")
    return np.asarray(value, float)


def _optical_tracker(opt: _Reader) -> OpticalTrackerSpec:
    """The ``optical_tracker`` section (:class:`OpticalTrackerSpec`)."""
    opt.check_keys({"transform_camera_to_base", "camera_positions_m", "field_of_view_half_angle_deg", "range_m",
                    "probe_diodes_m", "diode_axis", "emission_half_angle_deg", "min_diodes", "noise_const_m",
                    "noise_per_m"}, {"transform_camera_to_base", "camera_positions_m", "probe_diodes_m"})
    diodes = _points(opt, "probe_diodes_m", 3)
    axis = opt.vector("diode_axis", 3, default=[0.0, 0.0, 1.0])
    if np.linalg.norm(axis) < 1e-9:
        raise opt.error("diode_axis", "must not be the zero vector")
    rng = opt.vector("range_m", 2, nonnegative=True, default=[0.5, 6.0])
    if not rng[0] < rng[1]:
        raise opt.error("range_m", f"expected [nearest, farthest] with nearest < farthest, got {list(rng)}")
    spread = np.linalg.svd(diodes - diodes.mean(axis=0), compute_uv=False)
    if spread[1] < 1e-6:
        raise opt.error("probe_diodes_m", "the diodes are collinear: they cannot fix an orientation")
    fov = opt.number("field_of_view_half_angle_deg", positive=True, default=35.0)
    emission = opt.number("emission_half_angle_deg", positive=True, default=60.0)
    for key, value in (("field_of_view_half_angle_deg", fov), ("emission_half_angle_deg", emission)):
        if value >= 90.0:
            raise opt.error(key, f"must be below 90 deg, got {value}")
    return OpticalTrackerSpec(
        transform_camera_to_base=opt.transform("transform_camera_to_base"),
        camera_positions_m=_points(opt, "camera_positions_m", 2),
        field_of_view_half_angle_rad=float(np.deg2rad(fov)),
        range_m=rng,
        probe_diodes_m=diodes,
        diode_axis=axis / np.linalg.norm(axis),
        emission_half_angle_rad=float(np.deg2rad(emission)),
        min_diodes=opt.integer("min_diodes", minimum=3, maximum=len(diodes), default=3),
        noise_const_m=opt.number("noise_const_m", nonnegative=True, default=1.0e-4),
        noise_per_m=opt.number("noise_per_m", nonnegative=True, default=0.0),
    )
