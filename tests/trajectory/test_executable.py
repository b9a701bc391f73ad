"""Choice of the executed CP among the measured remedies (shortest that keeps the servo gate)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.core.errors import InfeasibleError
from pipeline.trajectory.executable import choose, reserve_floor, to_gate
from pipeline.trajectory.reachability import solve_cp_reachability


def test_the_shortest_passing_remedy_is_executed_else_the_lowest_ratio():
    rng = np.random.default_rng(3)
    for _ in range(200):
        names = ["time_optimal", "reserve", "smooth", "slowed"][: int(rng.integers(1, 5))]
        cands = {n: {"duration_s": float(rng.uniform(0.6, 0.9)),
                     "max_averaged_torque_ratio": float(rng.uniform(0.8, 1.4))} for n in names}
        pick = choose(cands, 1.0)
        passing = {n for n, c in cands.items() if c["max_averaged_torque_ratio"] <= 1.0}
        if passing:
            assert pick in passing
            assert all(cands[pick]["duration_s"] <= cands[n]["duration_s"] for n in passing)
        else:
            assert all(cands[pick]["max_averaged_torque_ratio"] <= c["max_averaged_torque_ratio"]
                       for c in cands.values())


def _servo(ratio: float, diverged: bool = False) -> SimpleNamespace:
    return SimpleNamespace(max_averaged_torque_ratio=ratio, diverged=diverged)


def test_a_diverged_servo_run_ends_the_remedy_search():
    runs: list[float] = []

    def run(x: float):
        runs.append(x)
        return SimpleNamespace(duration_s=1.0 + x), _servo(float("nan"), diverged=True)

    first = (SimpleNamespace(duration_s=1.0), _servo(1.5))
    _, sim, rounds = to_gate(run, first, lambda r: r - 1.0, 1.0)
    assert rounds == len(runs) == 1 and sim.diverged      # not slowed on: a NaN ratio measures nothing
    diverged_first = (SimpleNamespace(duration_s=1.0), _servo(float("nan"), diverged=True))
    assert to_gate(run, diverged_first, lambda r: r - 1.0, 1.0)[2] == 0


def test_the_reserve_remedy_keeps_the_torque_that_holds_the_path(pm, line_path, quick_traj_config):
    """Its floor on the joint that gravity loads most leaves room to move along the path; just below
    the torque that holds the path at rest no profile exists (the remedy without a floor crashed the
    stage there)."""
    n_grid = quick_traj_config.cp_n_grid
    floor = reserve_floor(pm, line_path, n_grid)
    assert np.all(floor <= 1.0) and np.all(floor > 0)
    loaded = int(np.argmax(floor))
    at_floor, below = np.ones(pm.nq), np.ones(pm.nq)
    at_floor[loaded] = floor[loaded]
    q = line_path(np.linspace(0.0, 1.0, n_grid + 1))
    gravity_share = np.max(np.abs(pm.rigid_torques(q, 0 * q, 0 * q)), axis=0) / pm.effort_Nm
    below[loaded] = 0.95 * gravity_share[loaded]
    profile = solve_cp_reachability(pm, line_path, n_grid, torque_scale=at_floor, acceleration_limits=False)
    assert profile.duration_s > 0 and np.all(profile.sdot[1:-1] > 0)
    with pytest.raises(InfeasibleError, match="holding torque"):
        solve_cp_reachability(pm, line_path, n_grid, torque_scale=below, acceleration_limits=False)
