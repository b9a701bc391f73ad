"""One OpenBLAS thread for the many small factorisations of this stage.

On the loaded 2-core machine a threaded 58x58 ``eigh`` took 9 ms instead of 0.3 ms and a
600x58 SVD 34 ms instead of 0.6 ms (measured). The context manager of the calibration stage
(``pipeline.calibration._blas``) does the work; without it this is a no-op.
"""

from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext


def single_thread_blas() -> AbstractContextManager:
    try:
        from pipeline.calibration._blas import single_thread_blas as _single
    except ImportError:  # pragma: no cover - the calibration helper moved or is absent
        return nullcontext()
    return _single()
