"""Gradient-based design (paper 000): the CasADi segment distance and the IPOPT design of n configurations."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import error_model as em
from pipeline.calibration import stage as st
from pipeline.calibration.gradient_design import GradientDesignConfig, gradient_design
from pipeline.robot.collision import segment_distances
from pipeline.robot.collision_sx import segment_distance_sx
from pipeline.robot.instruments import tracker_visibility
from pipeline.robot.model import RobotModel


def test_squared_casadi_segment_distance_matches_numpy():
    """The NLP's squared form of the shared distance (gradient design constraints)."""
    rng = np.random.default_rng(0)
    a, b, c, d = (ca.SX.sym(n, 3) for n in "abcd")
    f = ca.Function("d", [a, b, c, d], [segment_distance_sx(a, b, c, d) ** 2])
    P = rng.normal(size=(200, 4, 3))
    P[:20, 3] = P[:20, 2] + 2 * (P[:20, 1] - P[:20, 0])   # parallel segments
    ref = segment_distances(P[:, 0], P[:, 1], P[:, 2], P[:, 3])
    got = np.array([np.sqrt(float(f(*p))) for p in P])
    assert np.allclose(got, ref, atol=1e-6)


def test_gradient_design_improves_and_stays_feasible():
    robot = RobotModel.load("rx130l")
    mm = em.MeasurementModel(robot)
    rng = np.random.default_rng(1)
    cfg = st.Config(candidates="random", n_random_candidates=300, index_name="tcp_A", n_working_configurations=2)
    _, basis = st.identify_parameter_set(robot, mm, cfg, rng)
    cs = st.build_candidates(robot, cfg, basis, rng)
    spec, _ = st.index_spec(cfg, robot, mm, basis, rng)
    start = ds.remove_and_replace(cs.G, spec, 20, rng, n_initial=20)
    res = gradient_design(robot, mm, basis, cs.Q[start.selected], spec, GradientDesignConfig(max_iterations=300))
    assert res.status == "Solve_Succeeded" and res.fallback is None
    assert res.reverted == len(res.reverted_reasons)
    assert res.index_value < res.index_value_start
    # a non-success status is never the design: the warm start is kept and the result says why
    stop = gradient_design(robot, mm, basis, cs.Q[start.selected], spec, GradientDesignConfig(max_iterations=1))
    assert stop.status != "Solve_Succeeded" and stop.status in stop.fallback
    assert np.array_equal(stop.Q, cs.Q[start.selected]) and stop.index_value == stop.index_value_start
    assert res.index_value_start == pytest.approx(start.index_value, rel=1e-6)
    chain = cd.chain_from_robot(robot)
    mask, _ = cd.filter_configurations(chain, res.Q, cd.FilterMargins(0.0, 0.0, 0.0))
    assert mask.all()
    assert tracker_visibility(robot, robot.tracker.transform_tracker_to_base, res.Q).visible.all()
    assert res.run_time_s < 120 and res.evaluations > 0
