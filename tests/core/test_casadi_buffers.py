"""The buffered evaluation of a CasADi function gives the plain call's numbers exactly."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from pipeline.core.casadi_buffers import BufferedFunction


def _function() -> ca.Function:
    q = ca.SX.sym("q", 3)
    x = ca.SX.sym("x", 4)
    y = ca.vertcat(ca.sin(q[0]) * x[0] + x[1] * q[1] ** 2, ca.cos(q[2] + x[2]) * x[3])
    return ca.Function("f", [q, x], [y, ca.jacobian(y, x)])


def test_mapped_outputs_equal_the_plain_call_bit_for_bit():
    mapped = _function().map(7)
    rng = np.random.default_rng(0)
    Q, x = rng.normal(size=(3, 7)), rng.normal(size=4)
    y_plain, j_plain = (np.asarray(o) for o in mapped(Q, x))       # x broadcast over the 7 columns
    buffered = BufferedFunction(mapped)
    assert buffered.dense                                           # the buffer path, not the plain call
    y, j = buffered(Q, x)
    assert y.shape == (2, 7) and j.shape == (2, 28)
    assert np.array_equal(y, y_plain) and np.array_equal(j, j_plain)
    # a second call of the same object reuses its buffers, follows the new inputs, and leaves the
    # first call's outputs untouched
    y_kept = y.copy()
    y2, _ = buffered(2 * Q, x)
    assert np.array_equal(y2, np.asarray(mapped(2 * Q, x)[0])) and not np.array_equal(y2, y)
    assert np.array_equal(y, y_kept)


def test_a_wrong_input_shape_is_refused():
    with pytest.raises(ValueError, match="input 0 has shape"):
        BufferedFunction(_function().map(7))(np.zeros((3, 5)), np.zeros(4))
