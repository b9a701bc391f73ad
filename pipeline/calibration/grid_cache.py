"""The filtered candidate grid, computed once per content: in this process and on disk.

:func:`pipeline.calibration.candidates.filter_grid` depends only on the nominal chain (joint
placements, capsules, reflector, nominal tracker pose, limits), the grid size and the margins,
never on the seed, the hidden robot or the gravity model. A run with a second calibration pass
(:mod:`pipeline.run.second_pass`) filters the same 13^6 grid twice, and every run of the same robot
filters it again: the result is kept under a key that is the SHA-256 of those inputs (every array
of the :class:`~pipeline.calibration.candidates.Chain` by dtype, shape and bytes, the grid size, the
margins, the chunk size) and of the source code of the filter (``candidates.py`` and the
segment-distance code of ``pipeline/robot/collision.py``), so a changed robot, setting or filter
computes anew and no path enters the key.

Two levels: a small in-process table (the second pass in the same process), and ``.npz`` files
under the compiled-code cache folder (``$PIPELINE_CACHE_DIR``/grids, :func:`pipeline.core.codegen.cache_root`),
written atomically (``os.replace``). A file that cannot be read, or a folder that cannot be
written, only costs the computation. The result is the same arrays bit for bit; only the counts'
``time_s`` is the time of this call.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import tempfile
import time
import zipfile
from collections import OrderedDict
from pathlib import Path

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.core.codegen import cache_root
from pipeline.core.progress import TaskHandle
from pipeline.robot import collision

#: grids kept in this process (a run uses one; tests may use a few robots)
MEMORY_ENTRIES = 4
_MEMORY: OrderedDict[str, tuple[np.ndarray, np.ndarray, dict]] = OrderedDict()
_COUNT_KEYS = ("total", "prefix_collision_free", "collision", "visibility", "feasible")


def _code_sha256() -> str:
    digest = hashlib.sha256()
    for module in (cd, collision):
        digest.update(Path(module.__file__).read_bytes())
    return digest.hexdigest()


def grid_key(chain: cd.Chain, n_per_axis: int | list[int], margins: cd.FilterMargins, chunk: int) -> str:
    """SHA-256 of everything :func:`cd.filter_grid` reads (without a custom visibility test)."""
    digest = hashlib.sha256(_code_sha256().encode())
    for f in dataclasses.fields(chain):
        value = np.asarray(getattr(chain, f.name))
        digest.update(f"{f.name}:{value.dtype.str}:{value.shape}:".encode())
        digest.update(np.ascontiguousarray(value).tobytes())
    digest.update(repr((np.asarray(n_per_axis).tolist(), dataclasses.astuple(margins), chunk)).encode())
    return digest.hexdigest()


def _read(path: Path) -> tuple[np.ndarray, np.ndarray, dict] | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            counts = {k: int(v) for k, v in zip(_COUNT_KEYS, z["counts"], strict=True)}
            return z["Q"], z["grid_index"], counts
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):   # missing or damaged
        return None


def _write(path: Path, Q: np.ndarray, grid_index: np.ndarray, counts: dict) -> None:
    tmp_name = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=".grid-", suffix=".npz", delete=False) as tmp:
            tmp_name = tmp.name
            np.savez(tmp, Q=Q, grid_index=grid_index, counts=np.array([counts[k] for k in _COUNT_KEYS], np.int64))
        os.replace(tmp_name, path)
    except OSError:
        if tmp_name is not None:
            Path(tmp_name).unlink(missing_ok=True)


def filter_grid(chain: cd.Chain, n_per_axis: int | list[int] = 13, margins: cd.FilterMargins | None = None,
                chunk: int = 20_000, progress: TaskHandle | None = None, cache_dir: Path | None = None
                ) -> tuple[np.ndarray, np.ndarray, dict]:
    """:func:`cd.filter_grid` (laser tracker visibility), reused when computed before for the same
    content (see the module docstring); the arrays returned are the caller's own copies."""
    t0 = time.perf_counter()
    margins = margins or cd.FilterMargins()
    key = grid_key(chain, n_per_axis, margins, chunk)
    path = (cache_dir if cache_dir is not None else cache_root()) / "grids" / f"{key[:32]}.npz"
    found = _MEMORY.get(key) or _read(path)
    if found is None:
        Q, grid_index, counts = cd.filter_grid(chain, n_per_axis, margins, chunk=chunk, progress=progress)
        found = (Q, grid_index, {k: counts[k] for k in _COUNT_KEYS})
        _write(path, *found)
    _MEMORY[key] = found
    _MEMORY.move_to_end(key)
    while len(_MEMORY) > MEMORY_ENTRIES:
        _MEMORY.popitem(last=False)
    Q, grid_index, counts = found
    return Q.copy(), grid_index.copy(), {**counts, "time_s": time.perf_counter() - t0}
