"""Compiled CasADi code: several functions compiled side by side into one library."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from pipeline.core import codegen


def _functions() -> list[ca.Function]:
    x = ca.SX.sym("x", 3)
    return [ca.Function("side_a", [x], [ca.sin(x) * 2.0]),
            ca.Function("side_b", [x], [ca.dot(x, x)]),
            ca.Function("side_c", [x], [ca.jacobian(ca.exp(x) * x[0], x)])]


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_functions_compiled_side_by_side_evaluate_like_casadi(tmp_path, monkeypatch, jobs):
    monkeypatch.setenv("PIPELINE_JOBS", jobs)
    library = codegen.build_library("side", _functions(), cache_dir=tmp_path)
    x = np.array([0.3, -1.2, 2.0])
    for f in _functions():
        compiled = ca.external(f.name(), str(library))
        np.testing.assert_allclose(np.asarray(compiled(x)), np.asarray(f(x)), rtol=1e-14, atol=0)


def test_library_key_does_not_depend_on_the_cores(tmp_path, monkeypatch):
    monkeypatch.setenv("PIPELINE_JOBS", "2")
    first = codegen.build_library("side", _functions(), cache_dir=tmp_path)
    stamp = first.stat().st_mtime_ns
    monkeypatch.setenv("PIPELINE_JOBS", "1")
    again = codegen.build_library("side", _functions(), cache_dir=tmp_path)
    assert again == first and again.stat().st_mtime_ns == stamp     # found in the cache, not rebuilt


def test_gcc_failure_names_the_library(tmp_path, monkeypatch):
    monkeypatch.setenv("PIPELINE_JOBS", "2")
    with pytest.raises(codegen.SolverError, match="gcc failed"):
        codegen.build_library("side", _functions(), cache_dir=tmp_path, flags=("-fno-such-flag-anywhere",))
    assert not list(tmp_path.rglob("*.so"))
