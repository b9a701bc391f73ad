"""Efficient rounding of the optimal approximate design and the polished start of remove-and-replace."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.calibration import design as ds
from pipeline.calibration import design_bound as db
from pipeline.calibration import design_rounding as dr
from pipeline.calibration import error_model as em
from pipeline.calibration import indices as ix
from pipeline.calibration import stage as st
from pipeline.calibration import task_space as ts
from pipeline.calibration.config import Config
from pipeline.core.errors import ConfigError, InfeasibleError
from pipeline.robot.model import RobotModel


def _problem(seed: int, N: int = 120, m: int = 3, p: int = 8) -> tuple[np.ndarray, ix.IndexSpec]:
    rng = np.random.default_rng(seed)
    G = rng.standard_normal((N, m, p)) * rng.uniform(0.2, 2.0, size=(N, 1, 1))
    Jw = rng.standard_normal((3, p))            # a singular weighting, as the TCP's
    return G, ix.IndexSpec("V", working_jacobian=Jw, n_working=1)


@pytest.mark.parametrize("n", [1, 3, 7, 10, 25])
def test_efficient_rounding_sums_to_n_and_reproduces_an_exact_design(n):
    rng = np.random.default_rng(n)
    w = rng.uniform(0.0, 1.0, 30) * (rng.uniform(size=30) < 0.3)
    w[0] = 0.5
    k = dr.efficient_rounding(w, n)
    assert k.sum() == n and np.all(k >= 0) and np.all(k[w == 0] == 0)
    support = np.flatnonzero(w > dr.SUPPORT_THRESHOLD * w.max())
    if n >= support.size:                       # every support point gets a run
        assert np.all(k[support] >= 1)
    counts = np.zeros(30, int)
    counts[rng.choice(30, size=min(n, 5), replace=False)] = 1
    counts[np.flatnonzero(counts)[0]] += n - counts.sum()
    np.testing.assert_array_equal(dr.efficient_rounding(counts / n, n), counts)


def test_efficient_rounding_refuses_bad_weights():
    with pytest.raises(ValueError):
        dr.efficient_rounding(np.zeros(4), 2)
    with pytest.raises(ValueError):
        dr.efficient_rounding(np.array([0.5, -0.1, 0.6]), 2)


def test_rounded_start_is_n_distinct_heavy_candidates():
    w = np.array([0.05, 0.4, 0.0, 0.3, 0.25])
    s = dr.rounded_start(w, 3)
    assert len(set(s.tolist())) == 3 and set(s.tolist()) == {1, 3, 4}
    s5 = dr.rounded_start(w, 5)                 # more runs than support points: completed, distinct
    assert sorted(s5.tolist()) == [0, 1, 2, 3, 4]


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("n", [4, 9, 16])
def test_polished_design_between_bound_rounded_start_and_plain_exchange(seed, n):
    G, spec = _problem(seed)
    W = spec.weight_matrix(G.shape[2])
    opt = db.optimal_approximate_design(G, W, tol=dr.START_TOL, max_iterations=dr.START_MAX_ITERATIONS)
    start = dr.rounded_start(opt.weights, n)
    r = dr.approximate_remove_and_replace(G, spec, n, np.random.default_rng(seed))
    plain = ds.remove_and_replace(G, spec, n, np.random.default_rng(seed))
    v = db.design_value(G, W, r.selected)
    assert len(set(r.selected.tolist())) == n
    assert v == pytest.approx(r.index_value, rel=1e-8)
    assert v <= plain.index_value * (1 + 1e-9)                      # never worse than plain remove-and-replace
    assert v <= db.design_value(G, W, start) * (1 + 1e-9)          # never worse than its rounded start
    assert v >= opt.exact_bound(n) * (1 - 1e-9)                    # never better than the bound
    only_rounded = dr.approximate_remove_and_replace(G, spec, n, np.random.default_rng(seed), restarts=0)
    assert db.design_value(G, W, only_rounded.selected) <= db.design_value(G, W, start) * (1 + 1e-9)


def test_polished_design_is_deterministic_for_a_seed():
    G, spec = _problem(5)
    a = dr.approximate_remove_and_replace(G, spec, 10, np.random.default_rng(3), restarts=3)
    b = dr.approximate_remove_and_replace(G, spec, 10, np.random.default_rng(3), restarts=3)
    np.testing.assert_array_equal(a.selected, b.selected)


def test_non_trace_index_gets_plain_remove_and_replace():
    G, _ = _problem(6)
    spec = ix.IndexSpec("O3")
    r = dr.approximate_remove_and_replace(G, spec, 10, np.random.default_rng(1))
    plain = ds.remove_and_replace(G, spec, 10, np.random.default_rng(1))
    np.testing.assert_array_equal(np.sort(r.selected), np.sort(plain.selected))
    with pytest.raises(ValueError):
        dr.approximate_remove_and_replace(G, spec, 10, np.random.default_rng(1), restarts=-1)


@pytest.mark.parametrize(("field", "value"), [("design_start", "best"), ("design_restarts", -1),
                                              ("design_restarts", 1.5), ("design_restarts", True)])
def test_bad_design_start_fields_are_config_errors(field, value):
    with pytest.raises(ConfigError, match=f"calibration.{field}"):
        Config(**{field: value}).validate()
    Config().validate()                         # the defaults are valid


def test_design_figures_combine_tcp_and_reflector(tx40_setup):
    mm, basis, Qw = tx40_setup
    p = basis.shape[1]
    specs = {f: ts.task_space_spec(mm, Qw, basis, f) for f in ts.DESIGN_FIGURES}
    W = {f: s.weight_matrix(p) for f, s in specs.items()}
    tol = 1e-12 * max(np.abs(w).max() for w in W.values())
    np.testing.assert_allclose(W["tcp+reflector"], 0.5 * (W["tcp"] + W["reflector"]), rtol=0, atol=tol)
    np.testing.assert_allclose(W["tcp"], ts.task_space_spec(mm, Qw, basis).weight_matrix(p))   # the default: TCP
    # the reflector rows are the study's held-out figure (geometric basis)
    np.testing.assert_allclose(W["reflector"], db.reflector_weight(mm.robot, Qw, basis), rtol=0, atol=1e3 * tol)
    np.testing.assert_allclose(ts.tcp_part(specs["tcp+reflector"], "tcp+reflector").weight_matrix(p), W["tcp"])
    assert ts.tcp_part(specs["reflector"], "reflector") is None
    with pytest.raises(ValueError, match="design figure"):
        ts.task_space_spec(mm, Qw, basis, "flange")
    with pytest.raises(ConfigError, match="calibration.design_figure"):
        Config(design_figure="flange").validate()


@pytest.fixture(scope="session")
def tx40_setup():
    robot = RobotModel.load("staubli_tx40")
    mm = em.MeasurementModel(robot)
    cfg = st.Config(candidates="random", n_random_candidates=200, identifiability_samples=60)
    _, basis = st.identify_parameter_set(robot, mm, cfg, np.random.default_rng(3))
    Qw = ts.sample_region(robot, ts.default_region(robot), 20, np.random.default_rng(4))
    return mm, basis, Qw


def test_side_by_side_runs_give_the_result_of_one_after_the_other(monkeypatch):
    G, spec = _problem(7, N=150)
    monkeypatch.setattr(dr, "SIDE_BY_SIDE_MIN_ENTRIES", 0)
    results = {}
    for jobs in ("1", "2"):
        monkeypatch.setenv("PIPELINE_JOBS", jobs)
        rng = np.random.default_rng(11)
        r = dr.approximate_remove_and_replace(G, spec, 9, rng, restarts=2)
        results[jobs] = (r, rng.bit_generator.state, rng.uniform())
    (a, state_a, next_a), (b, state_b, next_b) = results["1"], results["2"]
    np.testing.assert_array_equal(a.selected, b.selected)
    assert (a.index_value, a.evaluations, a.history) == (b.index_value, b.evaluations, b.history)
    assert state_a == state_b and next_a == next_b     # the caller's generator continues where the runs left it


def test_an_error_of_a_forked_run_is_raised_with_its_field(monkeypatch):
    G, spec = _problem(8, N=150)
    G[:, :, 0] = 0.0                            # one parameter never excited
    monkeypatch.setattr(dr, "SIDE_BY_SIDE_MIN_ENTRIES", 0)
    monkeypatch.setenv("PIPELINE_JOBS", "2")
    with pytest.raises(InfeasibleError, match="calibration.candidates: .*regular"):
        dr.approximate_remove_and_replace(G, spec, 9, np.random.default_rng(0))
