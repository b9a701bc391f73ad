"""The excitation NLP's per-sample constraints compiled with their Jacobian give the interpreter's
numbers bit for bit, inside a mapped expression graph as IPOPT sees them; without gcc they stay
interpreted."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from pipeline.core import codegen
from pipeline.core import compiled_on_demand as cod
from pipeline.identification import design as D
from pipeline.identification import fourier as F
from pipeline.robot.symbolic import SymbolicRobot


@pytest.fixture(scope="module")
def constraints(rx130l):
    limits = F.ExcitationLimits.from_robot(rx130l, 0.95, 0.95, 0.95, 0.8, 0.05, 0.02)
    inner = limits.tightened(F.NLP_LIMIT_FACTOR, F.NLP_EXTRA_CLEARANCE_M)
    return D.sample_constraint_function(rx130l, SymbolicRobot(rx130l), inner)


def _values_and_jacobian(function: ca.Function, states: np.ndarray) -> tuple[np.ndarray, ca.DM]:
    """The mapped constraints and their Jacobian by CasADi's AD of the mapped call (the colouring
    and seeds IPOPT's constraint Jacobian gets)."""
    S = ca.MX.sym("S", *states.shape)
    h = function.map(states.shape[1])(S)
    both = ca.Function("h_and_jacobian", [S], [h, ca.jacobian(ca.vec(h), ca.vec(S))])
    value, jacobian = both(states)
    return np.asarray(value), jacobian


def test_compiled_constraints_and_jacobian_equal_the_interpreted_ones(rx130l, constraints):
    compiled = cod.compiled_with_jacobian(constraints, 1, subdir=D.CONSTRAINTS_CACHE, after_columns=0)
    assert compiled.class_name() == "External"
    rng = np.random.default_rng(7)
    n = 9
    lo, hi = rx130l.limits.lower_rad, rx130l.limits.upper_rad
    states = np.vstack([rng.uniform(lo, hi, (n, rx130l.nq)).T, rng.normal(0.0, 1.5, (2 * rx130l.nq, n))])
    h_interpreted, jac_interpreted = _values_and_jacobian(constraints, states)
    h_compiled, jac_compiled = _values_and_jacobian(compiled, states)
    np.testing.assert_array_equal(h_compiled, h_interpreted)
    assert jac_compiled.sparsity() == jac_interpreted.sparsity()     # the same structure for IPOPT
    np.testing.assert_array_equal(np.asarray(jac_compiled.nonzeros()), np.asarray(jac_interpreted.nonzeros()))


def test_below_the_break_even_and_without_gcc_the_constraints_stay_interpreted(constraints, tmp_path, monkeypatch,
                                                                             capsys):
    monkeypatch.setenv("PIPELINE_CACHE_DIR", str(tmp_path))
    assert cod.compiled_with_jacobian(constraints, cod.JACOBIAN_COMPILE_AFTER_COLUMNS - 1) is constraints

    def no_gcc(*args: object, **kwargs: object) -> None:
        raise OSError("gcc: not found")

    monkeypatch.setattr(codegen, "build_library", no_gcc)
    monkeypatch.setattr(cod, "_WARNED", [])
    assert cod.compiled_with_jacobian(constraints, cod.JACOBIAN_COMPILE_AFTER_COLUMNS) is constraints
    assert cod.compiled_with_jacobian(constraints, cod.JACOBIAN_COMPILE_AFTER_COLUMNS) is constraints
    assert capsys.readouterr().err.count("stay interpreted") == 1
