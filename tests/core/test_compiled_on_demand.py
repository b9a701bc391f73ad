"""A CasADi function interpreted until its use pays for gcc, then compiled: same numbers."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin

from pipeline.calibration import error_model as em
from pipeline.core.casadi_buffers import BufferedFunction
from pipeline.core.compiled_on_demand import CompiledOnDemand


def _function(name: str = "toy") -> ca.Function:
    q = ca.SX.sym("q", 3)
    x = ca.SX.sym("x", 2)
    y = ca.vertcat(ca.sin(q[0] * x[0]) * ca.cos(q[1]) + q[2] * x[1], ca.exp(-q[0] ** 2) * x[1] / (1 + q[2] ** 2))
    return ca.Function(name, [q, x], [y, ca.jacobian(y, x)])


def test_interpreted_until_the_threshold_then_compiled(tmp_path, monkeypatch):
    monkeypatch.setenv("PIPELINE_CACHE_DIR", str(tmp_path))
    f = CompiledOnDemand(_function(), after_columns=25)
    Q, x = np.random.default_rng(0).standard_normal((3, 10)), np.array([0.3, -1.2])
    first = f.mapped(10)(Q, x)
    assert f.compiled is None and f.columns_interpreted == 10
    f.mapped(10)(Q, x)
    assert f.compiled is None
    third = f.mapped(10)(Q, x)         # 30 columns >= 25: compiled before this call
    assert f.compiled is not None
    for a, b in zip(first, third, strict=True):
        np.testing.assert_array_equal(a, b)
    # a second instance finds the library in the cache at its first call
    g = CompiledOnDemand(_function(), after_columns=10**9)
    g.mapped(4)(Q[:, :4], x)
    assert g.compiled is not None


def test_instances_of_one_code_count_together_and_an_announced_use_compiles_at_once(tmp_path, monkeypatch):
    monkeypatch.setenv("PIPELINE_CACHE_DIR", str(tmp_path))
    Q, x = np.random.default_rng(2).standard_normal((3, 10)), np.array([-0.7, 0.4])
    a, b = CompiledOnDemand(_function("toy_pooled"), after_columns=25), CompiledOnDemand(_function("toy_pooled"),
                                                                                          after_columns=25)
    first = a.mapped(10)(Q, x)
    b.mapped(10)(Q, x)
    assert a.compiled is None and b.compiled is None and b.columns_interpreted == 10
    a.mapped(10)(Q, x)                 # 30 columns of this code in the process: compiled
    assert a.compiled is not None and a.columns_interpreted == 10
    b.mapped(10)(Q, x)                 # the other instance loads the library built for the first
    assert b.compiled is not None and b.columns_interpreted == 10
    for u, v in zip(first, b.mapped(10)(Q, x), strict=True):
        np.testing.assert_array_equal(u, v)
    # a use announced ahead counts like one evaluated: no column interpreted
    c = CompiledOnDemand(_function("toy_announced"), after_columns=25)
    c.expect(20)
    assert c.compiled is None
    c.expect(5)
    assert c.compiled is not None
    c.mapped(10)(Q, x)
    assert c.columns_interpreted == 0


def test_compiled_measurement_jacobian_equals_the_interpreted_one(rx130l):
    mm = em.MeasurementModel(rx130l)
    rng = np.random.default_rng(1)
    Q = rng.uniform(-2, 2, (40, mm.nq))
    x = 1e-3 * rng.standard_normal(mm.n)
    t0 = em.se3_to_vector(pin.SE3(pin.exp3(rng.standard_normal(3)), rng.standard_normal(3)))
    on_demand = CompiledOnDemand(mm.hj, subdir="measurement_model", after_columns=0)
    compiled = on_demand.mapped(40)(Q.T, x, t0)
    assert on_demand.compiled is not None
    interpreted = BufferedFunction(mm.hj.map(40))(Q.T, x, t0)
    for a, b in zip(interpreted, compiled, strict=True):
        np.testing.assert_array_equal(a, b)
