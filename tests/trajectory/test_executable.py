"""Choice of the executed CP among the measured remedies (shortest that keeps the servo gate)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from pipeline.trajectory.executable import choose, to_gate


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
