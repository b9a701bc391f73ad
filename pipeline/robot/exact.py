"""Lossless robot artefacts: the numbers of a handed-on robot stored beside its URDF.

A URDF keeps a joint's rotation as roll-pitch-yaw and ``robot.yaml`` keeps some values in
degrees or as RPY: reading them back changes the model by a few ulp (about 4e-16), and a later
stage that runs on the reloaded robot then differs from one that ran in the same process.
Here the Pinocchio model is stored with Pinocchio's own serialisation (a text archive) (every joint
placement, inertia, frame, limit and armature bit for bit) and every floating-point number of
the robot's facts (``RobotSpec``: tool, tracker, actuation, capsules, ...) in an ``.npz`` keyed by
its dotted field path. :func:`load_exact_robot` reads the URDF folder and then puts these
numbers back, so ``load_exact_robot(save_exact_robot(robot, d))`` equals ``robot`` exactly; the
URDF and ``robot.yaml`` stay the readable (and portable) form.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pipeline.core.artefacts import read_npz, write_bytes, write_npz
from pipeline.core.errors import RobotFileError
from pipeline.robot.model import RobotModel
from pipeline.robot.residual_map import ResidualMap

#: file names inside a saved robot folder
MODEL_TEXT = "model.pinocchio.txt"
SPEC_NPZ = "spec_exact.npz"
#: the calibration's residual map a calibrated robot carries (:mod:`pipeline.robot.residual_map`)
RESIDUAL_MAP_NPZ = "residual_map.npz"


def _float_fields(value: object, path: str) -> Iterator[tuple[str, np.ndarray]]:
    """(dotted path, float array) of every float, float array and SE3 inside ``value``."""
    if isinstance(value, pin.SE3):
        yield path, np.asarray(value.homogeneous, float).copy()
    elif isinstance(value, np.ndarray):
        if np.issubdtype(value.dtype, np.floating):
            yield path, value.copy()
    elif isinstance(value, float):
        yield path, np.asarray(value, float)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            yield from _float_fields(getattr(value, f.name), f"{path}.{f.name}" if path else f.name)
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from _float_fields(item, f"{path}.{key}" if path else str(key))
    elif isinstance(value, (list, tuple)):
        for k, item in enumerate(value):
            yield from _float_fields(item, f"{path}[{k}]")


def _model_bytes(model: pin.Model) -> bytes:
    return bytes(model.saveToString().encode("utf-8"))


def save_exact_robot(robot: RobotModel, folder: str | Path) -> Path:
    """``robot.save(folder)`` plus the exact numbers (:data:`MODEL_TEXT`, :data:`SPEC_NPZ`) and the
    residual map the robot carries (:data:`RESIDUAL_MAP_NPZ`, absent without one)."""
    folder = Path(robot.save(folder))
    write_bytes(folder / MODEL_TEXT, _model_bytes(robot.model))
    write_npz(folder / SPEC_NPZ, dict(_float_fields(robot.spec, "")))
    if robot.residual_map is not None:
        write_npz(folder / RESIDUAL_MAP_NPZ, robot.residual_map.to_arrays())
    elif (folder / RESIDUAL_MAP_NPZ).exists():
        (folder / RESIDUAL_MAP_NPZ).unlink()
    return folder


def attach_residual_map(robot: RobotModel, folder: Path) -> RobotModel:
    """``robot`` with the residual map saved in ``folder`` (if any)."""
    path = folder / RESIDUAL_MAP_NPZ
    robot.residual_map = ResidualMap.from_arrays(read_npz(path)) if path.is_file() else None
    return robot


def _set_path(root: object, path: str, array: np.ndarray) -> bool:
    """Put ``array`` at dotted ``path`` inside ``root`` when a value of the same kind is there."""
    parts = path.replace("[", ".[").split(".")
    parent: Any = root    # a dataclass, dict or list of the spec: walked by name or index
    for part in parts[:-1]:
        parent = parent[int(part[1:-1])] if part.startswith("[") else (
            parent[part] if isinstance(parent, dict) else getattr(parent, part, None))
        if parent is None:
            return False
    last = parts[-1]
    if last.startswith("["):
        return False                     # floats directly inside lists are not used by the spec
    current = parent.get(last) if isinstance(parent, dict) else getattr(parent, last, None)
    overrides = getattr(root, "limit_overrides", None)
    if current is None and isinstance(overrides, dict) and parent is overrides and array.ndim == 1:
        overrides[last] = array.copy()      # a limit robot.yaml overrode: saved into the URDF, kept as given
        return True
    if isinstance(current, pin.SE3) and array.shape == (4, 4):
        new: object = pin.SE3(array)
    elif isinstance(current, np.ndarray) and current.shape == array.shape:
        new = array.astype(current.dtype)
    elif isinstance(current, float) and array.shape == ():
        new = float(array)
    else:
        return False
    if isinstance(parent, dict):
        parent[last] = new
    else:
        setattr(parent, last, new)
    return True


def load_exact_robot(folder: str | Path) -> RobotModel:
    """The robot saved by :func:`save_exact_robot`, bit for bit (URDF + yaml alone when the
    exact files are absent). Raises :class:`RobotFileError` when they do not fit the URDF."""
    folder = Path(folder)
    robot = RobotModel.load(folder)
    stored, spec_npz = folder / MODEL_TEXT, folder / SPEC_NPZ
    if not stored.exists() or not spec_npz.exists():
        return attach_residual_map(robot, folder)
    model = pin.Model()
    try:
        model.loadFromString(stored.read_bytes().decode("utf-8"))
    except (RuntimeError, UnicodeDecodeError, ValueError) as exc:
        raise RobotFileError(stored, None, f"cannot read the stored model ({' '.join(str(exc).split())})") from None
    if list(model.names) != list(robot.model.names) or [f.name for f in model.frames] != \
            [f.name for f in robot.model.frames]:
        raise RobotFileError(stored, None, "the stored model's joints/frames differ from the URDF beside it")
    spec = robot.spec
    for path, array in read_npz(spec_npz).items():
        if not _set_path(spec, path, array):
            raise RobotFileError(spec_npz, path, "does not match a field of robot.yaml")
    return attach_residual_map(robot.with_model(model, spec), folder)


def robots_equal(a: RobotModel, b: RobotModel) -> bool:
    """Bit-for-bit equality of two robots' models and facts (tests, integrity checks)."""
    if _model_bytes(a.model) != _model_bytes(b.model):
        return False
    fa, fb = dict(_float_fields(a.spec, "")), dict(_float_fields(b.spec, ""))
    ma, mb = (dict(r.residual_map.to_arrays()) if r.residual_map is not None else {} for r in (a, b))
    return (fa.keys() == fb.keys() and all(np.array_equal(fa[k], fb[k]) for k in fa)
            and ma.keys() == mb.keys() and all(np.array_equal(ma[k], mb[k]) for k in ma))
