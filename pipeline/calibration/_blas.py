"""Limit OpenBLAS threads during the many small (p x p, p ~ 30) factorisations of the designs.

On a loaded 2-core machine a threaded 27x27 ``eigh`` costs ~10 ms instead of ~0.1 ms
(measured). ``threadpoolctl`` is not a dependency, so the bundled OpenBLAS libraries of numpy and
scipy are found in ``/proc/self/maps`` and driven through their ``*_set_num_threads`` symbols
(ctypes). Where that is impossible the context manager does nothing.
"""

from __future__ import annotations

import ctypes
from collections.abc import Iterator
from contextlib import contextmanager

_SET = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads", "openblas_set_num_threads")
_GET = ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads", "openblas_get_num_threads")


def _libraries() -> list[tuple[ctypes._CFuncPtr, ctypes._CFuncPtr]]:
    out = []
    try:
        paths = sorted({line.split()[-1] for line in open("/proc/self/maps")
                        if "openblas" in line.lower() and line.split()[-1].startswith("/")})
    except OSError:
        return out
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        setter = getter = None
        for s, g in zip(_SET, _GET, strict=True):
            if hasattr(lib, s) and hasattr(lib, g):
                setter, getter = getattr(lib, s), getattr(lib, g)
                break
        if setter is not None:
            out.append((setter, getter))
    return out


@contextmanager
def single_thread_blas() -> Iterator[None]:
    """Run the body with one OpenBLAS thread, restoring the previous counts afterwards."""
    libs = _libraries()
    before = []
    for setter, getter in libs:
        try:
            before.append(int(getter()))
            setter(1)
        except Exception:  # noqa: BLE001 - best effort
            before.append(None)
    try:
        yield
    finally:
        for (setter, _), n in zip(libs, before, strict=True):
            if n is not None:
                setter(n)
