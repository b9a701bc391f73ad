"""Run names and the robot a run directory belongs to.

A run without a ``name`` is named after its robot and profile: ``rx130l`` for the full profile,
``iiwa-quick`` for the quick one (the robot's folder name, its ROS package's for a ``urdf`` folder,
or a URDF's file stem). Two robots
therefore never share a default run directory. The robot a directory was made with is the
``robot`` of its ``config.yaml``; a run of another robot into it is refused unless forced, so a
run of one's own arm never replaces the built-in robot's run.
"""

from __future__ import annotations

from pathlib import Path

from pipeline.core.errors import ConfigError
from pipeline.core.yaml12 import YAMLError, load_yaml

#: the profile whose runs carry the bare robot name
DEFAULT_PROFILE = "full"
RUN_CONFIG_FILE = "config.yaml"


def robot_label(robot: str | Path) -> str:
    """Short name of a robot reference: a folder's name (for a ROS package's ``<package>/urdf``
    folder, the package's), a URDF's file stem, or the name itself."""
    path = Path(str(robot).rstrip("/\\") or str(robot))
    if path.suffix.lower() == ".urdf":
        return path.stem
    if path.name == "urdf" and path.parent.name:
        return path.parent.name
    return path.name or str(robot)


def default_run_name(robot: str | Path, profile: str) -> str:
    """``<robot>`` for the full profile, ``<robot>-<profile>`` otherwise."""
    label = robot_label(robot)
    return label if profile == DEFAULT_PROFILE else f"{label}-{profile}"


def run_dir_robot(run_dir: Path) -> str | None:
    """The ``robot`` of the run's ``config.yaml``; None for a new (or unreadable) run directory."""
    path = Path(run_dir) / RUN_CONFIG_FILE
    try:
        data = load_yaml(path.read_text(encoding="utf-8"))
    except (OSError, YAMLError):
        return None
    robot = data.get("robot") if isinstance(data, dict) else None
    return str(robot) if robot not in (None, "") else None


def check_run_robot(run_dir: Path, robot: str | Path, force: bool = False) -> None:
    """Refuse (:class:`ConfigError`) a run of ``robot`` into a directory made with another robot,
    unless ``force``."""
    stored = run_dir_robot(run_dir)
    if force or stored is None or robot_label(stored) == robot_label(robot):
        return
    raise ConfigError(Path(run_dir) / RUN_CONFIG_FILE, "robot",
                      f"this run directory holds a run of robot {robot_label(stored)!r}, not of "
                      f"{robot_label(robot)!r}: choose another run name (--set name=...) or --out, "
                      "or replace that run with --force")
