"""The EN ISO 9283 test path (DESIGN.md "EN ISO 9283 test path", paper 004 §2.3.3).

A cube of edge ``L`` with edges parallel to the base axes, centred at ``centre``; the measuring
plane is a diagonal plane of the cube (through two opposite edges), spanned by the in-plane unit
vectors ``u`` (along the edges it contains) and ``w`` (along the face diagonal). The plane is the
rectangle ``L x sqrt(2) L`` with corners ``C1..C4``. ``P1`` is the cube centre; ``P2..P5`` lie on
the rectangle's diagonals at ``corner_fraction`` (10 %) of the diagonal length from the corners.

Path, each piece starting and ending at rest: line P2 -> P4, rectangle P4 -> P5 -> P2 -> P3 -> P4,
transition to the large circle (diameter 0.8 L about P1, starting on the ray P1 -> P4), the circle,
transition to the small circle (0.1 L), the small circle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pipeline.core.config_checks import check_number, check_unique, check_vector
from pipeline.core.errors import ConfigError, Source
from pipeline.core.typed_config import check_choices
from pipeline.robot.paths import CartesianPath, CirclePath, LinePath, rectangle

PLANES = {
    "diagonal_x": (np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 1.0]) / np.sqrt(2)),
    "diagonal_y": (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 1.0]) / np.sqrt(2)),
    "horizontal": (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])),
}


class IsoPath(CartesianPath):
    """Concatenation of rest-to-rest pieces; ``points`` holds P1..P5 and C1..C4 (m)."""

    def __init__(self, pieces: list[CartesianPath], points: dict[str, np.ndarray], rotation: np.ndarray,
                 edge_m: float, plane: str) -> None:
        self.pieces = pieces
        self.points = points
        self.rotation = rotation
        self.edge_m = edge_m
        self.plane = plane
        self.label = "iso9283"
        self.breaks = np.concatenate([[0.0], np.cumsum([p.length_m for p in pieces])])
        self.length_m = float(self.breaks[-1])

    def _split(self, s_m: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        s = np.clip(np.atleast_1d(np.asarray(s_m, float)), 0.0, self.length_m)
        idx = np.clip(np.searchsorted(self.breaks, s, side="right") - 1, 0, len(self.pieces) - 1)
        return s, idx

    def position(self, s_m: npt.ArrayLike) -> np.ndarray:
        s, idx = self._split(s_m)
        out = np.empty((len(s), 3))
        for i, p in enumerate(self.pieces):
            m = idx == i
            if m.any():
                out[m] = p.position(s[m] - self.breaks[i])
        return out

    def derivatives(self, s_m: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        s, idx = self._split(s_m)
        d1, d2 = np.empty((len(s), 3)), np.empty((len(s), 3))
        for i, p in enumerate(self.pieces):
            m = idx == i
            if m.any():
                d1[m], d2[m] = p.derivatives(s[m] - self.breaks[i])
        return d1, d2

    def segments(self) -> list[CartesianPath]:
        return [sg for p in self.pieces for sg in p.segments()]


#: constant tool orientations of the path (pipeline.robot.defaults.iso_rotation), in the order a derived
#: cube tries them
ToolOrientation = Literal["down", "plane", "ready"]
IsoPlane = Literal["diagonal_x", "diagonal_y", "horizontal"]        # keys of PLANES
IsoSegment = Literal["line", "rectangle", "circle_large", "circle_small"]
TOOL_ORIENTATIONS: tuple[ToolOrientation, ...] = get_args(ToolOrientation)
ISO_PLANES: tuple[IsoPlane, ...] = get_args(IsoPlane)
ISO_SEGMENTS: tuple[IsoSegment, ...] = get_args(IsoSegment)


@dataclass
class IsoPathConfig:
    """EN ISO 9283 test path (DESIGN.md): cube of edge L, centre, diagonal plane, speeds."""

    #: None = derived from the robot: the largest feasible cube (pipeline.robot.defaults.iso_cube)
    edge_m: float | None = None
    centre_m: list[float] | None = None
    plane: IsoPlane = "diagonal_x"
    #: constant TCP orientation: down | plane (normal to the plane, away from the base) | ready (as at the
    #: robot's ready pose); None = derived: down, else plane, else ready, the first with a feasible cube
    tool_orientation: ToolOrientation | None = None
    speed_m_s: float = 1.0
    acceleration_m_s2: float = 5.0
    jerk_m_s3: float = 50.0
    corner_fraction: float = 0.1       # P2..P5 at this fraction of the diagonal from the corners
    large_circle_fraction: float = 0.8  # circle diameters as fractions of the edge (ISO: 80 % and 10 %)
    small_circle_fraction: float = 0.1
    segments: list[IsoSegment] = field(default_factory=lambda: list(ISO_SEGMENTS))

    def __post_init__(self) -> None:
        self.validate(None)

    def validate(self, source: Source = None, where: str = "control.iso") -> None:
        """Robot-independent checks; ConfigError naming ``<where>.<field>``."""
        if self.edge_m is not None:
            check_number(source, f"{where}.edge_m", self.edge_m, gt=0, unit="m")
        if self.centre_m is not None:
            check_vector(source, f"{where}.centre_m", self.centre_m, 3, "m")
        check_choices(self, where, source)
        check_number(source, f"{where}.speed_m_s", self.speed_m_s, gt=0, unit="m/s")
        check_number(source, f"{where}.acceleration_m_s2", self.acceleration_m_s2, gt=0, unit="m/s^2")
        check_number(source, f"{where}.jerk_m_s3", self.jerk_m_s3, gt=0, unit="m/s^3")
        check_number(source, f"{where}.corner_fraction", self.corner_fraction, gt=0, lt=0.5,
                     why=" (P2..P5 lie this fraction of the diagonal in from the corners)")
        # the circles are centred on P1 inside the L x L (or L x sqrt(2) L) rectangle of the plane
        for name in ("large_circle_fraction", "small_circle_fraction"):
            check_number(source, f"{where}.{name}", getattr(self, name), gt=0, le=1,
                         why=" (circle diameter as a fraction of the cube edge)")
        if not isinstance(self.segments, (list, tuple)) or not self.segments:
            raise ConfigError(source, f"{where}.segments",
                              f"expected a non-empty list of {', '.join(ISO_SEGMENTS)}, got {self.segments!r}")
        check_unique(source, f"{where}.segments", self.segments)


def tool_rotation(plane: str, tool_down: bool = True) -> np.ndarray:
    """Constant TCP orientation: z axis pointing down, or against the measuring plane's normal."""
    if tool_down:
        return pin.utils.rotate("x", np.pi)
    u, w = PLANES[plane]
    z = -np.cross(u, w)
    if z[0] < 0:  # face away from the robot base
        z = -z
    x = u - z * (u @ z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def iso9283_path(robot: object | None, edge_m: float, centre_m: npt.ArrayLike, plane: str = "diagonal_x",
                 rotation: np.ndarray | None = None, corner_fraction: float = 0.1,
                 large_circle_fraction: float = 0.8, small_circle_fraction: float = 0.1,
                 segments: Sequence[str] = ("line", "rectangle", "circle_large", "circle_small")) -> IsoPath:
    """Build the ISO 9283 path in a cube of edge ``edge_m`` centred at ``centre_m`` (base frame, m;
    a robot's cube comes from :func:`pipeline.robot.defaults.iso_cube` or its ``run_defaults``).
    ``rotation``: constant TCP orientation (default: tool z axis down).

    ``robot`` is accepted for the contract (the workspace check is done by IK when the path is
    executed).
    """
    del robot
    if plane not in PLANES:
        raise ConfigError(None, "control.iso.plane", f"unknown plane {plane!r}; one of {sorted(PLANES)}")
    if edge_m <= 0:
        raise ConfigError(None, "control.iso.edge_m", "must be > 0")
    c = np.asarray(centre_m, float)
    u, w = PLANES[plane]
    half_u = edge_m / 2
    half_w = edge_m / 2 * (np.sqrt(2) if plane != "horizontal" else 1.0)
    C = {  # rectangle corners in order around the plane
        "C1": c - half_u * u - half_w * w, "C2": c + half_u * u - half_w * w,
        "C3": c + half_u * u + half_w * w, "C4": c - half_u * u + half_w * w,
    }
    f = corner_fraction
    P = {"P1": c}
    for name, corner in zip(("P2", "P3", "P4", "P5"), ("C1", "C2", "C3", "C4"), strict=True):
        P[name] = C[corner] + f * 2 * (c - C[corner])  # 10 % of the diagonal from the corner
    R = pin.utils.rotate("x", np.pi) if rotation is None else np.asarray(rotation, float)
    normal = np.cross(u, w)
    pieces: list[CartesianPath] = []
    cur = None
    if "line" in segments:
        pieces.append(LinePath(P["P2"], P["P4"], R, "line P2-P4"))
        cur = P["P4"]
    if "rectangle" in segments:
        if cur is None:
            cur = P["P4"]
        pieces.append(rectangle([P["P4"], P["P5"], P["P2"], P["P3"]], R, label="rectangle"))
    d = (P["P4"] - c) / np.linalg.norm(P["P4"] - c)
    for key, frac in (("circle_large", large_circle_fraction), ("circle_small", small_circle_fraction)):
        if key not in segments:
            continue
        r = frac * edge_m / 2
        start = c + r * d
        if cur is not None and np.linalg.norm(start - cur) > 1e-9:
            pieces.append(LinePath(cur, start, R, f"transition to {key}"))
        pieces.append(CirclePath(c, normal, r, d, 2 * np.pi, R, key))
        cur = start
    if not pieces:
        raise ConfigError(None, "control.iso.segments", "no path segment selected")
    return IsoPath(pieces, {**P, **C}, R, edge_m, plane)
