"""Paper 000 study (``study calib-000``): the KUKA arms, the cell, the baselines and a quick run."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

from pipeline.calibration import error_model as em
from pipeline.papers import calib_000 as p0
from pipeline.papers import calib_000_elastic as el
from pipeline.papers import calib_000_report as rp
from pipeline.papers import calib_000_scene as sc
from pipeline.robot.model import RobotModel


@pytest.mark.parametrize(("name", "reach_m"), [("kuka_kr15", 1.61), ("kuka_kr300", 2.50), ("kuka_kr500", 2.825)])
def test_kuka_arms_reach_their_data_sheet_wrist_point(name: str, reach_m: float) -> None:
    robot = RobotModel.load(name)
    # KUKA's reach: axis 1 to the wrist point (frame of joint 5) with the arm stretched horizontally
    robot_data = robot.model.createData()
    pin.forwardKinematics(robot.model, robot_data, np.zeros(6))
    assert np.linalg.norm(robot_data.oMi[5].translation[:2]) == pytest.approx(reach_m, abs=1e-9)
    assert not robot.in_collision(np.zeros(6))


def test_notional_arm_has_the_papers_segment_lengths() -> None:
    base = RobotModel.load("kuka_kr15")
    arm = sc.notional_arm(base, 1.1, 0.6)
    q = np.zeros(6)
    q[1] = -np.pi / 2   # upper arm upright: joint 3 is lambda above joint 2
    z2 = arm.fk(q, "flange").translation
    assert arm.model.jointPlacements[3].translation[0] == pytest.approx(1.1)
    assert np.linalg.norm(arm.model.jointPlacements[4].translation) == pytest.approx(np.hypot(0.6, 0.035))
    assert z2[2] > base.fk(q, "flange").translation[2]   # taller than the KR 15 (a2 0.68 m)
    assert len(sc.LAMBDA_M) * len(sc.MU_M) == 90


def test_parameter_weights_scale_only_angles() -> None:
    names = ["j2.da", "j2.dalpha", "j3.beta", "j4.dd", "j2.dq", "tracker.dx", "reflector.dz"]
    lit = p0.parameter_weights(names, 1.0)
    scaled = p0.parameter_weights(names, 2.0)
    assert np.all(lit[-2:] == 0) and np.count_nonzero(lit) == 5
    assert np.allclose(scaled[:5] / lit[:5], [1, 4, 4, 1, 4])   # lengths kept, angles x 2^2


#: session fixtures that take seconds and serve several tests: their tests run on one pytest-xdist
#: worker, so each is built once per ``make test`` (tests/conftest.py, pytest_collection_modifyitems)
SHARED_COSTLY_FIXTURES = frozenset({"quick_row"})


@pytest.fixture(scope="session")
def quick_row() -> dict:
    cfg = p0.Settings(n=60, pool=250, gradient=False)
    return p0.run_arm("kuka_kr15", RobotModel.load("kuka_kr15"), cfg, seed=0)


def test_quick_run_tcp_criterion_is_best_on_its_figure_and_feasible(quick_row: dict) -> None:
    r = quick_row
    for key in ("random", "spread") + tuple(f"{c}_{m}" for c in p0.CRITERIA for m in ("ca", "free")):
        assert key in r
    tcp = r["tcp_ca"]["tcp_var"]
    assert tcp < r["random"] and tcp < r["spread"]
    for c in ("param_literal", "param_scaled", "param_legacy"):
        assert tcp <= r[f"{c}_ca"]["tcp_var"]
    # designs with collision avoidance are feasible in the cell; the spread baseline too
    for c in p0.CRITERIA:
        assert r[f"{c}_ca"]["collision_share"] == 0.0
        assert 0.0 <= r[f"{c}_free"]["collision_share"] <= 1.0
    assert r["spread_collision_share"] == 0.0
    head = rp.headline([r], [r | {"lambda_m": 0.7, "mu_m": 0.65}])
    for key in ("kuka_kr15.tcp_vs_heuristic", "kuka_kr15.tcp_vs_parameter", "notional.tcp_vs_heuristic",
                "notional.ca_effect", "notional.free_collision_share", "notional.table7_min_max_um2",
                "notional.tcp_vs_parameter.param_literal", "notional.parameter_vs_heuristic.param_scaled"):
        assert key in head
    gv, gs = rp.gain(1.0, 4.0)
    assert gv == pytest.approx(0.75) and gs == pytest.approx(0.5)


def test_gradient_refinement_never_worse_and_collision_free() -> None:
    rng = np.random.default_rng(1)
    setup = p0.setup_arm("kuka_kr15", RobotModel.load("kuka_kr15"), 200, rng)
    out = p0.optimise(setup, "tcp", True, p0.Settings(pool=200, iterations=8), rng)
    assert out["tcp_var"] <= out["tcp_var_discrete"] * (1 + 1e-9)
    assert out["collision_share"] == 0.0


def _without_timings(value: object) -> object:
    """``value`` with every wall-clock entry (``*time_s``) removed (nested dicts and lists)."""
    if isinstance(value, dict):
        return {k: _without_timings(v) for k, v in value.items() if not str(k).endswith("time_s")}
    if isinstance(value, list):
        return [_without_timings(v) for v in value]
    return value


@pytest.mark.slow   # forks a process pool; the dispatch order itself is a fast test (test_dispatch.py)
def test_notional_rows_do_not_depend_on_the_worker_count() -> None:
    cfg = p0.Settings(n=20, pool=60, gradient=False, criteria=("param_literal", "tcp"))
    tasks = p0.notional_tasks(cfg, seed=0, count=2)
    assert len({t.name for t in tasks}) == 2
    serial = p0.run_tasks(tasks, jobs=1)
    parallel = p0.run_tasks(tasks, jobs=2)
    assert [r["arm"] for r in parallel] == [t.name for t in tasks]
    assert [(r["lambda_m"], r["mu_m"]) for r in serial] == [(t.lambda_m, t.mu_m) for t in tasks]
    assert _without_timings(parallel) == _without_timings(serial)
    assert serial[0]["tcp_ca"]["tcp_var"] != serial[1]["tcp_ca"]["tcp_var"]   # two arms, two results


def test_elasticity_experiment_compliance_model_beats_geometric_on_the_elastic_truth(quick_row: dict) -> None:
    """Paper 000's outlook measured: on the elastic hidden robot the compliance-aware calibration of
    the tcp_ca design gives a smaller TCP error than the geometric one, and its fit explains the
    readings (chi²/dof near 1) where the geometric one cannot."""
    e = quick_row["elastic"]
    assert len(e["seeds"]) == p0.Settings().elastic_seeds and e["n_configurations"] <= 60
    assert e["n_parameters"]["all"] > e["n_parameters"]["geometric"]
    geo, comp = e["per_seed"]["geometric"], e["per_seed"]["all"]
    for g, c in zip(geo["random_rms_m"], comp["random_rms_m"], strict=True):
        assert c < 0.5 * g
    assert e["all"]["work_rms_m"] < e["geometric"]["work_rms_m"]
    assert max(comp["chi2_per_dof"]) < 3.0 < 10.0 < min(geo["chi2_per_dof"])
    assert 0.0 < e["gain_work"] < 1.0 and 0.0 < e["gain_random"] < 1.0
    head = rp.headline([quick_row], [quick_row | {"lambda_m": 0.7, "mu_m": 0.65}])
    assert head["kuka_kr15.elastic_gain"]["ours_work"] == e["gain_work"]
    assert "notional.elastic_gain" in head
    assert len(el.elastic_table([quick_row])) == 3


def test_compliance_columns_of_the_tcp_jacobian_match_finite_differences() -> None:
    """``dp_tcp/dc_i = -J_q[:, i] g_i(q)``: the TCP of the compliance-aware model moved by a small
    compliance step agrees with the Jacobian column."""
    robot = RobotModel.load("kuka_kr15")
    mm = em.MeasurementModel(robot, compliance=True)
    basis = np.eye(mm.n)
    q = np.array([0.3, -1.2, 1.4, 0.2, 0.7, -0.4])
    J = el.tcp_jacobian(robot, mm, q, basis)
    est = SimpleNamespace(x=np.zeros(mm.n))
    for i in (1, 2, 4):
        dx = np.zeros(mm.n)
        dx[mm.sl_compliance.start + i] = h = 1e-9
        est_i = SimpleNamespace(x=dx)
        fd = (el.model_tcp(robot, mm, est_i, q)[0] - el.model_tcp(robot, mm, est, q)[0]) / h
        assert np.allclose(fd, J[:, mm.sl_compliance.start + i], rtol=1e-4, atol=1e-9)
