"""The arm corpus: public arm models that a fresh clone installs from PyPI (the ``dev`` extra),
each named by its package and the file's path inside it, plus the built-in robots' URDFs.

Every entry goes through ``robot init`` (no options), ``check`` and a run of every stage as
shipped (``tests/anyarm/test_corpus.py``; the table in ``docs/robots.md`` is rendered from those
runs by ``tools/corpus_table.py``). Packages are located without importing them (some import
heavy simulators on import): :func:`importlib.util.find_spec` gives their folder.

Sources: example-robot-data (URDF, BSD-3-Clause), pybullet's ``pybullet_data`` (URDF, zlib),
rtb-data (the Robotics Toolbox's ROS-Industrial URDFs, MIT), robosuite-models (MJCF with meshes,
MIT), and the repository's ``robots/`` (URDF). Not in it: MJCF models made for gravity-free
simulation (gymnasium's pusher: 2 N·m actuators on a 7-axis arm), which no stage can move under
gravity.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path

from pipeline.robot.example_robots import example_robots_dir

REPO_ROBOTS = Path(__file__).resolve().parents[2] / "robots"


@dataclass(frozen=True)
class PublicArm:
    """One corpus arm: ``name`` (short, unique), ``source`` (the PyPI package, or ``built-in``),
    ``path`` inside the source's folder, and its number of arm axes as ``robot init`` finds them."""

    name: str
    source: str
    path: str
    axes: int

    @property
    def fmt(self) -> str:
        """``MJCF`` or ``URDF``."""
        return "MJCF" if self.path.endswith(".xml") else "URDF"


def _arms(source: str, entries: dict[str, tuple[str, int]]) -> list[PublicArm]:
    return [PublicArm(name, source, path, axes) for name, (path, axes) in entries.items()]


CORPUS: list[PublicArm] = [
    *_arms("example-robot-data", {
        "ur3": ("ur_description/urdf/ur3_robot.urdf", 6),
        "ur5": ("ur_description/urdf/ur5_robot.urdf", 6),
        "ur10": ("ur_description/urdf/ur10_robot.urdf", 6),
        "ur5_gripper": ("ur_description/urdf/ur5_gripper.urdf", 6),
        "panda": ("panda_description/urdf/panda.urdf", 7),
        "xarm7": ("xarm_description/urdf/xarm7.urdf", 7),
        "z1": ("z1_description/urdf/z1.urdf", 6),
        "jaco_j2s6s200": ("kinova_description/robots/kinova.urdf", 6),
        "tiago_arm": ("tiago_description/robots/tiago_no_hand.urdf", 7),
    }),
    *_arms("pybullet", {
        "pb_kuka_iiwa": ("kuka_iiwa/model.urdf", 7),
        "pb_franka_panda": ("franka_panda/panda.urdf", 7),
        "pb_xarm6": ("xarm/xarm6_robot.urdf", 6),
        "pb_xarm6_gripper": ("xarm/xarm6_with_gripper.urdf", 6),
    }),
    *_arms("rtb-data", {
        "abb_irb140": ("xacro/abb_irb140_description/urdf/irb140.urdf", 6),
        "kuka_kr16_2": ("xacro/kuka_description/kuka_kr16/urdf/kr16_2.urdf", 6),
        "kuka_kr120": ("xacro/kuka_description/kuka_kr120/urdf/kr120r2500pro.urdf", 6),
        "kuka_kr210": ("xacro/kuka_description/kuka_kr210/urdf/kr210l150.urdf", 6),
        "kuka_lbr_iiwa14": ("xacro/kuka_description/kuka_lbr_iiwa/urdf/lbr_iiwa_14_r820.urdf", 7),
        "puma560": ("xacro/unimation_puma560_description/urdf/puma560_robot.urdf", 6),
    }),
    *_arms("robosuite-models", {
        "rs_arx5": ("assets/robots/arx5/robot.xml", 6),
        "rs_vx300s": ("assets/robots/vx300s/robot.xml", 6),
        "rs_z1": ("assets/robots/z1/robot.xml", 6),
    }),
    *_arms("built-in", {
        "rx130l": ("rx130l/rx130l.urdf", 6),
        "staubli_tx40": ("staubli_tx40/tx40.urdf", 6),
        "kuka_kr15": ("kuka_kr15/kuka_kr15.urdf", 6),
        "kuka_kr300": ("kuka_kr300/kuka_kr300.urdf", 6),
    }),
]

#: the Python package (import name) that holds each PyPI source's files
_PACKAGES = {"pybullet": "pybullet_data", "rtb-data": "rtbdata", "robosuite-models": "robosuite_models"}


def source_dir(source: str) -> Path | None:
    """The folder of a corpus source, or None when its package is not installed."""
    if source == "example-robot-data":
        return example_robots_dir()
    if source == "built-in":
        return REPO_ROBOTS
    spec = importlib.util.find_spec(_PACKAGES[source])
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations)))


def arm_file(arm: PublicArm) -> Path | None:
    """The arm's URDF or MJCF file, or None when its source is not installed."""
    folder = source_dir(arm.source)
    path = None if folder is None else folder / arm.path
    return path if path is not None and path.is_file() else None


def corpus_arm(name: str) -> PublicArm:
    """The corpus entry called ``name``."""
    for arm in CORPUS:
        if arm.name == name:
            return arm
    raise KeyError(f"no corpus arm {name!r} (known: {', '.join(a.name for a in CORPUS)})")
