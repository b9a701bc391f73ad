"""A CasADi function evaluated straight into numpy arrays (no ``DM`` in between).

Calling a ``casadi.Function`` from Python returns ``DM`` objects, and ``np.asarray(DM)`` copies them
element by element through a Python list: for the batched measurement Jacobians of the calibration
(3 x 4000 entries per call, thousands of calls in a cross-validation) that copy costs about a
quarter of the evaluation. :class:`BufferedFunction` uses CasADi's buffer interface
(``Function.buffer``): the inputs are read from, and the outputs written to, numpy arrays in
column-major order, by the same evaluation code, so the numbers are identical to a plain call.

Inputs given with one column where the function takes ``n`` columns are repeated (the broadcast a
plain call of a mapped function applies). Sparse outputs are densified (structural zeros written as
zeros); a function with a sparse input is evaluated by the plain call.
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np
import numpy.typing as npt


class BufferedFunction:
    """``f(*args) -> list of (rows, cols) arrays`` for a dense ``casadi.Function`` ``f``."""

    def __init__(self, function: ca.Function) -> None:
        if not all(function.sparsity_out(i).is_dense() for i in range(function.n_out())):
            symbols = [ca.MX.sym(function.name_in(i), function.sparsity_in(i)) for i in range(function.n_in())]
            function = ca.Function(function.name(), symbols, [ca.densify(o) for o in function.call(symbols)],
                                   function.name_in(), function.name_out())
        self.function = function
        self.in_shapes = [(function.size1_in(i), function.size2_in(i)) for i in range(function.n_in())]
        self.out_shapes = [(function.size1_out(i), function.size2_out(i)) for i in range(function.n_out())]
        self.dense = (all(function.sparsity_in(i).is_dense() for i in range(function.n_in()))
                      and all(function.sparsity_out(i).is_dense() for i in range(function.n_out())))
        if self.dense:
            self._buffer, self._evaluate = function.buffer()

    def __call__(self, *args: npt.ArrayLike) -> list[np.ndarray]:
        if not self.dense:
            outs: Sequence[ca.DM] = self.function.call([ca.DM(np.asarray(a, float)) for a in args])
            return [np.asarray(o, float) for o in outs]
        inputs = [self._column_major(i, a) for i, a in enumerate(args)]
        # casadi's stubs name a third argument (the size in bytes) that its SWIG typemap takes from the buffer
        for i, a in enumerate(inputs):
            self._buffer.set_arg(i, memoryview(a))  # type: ignore[call-arg, arg-type]
        outputs = [np.empty(r * c) for r, c in self.out_shapes]
        for i, o in enumerate(outputs):
            self._buffer.set_res(i, memoryview(o))  # type: ignore[call-arg, arg-type]
        self._evaluate()
        return [o.reshape((c, r)).T for o, (r, c) in zip(outputs, self.out_shapes, strict=True)]

    def _column_major(self, i: int, value: npt.ArrayLike) -> np.ndarray:
        rows, cols = self.in_shapes[i]
        a = np.asarray(value, float)
        if a.ndim < 2:
            a = a.reshape(rows, -1) if a.size else a.reshape(rows, 0)
        if a.shape == (rows, 1) and cols != 1:
            a = np.repeat(a, cols, axis=1)
        if a.shape != (rows, cols):
            raise ValueError(f"{self.function.name()}: input {i} has shape {a.shape}, expected {(rows, cols)}")
        return np.ascontiguousarray(a.T).ravel()
