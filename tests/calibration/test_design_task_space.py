"""Task-space V criterion, working regions and the design table."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import design_table as dtab
from pipeline.calibration import error_model as em
from pipeline.calibration import indices as ix
from pipeline.calibration import measure as ms
from pipeline.calibration import stage as st
from pipeline.calibration import task_space as ts
from pipeline.calibration.design_state import DesignState
from pipeline.calibration.estimate import estimate
from pipeline.core.errors import ConfigError, DataFileError
from pipeline.robot.defaults import iso_cube
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot


@pytest.fixture(scope="session")
def robot():
    return RobotModel.load("rx130l")


@pytest.fixture(scope="session")
def setup(robot):
    mm = em.MeasurementModel(robot)
    rng = np.random.default_rng(3)
    cfg = st.Config(candidates="random", n_random_candidates=400, identifiability_samples=60)
    _, basis = st.identify_parameter_set(robot, mm, cfg, rng)
    cs = st.build_candidates(robot, cfg, basis, rng)
    region = ts.default_region(robot)
    Qw = ts.sample_region(robot, region, 60, rng)
    return mm, basis, cs, region, Qw


def test_region_samples_are_collision_free_with_the_tcp_inside(robot, setup):
    _, _, _, region, Qw = setup
    assert len(Qw) == 60
    p = robot.positions(Qw, robot.frame_tcp)
    assert np.all(p >= region.lower_m - 1e-12) and np.all(p <= region.upper_m + 1e-12)
    assert np.allclose(ts.tcp_positions(cd.chain_from_robot(robot), robot, Qw), p, atol=1e-12)
    assert not any(robot.in_collision(q) for q in Qw[:10])
    # orientations vary: not one IK solution repeated
    assert np.ptp(Qw[:, 3:], axis=0).min() > 0.5


def test_v_is_the_mean_predicted_tcp_variance(robot, setup):
    mm, basis, cs, _, Qw = setup
    spec = ts.task_space_spec(mm, Qw, basis)
    sel = ds.random_design(cs.G, spec, 30, np.random.default_rng(0)).selected
    M = dtab.information(cs.G[sel])
    C = np.linalg.inv(M)
    J = ts.tcp_jacobian(mm, Qw, basis).reshape(len(Qw), 3, -1)
    mean_var = np.mean([np.trace(Jk @ C @ Jk.T) for Jk in J])
    assert ix.evaluate(spec, M, 30) == pytest.approx(mean_var, rel=1e-9)
    assert ts.predicted_tcp_rms_m(spec, M) == pytest.approx(np.sqrt(mean_var), rel=1e-9)
    # TCP Jacobian = finite difference of the symbolic TCP position in the identifiable parameters
    fk = mm.sym.fk(robot.frame_tcp)
    th = np.zeros(basis.shape[1])
    k = 5
    th[k] = 1e-6
    dp = (np.asarray(fk(Qw[0], basis[mm.sl_kin] @ th)[0]).ravel()
          - np.asarray(fk(Qw[0], np.zeros(mm.n_kin))[0]).ravel()) / 1e-6
    assert np.allclose(dp, J[0][:, k], atol=1e-5)


def test_rank_one_search_on_v_matches_brute_force(setup):
    mm, basis, cs, _, Qw = setup
    spec = ts.task_space_spec(mm, Qw, basis)
    state = DesignState(cs.G, spec, None, np.arange(20))
    j, score = state.best_add()
    brute = [ix.score(spec, state.M + cs.G[c].T @ cs.G[c], 21) if c >= 20 else -np.inf for c in range(len(cs))]
    assert j == int(np.argmax(brute)) and score == pytest.approx(max(brute), rel=1e-8)


@pytest.mark.parametrize("method", ["remove_and_replace", "detmax", "bsaa"])
def test_selectors_improve_v_over_random(setup, method):
    mm, basis, cs, _, Qw = setup
    spec = ts.task_space_spec(mm, Qw, basis)
    rnd = ds.random_design(cs.G, spec, 25, np.random.default_rng(1))
    kw = {"t_initial": 1e-8, "t_final": 1e-16, "cooling": 0.9} if method == "bsaa" else {}
    sel = ds.select(method, cs.G, spec, 25, np.random.default_rng(1), **kw)
    assert sel.index_name == "V" and len(sel.selected) == 25
    assert sel.index_value < rnd.index_value


def test_design_table_rows_and_user_mode(robot, setup):
    mm, basis, cs, region, Qw = setup
    spec = ts.task_space_spec(mm, Qw, basis)
    rng = np.random.default_rng(2)
    sel = ds.remove_and_replace(cs.G, spec, 24, rng)
    real = RealRobot.create(robot, 2)

    meas = ms.measure_simulated(real, cs.Q[sel.selected], rng)
    est = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis)
    table = dtab.design_table(robot, real, mm, basis, spec, "chosen", meas.Q, est, cs, region, rng, n_heldout=80)
    rows = {r["design"]: r for r in table["rows"]}
    assert set(rows) == {"chosen", "every (N/n)-th feasible candidate", "random", "O3 remove-and-replace"}
    assert all(r["n_configurations"] == len(meas.Q) for r in rows.values())
    # V remove-and-replace minimises the predicted TCP RMS: no baseline of the same size beats it
    assert all(rows["chosen"]["predicted_tcp_rms_m"] <= r["predicted_tcp_rms_m"] for r in rows.values())
    assert table["n_heldout_region"] >= 3
    for r in rows.values():
        assert r["actual_model_rms_m"] is not None and 0 < r["predicted_model_rms_m"] < 1e-3
    # the certified bound over the pool lies below the verified prediction of every design of that size
    b = table["bound"]
    assert b is not None and b["n_configurations"] == len(meas.Q) and b["n_candidates"] == len(cs)
    assert all(0 < b["bound_verified_rms_m"] <= r["predicted_verified_rms_m"] for r in rows.values())
    assert rows["chosen"]["n_measured"] == len(meas.Q)
    assert all(r["n_measured"] <= r["n_configurations"] for r in rows.values())
    assert "Certified bound" in dtab.markdown(table) and dtab.summary(table)["bound"] == b
    assert all(r.get("repeated_model_rms_m") is None for r in rows.values())
    text = dtab.markdown(table)
    assert "O3 remove-and-replace" in text and "predicted TCP RMS" in text
    # user data: predicted figure of the user's configurations only, nothing measured
    user = dtab.design_table(robot, None, mm, basis, spec, "user file", meas.Q, est, None, region, rng)
    assert [r["design"] for r in user["rows"]] == ["user file"]
    assert user["rows"][0]["actual_model_rms_m"] is None and user["n_heldout_region"] is None
    assert user["rows"][0]["predicted_tcp_rms_m"] == pytest.approx(rows["chosen"]["predicted_tcp_rms_m"])
    assert "predicted figures only" in dtab.markdown(user)


def test_design_table_repeats_leave_the_single_draws_unchanged(robot, setup):
    mm, basis, cs, region, Qw = setup
    spec = ts.task_space_spec(mm, Qw, basis)
    real = RealRobot.create(robot, 2)
    Q = cs.Q[ds.remove_and_replace(cs.G, spec, 24, np.random.default_rng(5)).selected]
    meas = ms.measure_simulated(real, Q, np.random.default_rng(6))
    est = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis)

    def table(repeats):
        return dtab.design_table(robot, real, mm, basis, spec, "chosen", meas.Q, est, cs, region,
                                 np.random.default_rng(7), n_heldout=60, bound=False, repeats=repeats)

    single, rep = table(0), table(3)
    assert single["bound"] is None
    for a, b in zip(single["rows"], rep["rows"], strict=True):
        assert a["actual_model_rms_m"] == b["actual_model_rms_m"]
        assert 0 < b["repeated_model_rms_m"] < 1e-3
    # the expected figure of a design: the repeats of the best-predicted design beat those of O3 on this seed
    r = {row["design"]: row["repeated_model_rms_m"] for row in rep["rows"]}
    assert r["chosen"] < r["O3 remove-and-replace"]
    assert "repeated calibrations" in dtab.markdown(rep)


def test_reflector_term_at_the_poses_the_tracker_sees(robot, setup):
    mm, basis, _, region, Qw = setup
    Qv = ts.verifiable_configurations(robot, region, 40, np.random.default_rng(4), 0.01)
    assert Qv is not None and len(Qv) == 40
    margins = cd.FilterMargins(0.01, ts.VERIFIABLE_INCIDENCE_MARGIN_RAD, ts.VERIFIABLE_BEAM_MARGIN_M)
    assert cd.filter_configurations(cd.chain_from_robot(robot), Qv, margins)[0].all()
    p = robot.positions(Qv, robot.frame_tcp)
    assert np.all(p >= region.lower_m - 1e-12) and np.all(p <= region.upper_m + 1e-12)
    # W = (W_tcp over the region + W_reflector over the visible poses) / 2, whatever the two counts
    spec = ts.task_space_spec(mm, Qw, basis, "tcp+reflector", Qv)
    Jt, Jv = ts.tcp_jacobian(mm, Qw, basis), ts.reflector_jacobian(mm, Qv, basis)
    W = 0.5 * (Jt.T @ Jt / len(Qw) + Jv.T @ Jv / len(Qv))
    np.testing.assert_allclose(spec.weight_matrix(basis.shape[1]), W, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(ts.tcp_part(spec, "tcp+reflector").weight_matrix(basis.shape[1]), Jt.T @ Jt / len(Qw),
                               rtol=1e-10, atol=1e-12)
    # the visible poses face the tracker: a different weighting than the reflector over all working poses
    Jr = ts.reflector_jacobian(mm, Qw, basis)
    assert np.linalg.norm(Jv.T @ Jv / len(Qv) - Jr.T @ Jr / len(Qw)) > 0.05 * np.linalg.norm(Jr.T @ Jr / len(Qw))
    # without visible poses the reflector term stays on the working poses
    np.testing.assert_allclose(ts.task_space_spec(mm, Qw, basis, "tcp+reflector").weight_matrix(basis.shape[1]),
                               0.5 * (Jt.T @ Jt + Jr.T @ Jr) / len(Qw), rtol=1e-10, atol=1e-12)


def test_region_config_fields(robot, tmp_path):
    with pytest.raises(ConfigError, match="design_table_repeats"):
        st.Config(design_table_repeats=-1).validate()
    with pytest.raises(ConfigError, match="working_region"):
        st.Config(working_region="sphere").validate()
    with pytest.raises(ConfigError, match="working_box_m"):
        st.Config(working_region="box", working_box_m=[[0, 0, 0], [1, -1, 1]]).validate()
    with pytest.raises(ConfigError, match="working_csv"):
        st.Config(working_region="csv").validate()
    box = st.Config(working_region="box", working_box_m=[[0.8, -0.2, 0.4], [1.1, 0.2, 0.7]])
    box.validate()
    reg = ts.region_from_config(box, None, None, robot)
    assert np.allclose(reg.lower_m, [0.8, -0.2, 0.4])
    Q = np.zeros((3, 6))
    Q[:, 1] = [-0.5, 0.0, 0.5]
    path = tmp_path / "work.csv"
    path.write_text("q1,q2,q3,q4,q5,q6\n" + "\n".join(",".join(map(str, q)) for q in Q))
    csv = st.Config(working_region="csv", working_csv=str(path))
    assert np.allclose(ts.region_from_config(csv, None, None, robot).configurations, Q)
    path.write_text("q1,q2,q3,q4,q5,q6\n0,9,0,0,0,0\n")
    with pytest.raises(DataFileError, match="row 2"):
        ts.read_working_csv(str(path), robot)
    # no cube configured: the cube derived from the model (the one the control stage derives too)
    derived = ts.region_from_config(st.Config(), None, None, robot)
    cube = iso_cube(robot)
    assert np.allclose(0.5 * (derived.lower_m + derived.upper_m), cube.centre_m)
    assert np.allclose(derived.upper_m - derived.lower_m, cube.edge_m)
