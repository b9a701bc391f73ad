"""Public arm models of the PyPI package ``example-robot-data`` (a test and benchmark dependency,
installed with the ``dev`` extra): where its URDFs are, by a short name.

The package ships no Python module; its files live under ``<site-packages>/cmeel.prefix/share/
example-robot-data/robots/``. Kinova's Jaco (continuous joints, loaded with one turn each way) is
left unnamed on purpose: the any-arm tests must hold for arms they do not name.
"""

from __future__ import annotations

import sys
from pathlib import Path

#: short name -> URDF path relative to the package's ``robots/`` folder
EXAMPLE_ARMS: dict[str, str] = {
    "ur3": "ur_description/urdf/ur3_robot.urdf",
    "ur5": "ur_description/urdf/ur5_robot.urdf",
    "ur10": "ur_description/urdf/ur10_robot.urdf",
    "panda": "panda_description/urdf/panda.urdf",
    "xarm7": "xarm_description/urdf/xarm7.urdf",
    "z1": "z1_description/urdf/z1.urdf",
}


def example_robots_dir() -> Path | None:
    """The package's ``robots/`` folder on ``sys.path``, or None when it is not installed."""
    for base in map(Path, sys.path):
        candidate = base / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
        if candidate.is_dir():
            return candidate
    return None


def example_arm_urdf(name: str) -> Path | None:
    """URDF of an example arm by short name (:data:`EXAMPLE_ARMS`) or by its path relative to the
    package's ``robots/`` folder; None when the package (or the file) is not installed."""
    root = example_robots_dir()
    if root is None:
        return None
    path = root / EXAMPLE_ARMS.get(name, name)
    return path if path.is_file() else None
