"""Choice of the executed CP among the measured remedies (shortest that keeps the servo gate)."""

from __future__ import annotations

import numpy as np

from pipeline.trajectory.executable import choose


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
