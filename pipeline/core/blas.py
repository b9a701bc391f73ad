"""One BLAS thread around the many small (p x p, p ~ 30..60) factorisations of the stages.

On a loaded 2-core machine a threaded 27x27 ``eigh`` cost ~10 ms instead of ~0.1 ms and a
600x58 SVD 34 ms instead of 0.6 ms (measured), and a threaded BLAS changes summation order
from run to run. ``pipeline/__init__.py`` already asks for one thread through the environment
when it is imported before numpy; this context manager (threadpoolctl) enforces it where numpy
was loaded first, e.g. in a notebook.
"""

from __future__ import annotations

from contextlib import AbstractContextManager

from threadpoolctl import threadpool_limits


def single_thread_blas() -> AbstractContextManager:
    """Run the body with one BLAS thread, restoring the previous counts afterwards."""
    return threadpool_limits(limits=1, user_api="blas")
