"""TCP speed/acceleration bounds of the excitation (identification.excitation.max_tcp_*)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.core.errors import ConfigError
from pipeline.identification import design as D
from pipeline.identification import fourier as F
from pipeline.identification.tcp_motion import tcp_speed_acceleration
from pipeline.robot.symbolic import SymbolicRobot


def test_symbolic_tcp_motion_matches_pinocchio(rx130l):
    limits = F.ExcitationLimits.from_robot(rx130l, 0.95, 0.95, 0.95, 0.8, 0.05, 0.02, 2.0, 7.0)
    h = D.sample_constraint_function(rx130l, SymbolicRobot(rx130l), limits)
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = rng.uniform(rx130l.limits.lower_rad, rx130l.limits.upper_rad) * 0.5
        v, a = rng.normal(size=6), rng.normal(size=6)
        out = np.asarray(h(ca.DM(np.concatenate([q, v, a])))).ravel()
        speed, acc = tcp_speed_acceleration(rx130l, q[None], v[None], a[None])
        np.testing.assert_allclose(out[-2:], [speed[0] ** 2 / 2.0**2, acc[0] ** 2 / 7.0**2], rtol=1e-9)


def test_random_excitation_respects_the_tcp_bounds(rx130l):
    free = F.ExcitationLimits.from_robot(rx130l, 0.95, 0.95, 0.95, 0.8, 0.05, 0.02)
    bound = F.ExcitationLimits.from_robot(rx130l, 0.95, 0.95, 0.95, 0.8, 0.05, 0.02, 1.0, 3.0)
    assert not free.bounds_tcp and bound.bounds_tcp
    trajs = F.random_feasible_trajectories(rx130l, bound, 5, 0.1, 3, np.random.default_rng(0), n_check=100)
    for tr in trajs:
        rep = F.check_trajectory(rx130l, tr, bound, 200)
        assert rep.feasible
        assert rep.tcp_speed_max_m_s <= 1.0 + 1e-9 and rep.tcp_acceleration_max_m_s2 <= 3.0 + 1e-9
        # the same trajectory without bounds reports the same (finite) TCP figures
        rep_free = F.check_trajectory(rx130l, tr, free, 200)
        assert rep_free.tcp_speed_max_m_s == pytest.approx(rep.tcp_speed_max_m_s)


@pytest.mark.parametrize("value", [0, -1.0, "fast"])
def test_bad_tcp_bound_is_a_config_error(value):
    with pytest.raises(ConfigError, match="max_tcp_speed_m_s"):
        load_config(CONFIGS_DIR / "quick.yaml", values={"identification.excitation.max_tcp_speed_m_s": value})
