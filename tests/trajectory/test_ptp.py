"""Point to point: one compiled problem shared by all tests (session fixture)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from ruckig import Ruckig, Trajectory

from pipeline.core.errors import InfeasibleError, PipelineError, SolverError
from pipeline.trajectory import solve as solve_mod
from pipeline.trajectory.baselines import _ruckig_input, _states_at, ruckig_torque_feasible
from pipeline.trajectory.pareto import dominated_flags, settle_pareto
from pipeline.trajectory.ptp import PtpResult, energy_weights
from pipeline.trajectory.report import pareto_figure
from pipeline.trajectory.solve import plan_ptp
from pipeline.trajectory.trajectories import check_trajectory


@pytest.fixture
def plan(big_move_plan):
    # the session's plan of the big move (conftest): Pareto k2 = [0.01, 0.1, 1.0], 0.01 = the main solution
    return big_move_plan


def test_rest_to_rest_within_limits(plan, pm, big_move, quick_traj_config):
    tr = plan.trajectories["ptp"]
    q0, q1 = big_move
    assert np.allclose(tr.q[0], q0) and np.allclose(tr.q[-1], q1, atol=1e-8)
    assert np.abs(tr.v[0]).max() < 1e-9 and np.abs(tr.v[-1]).max() < 1e-5   # constr_viol_tol 1e-6 (scaled)
    assert np.abs(tr.a[0]).max() < 1e-6 and np.abs(tr.a[-1]).max() < 1e-6   # continuous acceleration
    chk = plan.checks["ptp"]
    assert chk.violation <= quick_traj_config.violation_tolerance
    assert chk.max_velocity_ratio <= 1.0 + quick_traj_config.violation_tolerance
    assert np.all(tr.q >= pm.lower_rad - 1e-9) and np.all(tr.q <= pm.upper_rad + 1e-9)


def test_faster_than_torque_feasible_ruckig(plan):
    assert plan.checks["ptp_ruckig"].max_torque_ratio <= 1.0 + 1e-9
    assert plan.result.duration_s < plan.ruckig.duration_s


def test_energy_optimum_at_ruckig_duration(plan):
    fixed = plan.at_ruckig_duration
    assert fixed.duration_s == pytest.approx(plan.ruckig.duration_s, rel=1e-9)
    assert plan.checks["ptp_energy_at_ruckig_duration"].energy < plan.checks["ptp_ruckig"].energy


def test_pareto_trades_time_for_energy(plan):
    T = [r.duration_s for r in plan.pareto]
    E = [r.info["fine_energy"] for r in plan.pareto]
    assert T[-1] >= T[0] - 1e-6 and E[-1] <= E[0] + 1e-6


def test_every_reported_energy_is_the_fine_grid_one(plan, pm, quick_traj_config):
    """Summary and Pareto entries report the fine-grid re-check with the same weights, so the
    main solution has one energy wherever it appears (not the optimiser's Simpson value)."""
    s = plan.summary()
    dt = quick_traj_config.fine_dt_s
    assert [e["k2"] for e in s["ptp_pareto"]] == [0.01, 0.1, 1.0]
    for e, r in zip(s["ptp_pareto"], plan.pareto, strict=True):
        assert e["energy"] == check_trajectory(pm, r.sample(dt), energy_weights=plan.weights).energy
    main = s["ptp_pareto"][0]
    assert plan.pareto[0] is plan.result
    assert main["duration_s"] == s["ptp_nlp_duration_s"]
    assert main["energy"] == check_trajectory(pm, plan.result.sample(dt), energy_weights=plan.weights).energy
    # the plan handed on (the NLP's, slowed into the fine-grid limits, or ruckig's profile)
    assert s["ptp_energy"] == check_trajectory(pm, plan.trajectories["ptp"], energy_weights=plan.weights).energy
    assert plan.result.energy != main["energy"]            # the Simpson value differs: not reported
    rk = plan.trajectories["ptp_ruckig"]
    assert s["ptp_ruckig_energy"] == check_trajectory(pm, rk, energy_weights=plan.weights).energy
    assert np.all(np.diff(rk.t_s) <= dt + 1e-12)           # the baseline checked on the same fine grid


def test_plan_never_slower_than_its_ruckig_baseline(plan, pm, quick_traj_config):
    """The torque-feasible ruckig profile is itself a candidate: the plan handed on is never longer,
    and it keeps the limits on the fine grid."""
    s = plan.summary()
    assert s["ptp_duration_s"] <= plan.ruckig.duration_s
    assert s["ptp_duration_vs_ruckig_ratio"] <= 1.0
    assert s["ptp_source"] in ("nlp", "ruckig") and s["ptp_nlp_warm_start"] in ("quintic", "ruckig")
    assert s["ptp_fine_violation"] <= quick_traj_config.violation_tolerance


def _really_dominated(i, pts):
    t, e = pts[i]
    return any(j != i and tj <= t and ej <= e and (tj < t or ej < e) for j, (tj, ej) in enumerate(pts))


def test_pareto_front_monotone_and_flags_true(plan):
    entries = plan.summary()["ptp_pareto"]
    pts = [(e["duration_s"], e["energy"]) for e in entries]
    assert all(isinstance(e["dominated"], bool) for e in entries)
    for i, e in enumerate(entries):
        if e["dominated"]:
            assert _really_dominated(i, pts)
    front = sorted((p for p, e in zip(pts, entries, strict=True) if not e["dominated"]), key=lambda p: p[0])
    assert len(front) >= 2
    for (t0, e0), (t1, e1) in zip(front[:-1], front[1:], strict=True):
        assert t1 >= t0 and e1 <= e0          # duration increasing => energy decreasing


def test_dominated_flags():
    # k2 = 0.003 of the review: 0.629 s / 1.760 is worse in both than 0.628 s / 1.416
    pts = [(0.629, 1.760), (0.628, 1.416), (0.64, 1.3), (0.64, 1.3), (0.70, 1.35)]
    assert dominated_flags(pts) == [True, False, False, False, True]   # equal points do not dominate
    assert dominated_flags([(1.0, 1.0), (1.0 + 1e-12, 1.0)]) == [False, False]   # within the tolerance


def _fake(k2, T, E, tag="warm"):
    z = np.zeros((2, 1))
    return PtpResult(np.array([0.0, T]), z, z, z, T, -1.0, 0.0, 0.0, 0, 1.0, k2, info={"E": E, "tag": tag})


def test_settle_pareto_resolves_dominated_points_cold():
    """Re-solve each dominated point once from a cold start, keep the lower k1 T + k2 E (fine-grid
    E), flag what stays dominated, never re-solve the main (cold-started) solution."""

    main = _fake(0.01, 0.628, 1.416, "main")
    better = _fake(0.003, 0.627, 1.5, "cold")           # beats 0.629 / 1.760 and is not dominated
    worse = _fake(0.1, 0.70, 1.6, "cold")              # still dominated, higher objective
    sweep = [_fake(0.003, 0.629, 1.760), main, _fake(0.1, 0.65, 1.5), _fake(0.3, 0.66, 1.45),
             _fake(1.0, 0.64, 1.3)]
    cold = {0.003: better, 0.1: worse, 0.3: SolverError(None, "ptp", "IPOPT failed: Maximum_Iterations")}
    asked = []

    def cold_solve(r):
        asked.append(r.k2)
        out = cold[r.k2]
        if isinstance(out, Exception):
            raise out
        return out

    out = settle_pareto(sweep, lambda r: r.info["E"], cold_solve, cold_started=(main,))
    assert sorted(asked) == [0.003, 0.1, 0.3]                 # each once; main and 1.0 not
    assert out[0] is better and better.info["cold_restart"] == "kept" and not better.info["dominated"]
    assert out[2] is sweep[2] and out[2].info["cold_restart"] == "discarded" and out[2].info["dominated"]
    assert out[3].info["cold_restart"].startswith("failed: IPOPT failed") and out[3].info["dominated"]
    assert out[1] is main and not main.info["dominated"] and out[4].info["dominated"] is False
    assert [r.info["fine_energy"] for r in out] == [1.5, 1.416, 1.5, 1.45, 1.3]
    pts = [(r.duration_s, r.info["fine_energy"]) for r in out]
    assert [_really_dominated(i, pts) for i in range(len(pts))] == [r.info["dominated"] for r in out]


def test_settle_pareto_flags_a_dominated_main_solution():

    main = _fake(0.01, 0.7, 2.0, "main")
    out = settle_pareto([main, _fake(0.1, 0.6, 1.0)], lambda r: r.info["E"],
                        lambda r: pytest.fail("the main solution is a cold start already"), cold_started=(main,))
    assert main.info["dominated"] and main.info["cold_restart"] == "is a cold start"
    assert not out[1].info["dominated"]


def test_pareto_figure_marks_dominated_points():
    fig = pareto_figure([(0.003, 0.629, 1.76), (0.01, 0.628, 1.416), (0.1, 0.64, 1.3)], (0.9, 1.2), "energy [s]")
    ax = fig.axes[0]
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    assert list(lines["PtP NLP (k1 = 1)"].get_xdata()) == [0.628, 0.64]        # the front only
    hollow = lines["dominated (local optimum)"]
    assert list(hollow.get_xdata()) == [0.629] and hollow.get_markerfacecolor() == "none"
    assert "dominated (local optimum)" in [t.get_text() for t in ax.get_legend().get_texts()]


def test_warm_start_from_own_solution_stays_put(plan, ptp_problem, big_move):
    """Primal + dual warm start at a solution: IPOPT confirms it in a few iterations, same motion."""
    res = plan.result
    again = ptp_problem.solve(*big_move, res.k1, res.k2, weights=plan.weights,
                              effort_Nm=ptp_problem.pm.effort_Nm * np.asarray(res.info["torque_scale"]),
                              velocity_rad_s=ptp_problem.pm.velocity_rad_s * np.asarray(res.info["velocity_scale"]),
                              x0=res.info["x"], coulomb_widths_rad_s=(), multipliers=res.info["multipliers"],
                              acceleration_rad_s2=ptp_problem.pm.acceleration_rad_s2 if res.info["acceleration_limits"]
                              else None)
    assert again.iterations <= 10 < res.iterations
    # same optimum to the solver's tolerance (tol 1e-4: the re-solve may polish it a little)
    assert again.duration_s == pytest.approx(res.duration_s, rel=1e-3)


def test_goal_outside_limits_is_named(ptp_problem, big_move):
    q0, _ = big_move
    bad = q0.copy()
    bad[1] = np.radians(170.0)
    with pytest.raises(InfeasibleError, match="joint 2"):
        ptp_problem.solve(q0, bad)


def test_unattainable_duration_raises_before_the_solver_runs(ptp_problem, big_move, pm):
    """0.05 s for a 90 deg move beats the velocity limits' own bound: refused up front, naming the joint."""
    with pytest.raises(InfeasibleError, match="ptp duration joint 1"):
        ptp_problem.solve(*big_move, k1=0.0, k2=1.0, weights=energy_weights(pm, "normalised"), duration_s=0.05)
    bound_s = float(np.max(np.abs(big_move[1] - big_move[0]) / pm.velocity_rad_s))
    bang_bang_s = 2.0 * np.sqrt(abs(big_move[1][0] - big_move[0][0]) / 0.5)     # joint 1 at 0.5 rad/s²
    with pytest.raises(InfeasibleError, match=f"below the {bang_bang_s:.4g} s"):
        ptp_problem.solve(*big_move, k1=0.0, k2=1.0, duration_s=1.01 * bound_s,
                          acceleration_rad_s2=np.full(pm.nq, 0.5))


def test_compiled_library_is_reused(pm, rx130l, ptp_problem, quick_traj_config):
    mtime = ptp_problem.library.stat().st_mtime_ns
    again = solve_mod.ptp_problem(pm, rx130l, quick_traj_config)
    assert again.library == ptp_problem.library
    assert again.library.stat().st_mtime_ns == mtime          # loaded from the cache, not rebuilt


def test_energy_measure_names(pm):
    assert np.allclose(energy_weights(pm, "torque"), 1.0)
    assert np.allclose(energy_weights(pm, "normalised"), pm.effort_Nm**-2)
    w = energy_weights(pm, "electrical", np.ones(6), np.ones(6), np.full(6, 10.0))
    assert np.allclose(w, 0.01)
    with pytest.raises(PipelineError):
        energy_weights(pm, "joules")


def test_ruckig_search_respects_torques(pm, big_move):
    rk = ruckig_torque_feasible(pm, *big_move, jerk_ratios_1_s=(25.0,), joint_rounds=1)
    chk = check_trajectory(pm, rk.trajectory)
    assert chk.max_torque_ratio <= 1.0
    assert np.diff(rk.trajectory.t_s).max() <= 5e-4 + 1e-12


def test_ruckig_samples_are_ruckigs_own_bit_for_bit():
    """The profiles sampled in numpy equal ``Trajectory.at_time`` to the last bit (asymmetric and
    symmetric acceleration limits, joints at rest, times past the end)."""
    rng = np.random.default_rng(7)
    for trial in range(16):
        n = int(rng.integers(1, 8))
        q0, q1 = rng.uniform(-3, 3, n), rng.uniform(-3, 3, n)
        q1[: n // 3] = q0[: n // 3]
        amax = rng.uniform(0.5, 50, n)
        amin = amax * rng.uniform(0.3, 2, n) if trial % 2 else None
        traj = Trajectory(n)
        Ruckig(n).calculate(_ruckig_input(q0, q1, rng.uniform(0.2, 5, n), amax, amax * rng.uniform(2, 200, n),
                                          amin), traj)
        t = np.append(np.linspace(0.0, traj.duration, 400), traj.duration + 0.01)
        expected = np.array([traj.at_time(tk) for tk in t])
        sampled = np.stack(_states_at(traj, t), axis=1)
        assert np.array_equal(sampled.view(np.uint64), expected.view(np.uint64)), trial


def test_ruckig_refinement_is_feasible_and_not_slower(pm, big_move):
    """The Nelder-Mead refinement of the ruckig limits never returns a slower or an infeasible move
    (checked on the 0.5 ms grid), and it is counted in the evaluations."""
    q0, q1 = big_move
    plain = ruckig_torque_feasible(pm, q0, q1, jerk_ratios_1_s=(25.0,), joint_rounds=2)
    refined = ruckig_torque_feasible(pm, q0, q1, jerk_ratios_1_s=(25.0,), joint_rounds=2, refine_evaluations=200)
    assert refined.duration_s <= plain.duration_s + 1e-9
    assert refined.evaluations > plain.evaluations
    assert np.diff(refined.trajectory.t_s).max() <= 5e-4 + 1e-12
    assert check_trajectory(pm, refined.trajectory).max_torque_ratio <= 1.0 + 1e-9


def test_no_energy_plan_when_ruckig_is_shorter_than_the_transcription(pm, ptp_problem, big_move,
                                                                      quick_traj_config, monkeypatch):
    """A kinematically limited move (the Panda's derived move): ruckig's jerk-limited profile switches
    between the transcription's nodes and is shorter than any of its plans; the energy comparison at
    ruckig's duration is then reported as absent with the reason, not as a failed solve. Here a
    baseline time-compressed to 0.8 of ruckig's stands for it."""
    real = solve_mod.ruckig_torque_feasible

    def faster(*args, **kwargs):
        rk = real(*args, **kwargs)
        tr = rk.trajectory
        quick = dataclasses.replace(tr, t_s=0.8 * tr.t_s, v=tr.v / 0.8, a=tr.a / 0.64)
        return dataclasses.replace(rk, trajectory=quick, duration_s=0.8 * rk.duration_s)

    monkeypatch.setattr(solve_mod, "ruckig_torque_feasible", faster)
    cfg = dataclasses.replace(quick_traj_config, ptp_pareto_k2=[0.01])
    plan = plan_ptp(pm, ptp_problem, *big_move, cfg)
    assert plan.ruckig.duration_s < plan.result.duration_s
    assert plan.at_ruckig_duration is None and "ptp_energy_at_ruckig_duration" not in plan.trajectories
    s = plan.summary()
    assert s["ptp_energy_at_ruckig_duration_ratio"] is None and "shorter" in s["ptp_energy_at_ruckig_duration_note"]
    assert s["ptp_energy_at_ruckig_duration_solver_status"] == "not_attempted"
