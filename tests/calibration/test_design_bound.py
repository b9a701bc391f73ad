"""Lower bound on the V criterion of any design (optimal approximate design) and the per-seed spread."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.calibration import design as ds
from pipeline.calibration import design_bound as db
from pipeline.calibration import error_model as em
from pipeline.calibration import indices as ix
from pipeline.calibration import stage as st
from pipeline.calibration import task_space as ts
from pipeline.robot.model import RobotModel


def _random_problem(seed: int, N: int = 80, m: int = 3, p: int = 6) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    G = rng.standard_normal((N, m, p)) * rng.uniform(0.2, 2.0, size=(N, 1, 1))
    L = rng.standard_normal((p, 3))
    return G, L @ L.T            # a singular weighting, as the TCP's (tracker parameters: zero rows)


def test_separable_design_has_the_closed_form_optimum():
    # one candidate per parameter, G_k = e_k^T: M(w) = diag(w), V = sum c_k / w_k, minimised by
    # w_k ~ sqrt(c_k) with V* = (sum sqrt(c_k))^2
    c = np.array([1.0, 4.0, 9.0, 0.25])
    G = np.eye(4)[:, None, :]
    opt = db.optimal_approximate_design(G, np.diag(c), tol=1e-8)
    assert opt.converged
    assert opt.value == pytest.approx(np.sum(np.sqrt(c)) ** 2, rel=1e-6)
    assert opt.lower_bound <= opt.value * (1 + 1e-12)
    np.testing.assert_allclose(opt.weights, np.sqrt(c) / np.sum(np.sqrt(c)), rtol=1e-4)


@pytest.mark.parametrize("seed", [0, 1])
def test_bound_is_below_every_exact_design_and_certified(seed):
    G, W = _random_problem(seed)
    opt = db.optimal_approximate_design(G, W, tol=1e-4)
    assert opt.converged and opt.gap <= 1e-4
    assert opt.lower_bound <= opt.value <= opt.lower_bound * (1 + 1e-4) + 1e-15
    uniform = db.criterion(W, db.information(G, np.full(len(G), 1.0 / len(G))))
    assert opt.value <= uniform
    rng = np.random.default_rng(seed + 10)
    n = 8
    for _ in range(200):
        S = rng.choice(len(G), size=n, replace=False)
        assert db.design_value(G, W, S) >= opt.exact_bound(n) * (1 - 1e-12)
    # the exchange algorithm on the same criterion cannot beat the bound either
    Lw = np.linalg.cholesky(W + 1e-12 * np.eye(W.shape[0]))
    spec = ix.IndexSpec("V", working_jacobian=Lw.T, n_working=1)
    r = ds.remove_and_replace(G, spec, n, rng)
    assert db.design_value(G, W, r.selected) >= opt.exact_bound(n) * (1 - 1e-9)


def test_bound_from_an_unconverged_iterate_is_still_valid():
    G, W = _random_problem(2)
    rough = db.optimal_approximate_design(G, W, tol=1e-9, max_iterations=3)
    fine = db.optimal_approximate_design(G, W, tol=1e-6)
    assert not rough.converged
    assert rough.lower_bound <= fine.value * (1 + 1e-12)
    assert fine.value <= rough.value


def test_singular_pool_is_refused():
    G = np.zeros((10, 3, 4))
    G[:, :, :3] = np.random.default_rng(0).standard_normal((10, 3, 3))
    with pytest.raises(ValueError, match="regular"):
        db.optimal_approximate_design(G, np.eye(4))


def test_configurations_to_reach_is_the_fewest():
    G, W = _random_problem(3)
    opt = db.optimal_approximate_design(G, W, tol=1e-4)
    target = opt.lower_bound / 13.4
    k = db.configurations_to_reach(opt, target)
    assert opt.exact_bound(k) <= target < opt.exact_bound(k - 1)


def test_rms_samples_have_the_predicted_mean_square_and_compare_fairly():
    G, W = _random_problem(4)
    C = np.linalg.inv(db.exact_information(G, np.arange(12)))
    rng = np.random.default_rng(5)
    a = db.rms_samples(C, W, 100_000, rng)
    b = db.rms_samples(C, W, 100_000, rng)
    assert np.mean(a ** 2) == pytest.approx(np.trace(W @ C), rel=0.02)
    assert db.probability_below(a, b, 1.0) == pytest.approx(0.5, abs=0.01)      # same design: a coin flip
    assert db.probability_below(0.5 * a, b, 0.85) > db.probability_below(a, b, 0.85)
    c = db.rms_scale_needed(a, b, 0.85, 10, p_all=0.5)
    p1 = db.probability_below(c * a, b, 0.85)
    assert p1 ** 10 == pytest.approx(0.5, abs=0.02)


@pytest.fixture(scope="session")
def tx40_pool():
    robot = RobotModel.load("staubli_tx40")
    mm = em.MeasurementModel(robot)
    rng = np.random.default_rng(11)
    cfg = st.Config(candidates="random", n_random_candidates=300, identifiability_samples=60)
    _, basis = st.identify_parameter_set(robot, mm, cfg, rng)
    cs = st.build_candidates(robot, cfg, basis, rng)
    Qw = ts.sample_region(robot, ts.default_region(robot), 40, rng)
    return robot, mm, basis, cs, Qw


def test_reflector_weight_is_the_studys_predicted_figure(tx40_pool):
    robot, mm, basis, cs, Qw = tx40_pool
    W = db.reflector_weight(robot, Qw, basis)
    C = np.linalg.inv(db.exact_information(cs.G, np.arange(30)))
    _, J = mm.jacobian(Qw, np.zeros(mm.n), robot.tracker.transform_tracker_to_base, basis)
    study = np.mean(np.einsum("nip,pq,niq->n", J, C, J))          # calib_design.evaluate_seed's prediction
    assert np.trace(W @ C) == pytest.approx(study, rel=1e-6)
    with pytest.raises(ValueError, match="geometric"):
        db.reflector_weight(robot, Qw, np.vstack([basis, np.zeros((robot.nq, basis.shape[1]))]))


def test_no_design_of_a_robot_pool_beats_the_bound(tx40_pool):
    robot, mm, basis, cs, Qw = tx40_pool
    spec = ts.task_space_spec(mm, Qw, basis)
    W = spec.weight_matrix(basis.shape[1])
    opt = db.optimal_approximate_design(cs.G, W, tol=1e-3)
    n = 20
    rng = np.random.default_rng(0)
    for sel in (ds.remove_and_replace(cs.G, spec, n, rng).selected, ds.linear_scan_design(cs.G, spec, n).selected,
                ds.random_design(cs.G, spec, n, rng).selected):
        v = db.design_value(cs.G, W, sel)
        assert v == pytest.approx(ix.evaluate(spec, db.exact_information(cs.G, sel), n), rel=1e-9)
        assert v >= opt.exact_bound(n) and math.isfinite(v)
