"""Volumes of a URDF link's meshes: what a placeholder mass is estimated from.

A link's volume is the sum over its collision meshes (else its visual meshes) of each mesh's
convex hull (``scipy.spatial.ConvexHull`` of the vertices coal's mesh loader reads, scaled as
the URDF states), with the links fixed below it (Pinocchio merges them into the same body). A
hull is defined for any mesh, closed or not, and encloses the housing a vendor's collision mesh
outlines. ``None`` where a mesh cannot be found or read.

Density: the arms of example-robot-data and pybullet_data that state their link masses weigh
760-1510 kg/m³ of their collision meshes' convex hulls (UR3 1510, UR5 1400, UR10 1105, Panda 885,
xArm 7 997, Z1 863, iiwa 759, xArm 6 819, Jaco 908; median 908): cast housings, motors and gears
with air inside. :data:`LINK_DENSITY_KG_M3` is that median, rounded.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

from pipeline.robot.urdf_import import resolve_mesh

#: mass per convex-hull volume of a serial arm's links (module docstring)
LINK_DENSITY_KG_M3 = 900.0


def _hull_volume_m3(path: Path, scale: np.ndarray) -> float | None:
    try:
        import coal
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            vertices = np.asarray(coal.MeshLoader().load(str(path), scale).vertices(), float)
        return float(ConvexHull(vertices).volume)
    except Exception:     # noqa: BLE001 (an unreadable or flat mesh: no estimate, the reach rule stands)
        return None


def _fixed_below(root: ET.Element, link: str) -> list[str]:
    """``link`` and the links fixed to it (through fixed joints only)."""
    children: dict[str, list[str]] = {}
    for joint in root.findall("joint"):
        if joint.get("type") == "fixed":
            parent, child = joint.find("parent"), joint.find("child")
            if parent is not None and child is not None:
                children.setdefault(parent.get("link", ""), []).append(child.get("link", ""))
    found, todo = [], [link]
    while todo:
        current = todo.pop()
        found.append(current)
        todo += children.get(current, [])
    return found


def link_volume_m3(root: ET.Element, urdf: Path, link: str) -> float | None:
    """Convex-hull volume of the meshes of ``link`` and the links fixed below it (collision meshes,
    else visual ones); None when it has none or one cannot be read."""
    links = {element.get("name"): element for element in root.findall("link")}
    for tag in ("collision", "visual"):
        meshes = [mesh for name in _fixed_below(root, link) if name in links
                  for element in links[name].findall(tag) for mesh in element.iter("mesh")]
        if not meshes:
            continue
        total = 0.0
        for mesh in meshes:
            path = resolve_mesh(mesh.get("filename", ""), urdf)
            scale = np.array([float(v) for v in (mesh.get("scale") or "1 1 1").split()])
            volume = None if path is None else _hull_volume_m3(path, scale)
            if volume is None:
                return None
            total += volume
        return total
    return None
