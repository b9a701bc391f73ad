"""Commissioning toolkit for a 6-axis industrial arm.

Four stages share one robot model: geometric calibration, dynamic identification,
model-based feedforward control and time/energy-optimal trajectories.
"""

import os as _os

# One BLAS/OpenMP thread unless the user says otherwise: the same config then gives the same
# numbers (a threaded BLAS changes summation order, and IPOPT's path on the non-convex PtP NLP
# with it), and the many small factorisations here run faster single-threaded. Effective when
# numpy is imported after this package (the CLI, the tests); set the variables yourself otherwise.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_name, "1")

__version__ = "0.1.0"
