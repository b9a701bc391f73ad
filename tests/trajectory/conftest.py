"""Shared trajectory fixtures: the nominal RX130L planning model, a joint path of the quick ISO
line, ONE compiled PtP problem (quick settings: N = 25, gcc -O0; cached on disk by the hash
of its code, so the notebook and the stage test reuse the library) and ONE quick-profile PtP plan of
the big move, read by the PtP and the settling tests."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.solve import PTPPlan, cp_joint_path, plan_ptp
from pipeline.trajectory.solve import ptp_problem as compile_ptp_problem  # the fixture below takes its name


@pytest.fixture(scope="session")
def quick_traj_config():
    return load_config(CONFIGS_DIR / "quick.yaml").trajectory


@pytest.fixture(scope="session")
def pm(rx130l):
    return PlanningModel.from_robot(rx130l)


@pytest.fixture(scope="session")
def line_path(rx130l, quick_traj_config):
    path, _ = cp_joint_path(rx130l, quick_traj_config)
    return path


#: session fixtures that take seconds and serve several tests: their tests run on one pytest-xdist
#: worker, so each is built once per ``make test`` (tests/conftest.py, pytest_collection_modifyitems)
SHARED_COSTLY_FIXTURES = frozenset({"ptp_problem", "big_move_plan"})


@pytest.fixture(scope="session")
def ptp_problem(rx130l, pm, quick_traj_config):
    return compile_ptp_problem(pm, rx130l, quick_traj_config)


@pytest.fixture(scope="session")
def big_move():
    return np.radians([-45, 20, 30, 0, 40, 0]), np.radians([45, 60, -20, 30, 50, 60])


@pytest.fixture(scope="session")
def big_move_plan(pm, ptp_problem, big_move, quick_traj_config) -> PTPPlan:
    """The quick profile's PtP plan of ``big_move``: the time-optimal move (k1 = 1, k2 = 0.01), ruckig,
    the energy optimum at ruckig's duration and the Pareto sweep k2 = [0.01, 0.1, 1.0] (0.01 is the
    main solution, reused). Shared: a test that adds to its dicts first copies them (``dataclasses.replace``)."""
    assert quick_traj_config.ptp_k1 == 1.0 and quick_traj_config.ptp_k2 == 0.01
    assert quick_traj_config.ptp_pareto_k2 == [0.01, 0.1, 1.0]
    return plan_ptp(pm, ptp_problem, *big_move, quick_traj_config)

