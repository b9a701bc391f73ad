"""The excitation's base set shrunk to what the geometry can excite (:mod:`pipeline.identification.base_set`):
the columns over a condition-number bound leave the set, each replaced by its least-squares combination
of the kept ones, so the base regressor of the rest reproduces every torque on the same samples."""

from __future__ import annotations

import numpy as np

from pipeline.identification.base_set import columns_over_condition, without_columns
from pipeline.identification.regressor import base_parameters_from_regressor


def _regressor(rng: np.random.Generator) -> np.ndarray:
    """8 standard columns: 0-4 independent, 5 = 2 x column 1 (structural), 6 nearly column 0 + column 3
    (1e-7 off: excitable in theory, not in practice), 7 independent."""
    Y = rng.normal(size=(400, 8))
    Y[:, 5] = 2.0 * Y[:, 1]
    Y[:, 6] = Y[:, 0] + Y[:, 3] + 1e-7 * rng.normal(size=400)
    return Y


def test_columns_over_the_bound_are_left_out_and_the_torques_still_fit():
    rng = np.random.default_rng(3)
    Y = _regressor(rng)
    base = base_parameters_from_regressor(Y, [f"p{i}" for i in range(8)], 1e-12)
    assert base.n_base == 7                                  # column 5 is structural
    Wb = base.base_regressor(Y)
    assert np.linalg.cond(Wb) > 1e6
    drop = columns_over_condition(Wb, 1e4)
    assert len(drop) == 1
    shrunk = without_columns(base, drop, Y)
    assert shrunk.n_base == 6
    assert np.linalg.cond(shrunk.base_regressor(Y)) <= 1e4
    p = rng.normal(size=8)
    # the rest's base regressor reproduces the torques of any parameters on these samples
    assert np.allclose(shrunk.base_regressor(Y) @ shrunk.from_standard(p), Y @ p, atol=1e-5)
    assert set(shrunk.dependent) == {*base.dependent, *base.independent[drop]}


def test_nothing_left_out_under_the_bound():
    rng = np.random.default_rng(4)
    Y = rng.normal(size=(200, 5))
    assert len(columns_over_condition(Y, 1e3)) == 0
    base = base_parameters_from_regressor(Y, list("abcde"), 1e-9)
    assert without_columns(base, np.zeros(0, int), Y) is base
