"""Atomic artefact files and the hashes of files and trees.

* Every file is written to a temporary file in the same directory, flushed, ``fsync``-ed and
  moved into place with ``os.replace`` (atomic on POSIX): a reader never sees half a file.
* :func:`stable_json`, :func:`hash_files` and :func:`hash_tree` give content hashes that do not
  depend on dict order or file listing order.

Stage directories (layout, staging and commit, the inputs hash) are in :mod:`pipeline.run.stage_io`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import math
import os
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure


# --------------------------------------------------------------------------------------------
# Atomic files
# --------------------------------------------------------------------------------------------
def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


UMASK = _current_umask()


def fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "wb") -> Iterator[Any]:
    """Open a temporary file next to ``path``; on success fsync and ``os.replace`` it into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        kwargs = {"encoding": "utf-8", "newline": "\n"} if "b" not in mode else {}
        os.chmod(tmp, 0o666 & ~UMASK)          # mkstemp makes 0600; use the usual permissions
        with os.fdopen(fd, mode, **kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    fsync_dir(path.parent)


def write_bytes(path: str | Path, data: bytes) -> Path:
    with atomic_open(path, "wb") as fh:
        fh.write(data)
    return Path(path)


def write_text(path: str | Path, text: str) -> Path:
    with atomic_open(path, "w") as fh:
        fh.write(text)
    return Path(path)


#: what :func:`json.dumps` writes: None, bool, number, str, and lists and str-keyed dicts of them
JsonValue = None | bool | int | float | str | list["JsonValue"] | dict[str, "JsonValue"]


def to_jsonable(value: object) -> JsonValue:
    """numpy arrays/scalars, tuples, Paths, dataclasses -> JSON types. NaN/inf -> None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON-able: {type(value).__name__}")


def write_json(path: str | Path, obj: object) -> Path:
    """Atomic JSON (indented, keys in insertion order); numpy values converted."""
    text = json.dumps(to_jsonable(obj), indent=2, allow_nan=False) + "\n"
    return write_text(path, text)


def read_json(path: str | Path) -> Any:
    return json.loads(Path(path).read_text(encoding="utf-8"))


def write_npz(path: str | Path, arrays: Mapping[str, Any]) -> Path:
    """Atomic compressed ``.npz``; object arrays are refused (they would need pickle)."""
    clean: dict[str, np.ndarray] = {}
    for key, value in arrays.items():
        arr = np.asarray(value)
        if arr.dtype == object:
            raise TypeError(f"array {key!r} has dtype object; only numeric/bool/str arrays can be saved")
        clean[str(key)] = arr
    buf = io.BytesIO()
    np.savez_compressed(buf, **clean)
    return write_bytes(path, buf.getvalue())


def read_npz(path: str | Path) -> dict[str, np.ndarray]:
    with np.load(Path(path), allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


def figure_png(fig: Figure, dpi: int = 120) -> bytes:
    """The PNG file of a matplotlib figure, as bytes (tight bounding box)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()


def save_figure(path: str | Path, fig: Figure, dpi: int = 120, close: bool = True,
                png: bytes | None = None) -> Path:
    """Atomic PNG of a matplotlib figure (closed afterwards unless ``close=False``); ``png``: the
    figure already rendered (:func:`figure_png`, e.g. by a worker process)."""
    data = figure_png(fig, dpi) if png is None else png
    if close:
        plt.close(fig)
    return write_bytes(path, data)


# --------------------------------------------------------------------------------------------
# Hashing
# --------------------------------------------------------------------------------------------
def stable_json(obj: object) -> str:
    """Canonical JSON (sorted keys, no spaces) used for hashing."""
    return json.dumps(to_jsonable(obj), sort_keys=True, separators=(",", ":"), allow_nan=False)


def hash_files(paths: list[Path], root: Path | None = None) -> str:
    """sha256 over (relative name, content) of the given files, in sorted order."""
    h = hashlib.sha256()
    for p in sorted(paths):
        name = str(p.relative_to(root)) if root is not None else p.name
        h.update(name.encode())
        h.update(b"\0")
        h.update(p.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def hash_tree(folder: str | Path, suffixes: tuple[str, ...] | None = None) -> str:
    """sha256 of every file under ``folder`` (skipping caches and hidden files)."""
    folder = Path(folder)
    files = [
        p for p in folder.rglob("*")
        if p.is_file()
        and "__pycache__" not in p.parts
        and not any(part.startswith(".") for part in p.relative_to(folder).parts)
        and (suffixes is None or p.suffix in suffixes)
    ]
    return hash_files(files, folder)
