"""Fourier excitation: rest-to-rest, derivatives, exact criterion gradient, constraints."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.solver_status import SUCCESS_STATUSES
from pipeline.identification import design as D
from pipeline.identification import fourier as F
from pipeline.identification.regressor import RegressorModel, base_parameters
from pipeline.robot.symbolic import SymbolicRobot


@pytest.fixture(scope="module")
def setup(rx130l):
    act = rx130l.actuation
    reg = RegressorModel(rx130l.model, act.gear_matrix, act.coulomb_smoothing_rad_s)
    base = base_parameters(reg, np.random.default_rng(0), lower=rx130l.limits.lower_rad,
                           upper=rx130l.limits.upper_rad)
    limits = F.ExcitationLimits.from_robot(rx130l, 0.95, 0.95, 0.95, 0.8, 0.05, 0.02)
    sym = SymbolicRobot(rx130l)
    return reg, base, limits, sym


def test_fourier_derivatives_and_rest(rx130l, setup):
    _, _, limits, _ = setup
    traj = F.random_trajectory(rx130l, limits, 5, 0.1, np.random.default_rng(1))
    h = 1e-4
    t = np.linspace(0.3, 9.7, 17)
    q, v, a = traj.evaluate(t)
    qp, vp, _ = traj.evaluate(t + h)
    qm, vm, _ = traj.evaluate(t - h)
    np.testing.assert_allclose((qp - qm) / (2 * h), v, atol=1e-6)
    np.testing.assert_allclose((vp - vm) / (2 * h), a, atol=1e-5)
    q0, v0, a0 = traj.evaluate(np.array([0.0, traj.period_s]))
    np.testing.assert_allclose(v0, 0.0, atol=1e-12)
    np.testing.assert_allclose(a0, 0.0, atol=1e-12)
    np.testing.assert_allclose(q0[0], q0[1], atol=1e-12)  # periodic


@pytest.mark.parametrize("friction", ["nominal", "stribeck_and_load"])
def test_nominal_torques_are_inverse_dynamics_number_for_number(rx130l, setup, friction):
    """The feasibility checks' torques of whole trajectories equal ``inverse_dynamics`` sample by sample
    exactly (the random baseline and the fine-grid check decide on them), also with an identified
    Stribeck term and load-dependent Coulomb friction."""
    robot = rx130l.copy()
    if friction == "stribeck_and_load":
        act = robot.spec.actuation
        act.static_friction_excess_Nm = 0.3 * np.asarray(act.coulomb_Nm, float)
        act.stribeck_velocity_rad_s = np.full(robot.nq, 0.05)
        act.coulomb_load_coefficient = np.linspace(0.0, 0.02, robot.nq)
    traj = F.random_trajectory(robot, setup[2], 5, 0.1, np.random.default_rng(3))
    q, v, a = traj.evaluate(traj.sample_times(200))
    expected = np.array([robot.inverse_dynamics(*s) for s in zip(q, v, a, strict=True)])
    assert np.array_equal(F.nominal_torques(robot, q, v, a), expected)
    assert friction == "nominal" or not np.array_equal(expected, F.nominal_torques(rx130l, q, v, a))


@pytest.mark.parametrize("criterion,softness", [("cond", 0.0), ("cond", 0.2), ("logdet", 0.0)])
def test_criterion_gradient_is_exact(rx130l, setup, criterion, softness):
    reg, base, limits, sym = setup
    traj = F.random_trajectory(rx130l, limits, 5, 0.1, np.random.default_rng(2))
    basis = F.fourier_basis(np.arange(50) * 0.2, 0.1, 5)
    crit = D.ExcitationCriterion(D.regressor_casadi(sym, reg, base), basis, rx130l.nq, criterion, softness)
    x = traj.coefficients.ravel()
    W = crit.matrix(x)
    np.testing.assert_allclose(W, base.base_regressor(reg.stacked(*traj.evaluate(np.arange(50) * 0.2))),
                               atol=1e-9)
    f, g = crit.value_and_gradient(x)
    if criterion == "cond" and softness == 0:
        assert np.exp(0.5 * f) == pytest.approx(D.condition_number(W), rel=1e-8)
    if criterion == "cond" and softness > 0:  # the surrogate bounds log cond^2 from above
        log_c2 = 2 * np.log(D.condition_number(W))
        assert log_c2 <= f <= log_c2 + 2 * softness * np.log(W.shape[1]) + 1e-9
    rng = np.random.default_rng(3)
    for _ in range(3):
        d = rng.normal(size=x.size) * 1e-6
        fp, _ = crit.value_and_gradient(x + d, gradient=False)
        fm, _ = crit.value_and_gradient(x - d, gradient=False)
        assert (fp - fm) / 2 == pytest.approx(g @ d, rel=1e-4, abs=1e-12)


@pytest.mark.parametrize("rows", [[0], [1, 4]])
def test_criterion_scores_only_the_joints_the_fit_uses(rx130l, setup, rows):
    """With a subset of joints identified, the design's matrix is the fit's base regressor: the
    torque rows of those joints only (same rows, same columns, same condition number)."""
    _, _, limits, sym = setup
    act = rx130l.actuation
    reg = RegressorModel(rx130l.model, act.gear_matrix, act.coulomb_smoothing_rad_s, np.asarray(rows))
    base = base_parameters(reg, np.random.default_rng(0), lower=rx130l.limits.lower_rad,
                           upper=rx130l.limits.upper_rad)
    traj = F.random_trajectory(rx130l, limits, 5, 0.1, np.random.default_rng(2))
    t = np.arange(80) / 8.0  # one period, more rows than base parameters for a single joint
    crit = D.ExcitationCriterion(D.regressor_casadi(sym, reg, base), basis=F.fourier_basis(t, 0.1, 5),
                                 nq=rx130l.nq)
    x = traj.coefficients.ravel()
    W_fit = base.base_regressor(reg.stacked(*traj.evaluate(t)))
    W = crit.matrix(x)
    assert W.shape == W_fit.shape == (len(rows) * len(t), base.n_base)
    np.testing.assert_allclose(W, W_fit, atol=1e-9)
    f, g = crit.value_and_gradient(x)
    assert np.exp(0.5 * f) == pytest.approx(D.condition_number(W_fit), rel=1e-8)
    d = np.random.default_rng(3).normal(size=x.size) * 1e-5
    fp, _ = crit.value_and_gradient(x + d, gradient=False)
    fm, _ = crit.value_and_gradient(x - d, gradient=False)
    # G = W^T W squares one joint's cond (~1e4): the difference quotient carries ~1e-4 round-off
    assert (fp - fm) / 2 == pytest.approx(g @ d, rel=2e-3)


def test_optimised_excitation_is_feasible_and_better_than_random(rx130l, setup):
    reg, base, limits, sym = setup
    res = D.optimize_excitation(rx130l, sym, reg, base, limits, np.random.default_rng(5), n_samples=50,
                                n_starts=1, n_random=8, max_iter=25)
    assert res.feasibility.feasible
    report = F.check_trajectory(rx130l, res.trajectory, limits, 800)
    assert report.feasible  # also on a finer grid than the one of the check
    assert res.cond_optimized < res.cond_starts[0] < np.inf
    assert res.cond_optimized < res.cond_random_median
    assert len(res.cond_random) == 8 and res.cond_history[0]


def test_check_trajectory_flags_a_limit_violation(rx130l, setup):
    _, _, limits, _ = setup
    traj = F.random_trajectory(rx130l, limits, 5, 0.1, np.random.default_rng(6))
    coef = traj.coefficients.copy()
    coef[:, 1:] *= 5.0
    bad = F.FourierTrajectory(coef, traj.base_frequency_hz)
    report = F.check_trajectory(rx130l, bad, limits)
    assert not report.feasible
    assert max(report.position_ratio, report.velocity_ratio, report.acceleration_ratio, report.torque_ratio) > 1


def test_logdet_option_runs_and_improves_the_determinant(rx130l, setup):
    reg, base, limits, sym = setup
    res = D.optimize_excitation(rx130l, sym, reg, base, limits, np.random.default_rng(7), n_samples=40,
                                n_starts=1, n_random=3, max_iter=10, criterion="logdet")
    assert res.criterion == "logdet" and res.feasibility.feasible
    basis = F.fourier_basis(np.arange(40) * 0.25, 0.1, 5)
    crit = D.ExcitationCriterion(D.regressor_casadi(sym, reg, base), basis, rx130l.nq, "logdet")
    start = [t for t in F.random_feasible_trajectories(rx130l, limits, 5, 0.1, 3, np.random.default_rng(7))]
    f_best_start = min(crit.value_and_gradient(t.coefficients.ravel(), False)[0] for t in start)
    f_opt, _ = crit.value_and_gradient(res.trajectory.coefficients.ravel(), False)
    assert f_opt <= f_best_start + 1e-12          # never worse than the best random start
    if res.source == "optimised":
        assert f_opt < f_best_start
    else:  # 10 iterations: IPOPT did not converge, the best random start is used and said so
        assert res.fallback_reason and res.start_results[0]["status"] not in SUCCESS_STATUSES


def test_diverged_excitation_falls_back_to_the_best_random(rx130l, setup):
    """IPOPT stopped before convergence (max_iter=1): never stored as "optimised"."""
    reg, base, limits, sym = setup
    res = D.optimize_excitation(rx130l, sym, reg, base, limits, np.random.default_rng(11), n_samples=40,
                                n_starts=2, n_random=4, max_iter=1)
    assert res.source == "best random" and "Maximum_Iterations_Exceeded" in res.fallback_reason
    assert res.cond_optimized == pytest.approx(min(res.cond_random))
    assert res.feasibility.feasible


def test_the_best_random_fallback_passes_the_fine_grid_check(rx130l, setup):
    """The random starts pass a grid of n_check // 2 samples; the fallback is scaled into the limits
    on the grid of n_check, where all four of these randoms peak over a limit between samples."""
    reg, base, limits, sym = setup
    randoms = F.random_feasible_trajectories(rx130l, limits, 5, 0.1, 4, np.random.default_rng(12), n_check=4)
    assert not any(F.check_trajectory(rx130l, r, limits, 8).feasible for r in randoms)
    res = D.optimize_excitation(rx130l, sym, reg, base, limits, np.random.default_rng(12), n_samples=40,
                                n_starts=2, n_random=4, max_iter=1, n_check=8)
    assert res.source == "best random"
    assert res.feasibility.feasible and F.check_trajectory(rx130l, res.trajectory, limits, 8).feasible


def test_optimum_worse_than_random_is_not_used(rx130l, setup, monkeypatch):
    """A (forced) converged optimum worse than the best random start: the best random is used."""
    reg, base, limits, sym = setup
    worst: dict = {}
    shrink = D.shrink_to_feasible

    def bad_shrink(robot, traj, lim, n_check):
        randoms = F.random_feasible_trajectories(rx130l, limits, 5, 0.1, 4, np.random.default_rng(12),
                                                 n_check=n_check // 2)
        if any(np.array_equal(traj.coefficients, r.coefficients) for r in randoms):
            return shrink(robot, traj, lim, n_check)       # the fallback's own fine-grid check
        crit_c = [D.condition_number(D.ExcitationCriterion(D.regressor_casadi(sym, reg, base),
                                                           F.fourier_basis(np.arange(40) * 0.25, 0.1, 5),
                                                           rx130l.nq).matrix(t.coefficients.ravel()))
                  for t in randoms]
        worst["traj"] = randoms[int(np.argmax(crit_c))]
        return worst["traj"], F.check_trajectory(rx130l, worst["traj"], lim, n_check)

    monkeypatch.setattr(D, "shrink_to_feasible", bad_shrink)
    monkeypatch.setattr(D, "is_success", lambda status: True)
    res = D.optimize_excitation(rx130l, sym, reg, base, limits, np.random.default_rng(12), n_samples=40,
                                n_starts=1, n_random=4, max_iter=1)
    assert res.source == "best random" and "not better" in res.fallback_reason
    assert res.cond_optimized == pytest.approx(min(res.cond_random))
