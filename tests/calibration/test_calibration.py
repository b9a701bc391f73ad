"""Calibration stage: error model, candidates, estimation, bad input, end-to-end targets."""

from __future__ import annotations

import json
import time
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import error_model as em
from pipeline.calibration import gates as cg
from pipeline.calibration import indices as ix
from pipeline.calibration import measure as ms
from pipeline.calibration import stage as st
from pipeline.calibration.elastostatic import design_basis, design_blocks, measurement_model
from pipeline.calibration.estimate import estimate, register_points
from pipeline.core.config import quick_config
from pipeline.core.errors import ConfigError, DataFileError, InfeasibleError, PipelineError, SolverError
from pipeline.quality import QualityGates
from pipeline.robot.instruments import tracker_visibility
from pipeline.robot.model import RobotModel
from pipeline.run.runner import run_pipeline
from pipeline.sim.truth import RealRobot, TruthConfig


@pytest.fixture(scope="session")
def robot():
    return RobotModel.load("rx130l")


@pytest.fixture(scope="session")
def mm(robot):
    return em.MeasurementModel(robot)


def _cfg(**kw):
    # no design table: it is computed last (no later draw of the Generator) and checked on the runner's
    # quick-profile run below and in test_design_task_space.py
    base = dict(candidates="random", n_random_candidates=800, n_configurations=40, n_heldout=1000, figures=False,
                design_table=False)
    base.update(kw)
    return st.Config(**base)


# ------------------------------------------------------------------ error model / identifiability
def test_identifiable_set_found_by_analysis(robot, mm):
    rep, basis = st.identify_parameter_set(robot, mm, st.Config(), np.random.default_rng(0))
    names = rep.identifiable_names
    # position-only data of a 6R arm with unknown tracker pose and reflector offset:
    # 4 per joint - 4 (axis 1 into the tracker pose) - 2 (axis 6 into the reflector) + 6 + 3 = 27
    assert rep.rank == 27 and len(names) == 27 and basis.shape == (mm.n, 27)
    assert all(f"tracker.{c}" in names for c in ("dx", "dy", "dz", "rx", "ry", "rz"))
    assert all(f"reflector.{c}" in names for c in ("dx", "dy", "dz"))
    assert not any(n.startswith(("base.", "tool.")) for n in names)
    # the dropped ones are explained: base vs tracker redundancy, joint-1 offset in the tracker yaw
    assert "tracker.rz" in [n for n, _ in rep.combined["j1.dq"]]
    assert "tracker.dx" in [n for n, _ in rep.combined["base.dx"]]
    assert any(a.startswith("base.") or b.startswith("base.") for a, b, _ in rep.correlated_pairs)
    assert "identifiable" in rep.markdown()
    # the same rank with the modified-DH + Hayati model
    rep2, basis2 = st.identify_parameter_set(robot, mm, st.Config(error_model="mdh_hayati"),
                                             np.random.default_rng(0))
    assert rep2.rank == 27 and any(n.endswith(".beta") for n in rep2.identifiable_names)
    # joint_axes in either error model: the placements' rotations and zero offsets, no length
    for error_model in ("se3", "mdh_hayati"):
        rep3, _ = st.identify_parameter_set(robot, mm, st.Config(error_model=error_model, parameters="joint_axes"),
                                            np.random.default_rng(0))
        kinematic = {n.split(".")[1] for n in rep3.identifiable_names if n.startswith("j")}
        assert kinematic and kinematic <= {"rx", "ry", "rz", "dq", "dalpha", "dtheta", "beta"}
        assert {"dq", "dalpha" if error_model == "mdh_hayati" else "rx"} <= kinematic


def test_numpy_kinematics_and_jacobian_match_pinocchio_and_casadi(robot, mm):
    ch = cd.chain_from_robot(robot)
    Q = em.random_configurations(robot, 30, np.random.default_rng(3))
    kin = cd.kinematics(ch, Q)
    assert np.allclose(kin.p_reflector, robot.positions(Q, "reflector"), atol=1e-12)
    assert np.allclose(cd.capsule_segments(ch, kin), robot.capsule_segments(Q), atol=1e-12)
    T0 = robot.tracker.transform_tracker_to_base * pin.exp6(np.array([0.01, -0.02, 0.03, 0.01, 0.02, -0.03]))
    Y, J = mm.jacobian(Q, np.zeros(mm.n), T0)
    Y2, J2 = cd.nominal_jacobian(ch, Q, T0)
    assert np.allclose(Y, Y2, atol=1e-12) and np.allclose(J, J2, atol=1e-10)


def test_filter_is_conservative_against_the_sensor_rule(robot):
    ch = cd.chain_from_robot(robot)
    Q = em.random_configurations(robot, 60000, np.random.default_rng(4))
    mask, counts = cd.filter_configurations(ch, Q)
    assert counts["feasible"] > 50 and counts["collision"] > 0 and counts["visibility"] > 0
    Qf = Q[mask]
    vis = tracker_visibility(robot, robot.tracker.transform_tracker_to_base, Qf)
    assert vis.visible.all()
    assert not any(robot.in_collision(q) for q in Qf[:50])


def test_grid_filter_matches_flat_filter_on_a_small_grid(robot):
    ch = cd.chain_from_robot(robot)
    Qg, flat, counts = cd.filter_grid(ch, 4)
    vals = cd.grid_values(ch, 4)
    allQ = np.stack(np.meshgrid(*vals, indexing="ij"), axis=-1).reshape(-1, 6)
    mask, _ = cd.filter_configurations(ch, allQ)
    assert counts["total"] == 4 ** 6
    assert np.array_equal(np.flatnonzero(mask), flat)
    assert np.allclose(allQ[mask], Qg)


# ------------------------------------------------------------------ estimation
def test_registration_recovers_a_rigid_transform():
    rng = np.random.default_rng(0)
    T = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3))
    Y = rng.normal(size=(20, 3))
    P = Y @ T.rotation.T + T.translation
    Te = register_points(Y, P)
    assert np.allclose(Te.homogeneous, T.homogeneous, atol=1e-10)


def test_lm_recovers_synthetic_errors_without_noise(robot, mm):
    rng = np.random.default_rng(5)
    rep, basis = st.identify_parameter_set(robot, mm, st.Config(), rng)
    xt = np.zeros(mm.n)
    xt[: 7 * 6] = rng.normal(size=42) * 5e-4
    xt[mm.sl_reflector] = rng.normal(size=3) * 1e-3
    Tt = robot.tracker.transform_tracker_to_base * pin.exp6(np.r_[rng.normal(size=3) * 0.05, rng.normal(size=3) * 0.03])
    Q = em.random_configurations(robot, 40, rng)
    Y = mm.predict(Q, xt, Tt)
    est = estimate(mm, Q, Y, np.full(len(Q), 1e-5), basis)
    Qh = em.random_configurations(robot, 200, rng)
    err = np.linalg.norm(mm.predict(Qh, est.x, est.registration) - mm.predict(Qh, xt, Tt), axis=1)
    assert err.max() < 1e-8
    assert est.converged


def test_too_few_or_degenerate_configurations_raise(robot, mm):
    rng = np.random.default_rng(6)
    _, basis = st.identify_parameter_set(robot, mm, st.Config(), rng)
    Q = em.random_configurations(robot, 40, rng)
    Q[:, 1:] = Q[0, 1:]  # only axis 1 moves: most parameters are not excited
    Y = mm.predict(Q, np.zeros(mm.n), robot.tracker.transform_tracker_to_base)
    with pytest.raises(SolverError, match="singular"):
        estimate(mm, Q, Y, np.full(len(Q), 1e-5), basis, source="degenerate.csv")
    with pytest.raises(SolverError, match="equations"):
        estimate(mm, Q[:5], Y[:5], np.full(5, 1e-5), basis)


def test_candidate_set_that_cannot_be_regular_raises(robot, mm):
    rng = np.random.default_rng(7)
    _, basis = st.identify_parameter_set(robot, mm, st.Config(), rng)
    ch = cd.chain_from_robot(robot)
    Q = np.tile(em.random_configurations(robot, 1, rng), (200, 1))
    Q[:, 0] = np.linspace(-1, 1, 200)
    cs = cd.build_candidate_set(ch, Q, basis, robot.tracker.transform_tracker_to_base)
    with pytest.raises(InfeasibleError, match="cannot make the information matrix regular"):
        ds.remove_and_replace(cs.G, ix.IndexSpec("O3"), 30, rng)


# ------------------------------------------------------------------ CSV input
def _write(tmp_path, text):
    p = tmp_path / "meas.csv"
    p.write_text(text)
    return p


def test_csv_bad_inputs_name_file_and_problem(robot, tmp_path):
    head = "q1,q2,q3,q4,q5,q6,x,y,z\n"
    good = "0.1,0.2,0.3,0.1,0.2,0.3,1.0,2.0,0.5\n"
    cases = {
        "NaN": head + good + "0.1,0.2,nan,0.1,0.2,0.3,1.0,2.0,0.5\n",
        "columns": head + good + "0.1,0.2,0.3,0.1,0.2,1.0,2.0,0.5\n",
        "not a number": head + "0.1,0.2,abc,0.1,0.2,0.3,1.0,2.0,0.5\n",
        "need at least": head + good * 5,
        "expected columns": "a,b,c\n1,2,3\n",
        "empty": "",
    }
    for problem, text in cases.items():
        p = _write(tmp_path, text)
        with pytest.raises(DataFileError) as exc:
            ms.read_csv(p, robot, min_rows=27)
        assert str(p) in str(exc.value)
        assert problem in str(exc.value) or (problem == "columns" and "columns" in str(exc.value))
    with pytest.raises(DataFileError, match="does not exist"):
        ms.read_csv(tmp_path / "missing.csv", robot)


def test_bad_csv_through_runner_writes_nothing(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n" + "0.1,0.2,0.3,0.1,0.2,0.3,1.0,2.0,nan\n" * 30)
    cfg = quick_config(**{"stages": ["model", "calibration"], "name": "badcsv",
                          "calibration.measurements_csv": str(bad)})
    with pytest.raises(PipelineError, match="bad.csv"):
        run_pipeline(cfg, out_root=tmp_path / "runs", log=lambda m: None)
    assert not (tmp_path / "runs" / "badcsv" / "calibration").exists()


def test_csv_round_trip_gives_the_same_calibration(robot, tmp_path):
    real = RealRobot.create(robot, 11)
    rng = np.random.default_rng(11)
    mmod = em.MeasurementModel(robot)
    _, basis = st.identify_parameter_set(robot, mmod, st.Config(), rng)
    ch = cd.chain_from_robot(robot)
    Q, _ = cd.random_candidates(ch, 60, rng)
    meas = ms.measure_simulated(real, Q, rng)
    path = ms.write_csv(tmp_path / "m.csv", meas)
    back = ms.read_csv(path, robot, min_rows=basis.shape[1])
    assert np.allclose(back.Q, meas.Q) and np.allclose(back.Y, meas.Y)
    e1 = estimate(mmod, meas.Q, meas.Y, meas.sigma_m, basis)
    e2 = estimate(mmod, back.Q, back.Y, back.sigma_m, basis)
    assert np.allclose(back.sigma_m, meas.sigma_m, rtol=1e-4)  # noise model vs sensor sigma
    assert np.allclose(e1.x, e2.x, atol=1e-8)


def test_a_simulated_record_reads_back_as_measured(robot, tmp_path):
    """The measurement and validation files of a simulated record hold the tracker's readings, in
    order (fit first, from one random stream), as the stage reads them."""
    real = RealRobot.create(robot, 5)
    Q, _ = cd.random_candidates(cd.chain_from_robot(robot), 30, np.random.default_rng(5))
    fit, validation = ms.write_simulated_record(real, Q[:20], Q[20:], tmp_path, np.random.default_rng(6))
    rng = np.random.default_rng(6)
    for path, Qs in ((fit, Q[:20]), (validation, Q[20:])):
        measured, back = ms.measure_simulated(real, Qs, rng), ms.read_csv(path, robot, min_rows=1)
        assert len(back) == len(measured) > 0
        assert np.allclose(back.Q, measured.Q) and np.allclose(back.Y, measured.Y, atol=1e-12)


# ------------------------------------------------------------------ end-to-end targets
def test_csv_with_a_utf8_bom_reads_like_without(robot, tmp_path):
    """Excel's "CSV UTF-8" starts with a byte-order mark, invisible in a terminal."""
    rng = np.random.default_rng(3)
    Q, _ = cd.random_candidates(cd.chain_from_robot(robot), 5, rng)
    meas = ms.measure_simulated(RealRobot.create(robot, 3), Q, rng)
    plain = ms.write_csv(tmp_path / "plain.csv", meas)
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    a, b = ms.read_csv(plain, robot), ms.read_csv(bom, robot)
    assert np.array_equal(a.Q, b.Q) and np.array_equal(a.Y, b.Y)


def _check_targets(summary):
    assert summary["n_configurations"] <= 50
    assert summary["heldout_n_poses"] >= 1000
    assert summary["heldout_rms_position_error_before_m"] > 5e-4           # millimetres before
    assert summary["heldout_rms_position_error_after_m"] <= 3 * summary["noise_total_sigma_m"]
    ratio = summary["heldout_rms_position_error_after_m"] / summary["predicted_rms_position_error_m"]
    assert 1 / 1.5 <= ratio <= 1.5


def _truth_gap(robot_a, robot_b, Q, frame="reflector"):
    """RMS position difference of ``frame`` after the rigid alignment of the reflector points (the
    base frame is only defined up to the unknown tracker pose)."""
    Pa, Pb = robot_a.positions(Q, "reflector"), robot_b.positions(Q, "reflector")
    T = register_points(Pa, Pb)
    Fa, Fb = robot_a.positions(Q, frame), robot_b.positions(Q, frame)
    return float(np.sqrt(np.mean(np.sum((Fa @ T.rotation.T + T.translation - Fb) ** 2, axis=1))))


def test_quick_profile_stage_through_runner(tmp_path):
    # one pass: the second pass through the runner is covered by test_second_pass.py (and tests/run/test_second_pass.py)
    cfg = quick_config(**{"stages": ["model", "calibration"], "name": "calq", "calibration.second_pass": "never"})
    cfg.sections["truth"] = TruthConfig.ideal()   # geometric-only truth: the geometric targets hold
    res = run_pipeline(cfg, out_root=tmp_path, log=lambda m: None)
    out = res.outputs["calibration"]
    s = out.summary
    for key in ("n_configurations", "selection_method", "index_name", "index_value",
                "heldout_rms_position_error_before_m", "heldout_rms_position_error_after_m",
                "heldout_max_position_error_after_m", "predicted_rms_position_error_m", "tracker_noise_sigma_m",
                "noise_total_sigma_m", "noise_sensor_sigma_m"):
        assert key in s
    _check_targets(s)
    assert s["n_configurations_not_visible"] == s["n_configurations_commanded"] - s["n_configurations"] >= 0
    assert s["selection_method"] != "user file" and s["validation_source"] == "simulated tracker (held-out)"
    stage_report = (tmp_path / "calq" / "calibration" / "report.md").read_text()
    assert "visible to the tracker" in stage_report and "no held-out validation" not in stage_report
    # the design table (the other simulated runs of these tests leave it out)
    assert s["design_table"] and "### Design table" in stage_report
    assert out.arrays["configurations_selected"].shape == (s["n_configurations"], 6)
    stage_dir = tmp_path / "calq" / "calibration"
    assert (stage_dir / "heldout_errors.png").exists() and (stage_dir / "index_history.png").exists()
    json.loads((stage_dir / "summary.json").read_text())
    # the saved calibrated robot is much closer to the truth than the nominal one
    nominal = RobotModel.load("rx130l")
    calibrated = RobotModel.load(stage_dir / "robot")
    truth = RealRobot.create(nominal, cfg.seed, TruthConfig.ideal()).truth
    Q = em.random_configurations(nominal, 300, np.random.default_rng(0))
    assert _truth_gap(calibrated, truth, Q) < 0.1 * _truth_gap(nominal, truth, Q)
    # rigid tool: the TCP moved with the identified reflector offset (tool rotations stay unobservable)
    assert _truth_gap(calibrated, truth, Q, "tcp") < 0.1 * _truth_gap(nominal, truth, Q, "tcp")


@pytest.mark.parametrize("name,seed", [("staubli_tx40", 3), pytest.param("rx130l", 4, marks=pytest.mark.slow)])
def test_targets_hold_for_other_robots_and_seeds(name, seed):
    """The targets of the quick run on another arm and seed. The RX130L at seed 4 is a slow check:
    the fast suite calibrates the RX130L through the runner (quick profile, seed 1) and the TX40 here;
    the slow twin adds a second seed of the RX130L."""
    robot = RobotModel.load(name)
    real = RealRobot.create(robot, seed, TruthConfig.ideal())
    cfg = _cfg()
    out = st.calibrate(robot, real, cfg, np.random.default_rng(seed))
    _check_targets(st.summary_of(out, cfg))


def test_too_small_candidate_set_through_runner_writes_nothing(tmp_path):
    # fewer random candidates than configurations: caught when the configuration is loaded
    with pytest.raises(ConfigError, match="calibration.n_random_candidates: 5 feasible random candidates"):
        quick_config(**{"stages": ["model", "calibration"], "calibration.n_random_candidates": 5})
    # a grid with too few feasible points: found while running, before the stage writes anything
    cfg = quick_config(**{"stages": ["model", "calibration"], "name": "fewcand",
                          "calibration.candidates": "grid", "calibration.grid_per_axis": 3})
    with pytest.raises(PipelineError, match="calibration.grid_per_axis: only .* 40 configurations asked for"):
        run_pipeline(cfg, out_root=tmp_path / "runs", log=lambda m: None)
    assert not (tmp_path / "runs" / "fewcand" / "calibration").exists()


@pytest.mark.parametrize("key,value,problem", [("index_name", "O9", "index_name"),
                                               ("selection_method", "greedy", "selection_method"),
                                               ("n_configurations", 0, "n_configurations"),
                                               ("error_model", "dh", "error_model")])
def test_bad_config_values_name_the_field(key, value, problem):
    with pytest.raises(ConfigError, match=f"calibration.{problem}"):
        quick_config(**{f"calibration.{key}": value})


# ------------------------------------------------------------------ user files: no simulated robot
class _NoHiddenRobot:
    """Stand-in for the RealRobot: any use of it fails the test."""

    def __getattr__(self, name):
        raise AssertionError(f"the hidden robot was used (attribute {name!r}) although the data come from files")


class _Ctx:
    """Stage context as the runner hands it to a stage fed from files: no hidden robot."""

    def __init__(self, config, robot, seed):
        self.config, self.robot, self.rng, self.progress = config, robot, np.random.default_rng(seed), None
        self.run = SimpleNamespace(accept_poor=False)
        self.real = None


@pytest.fixture(scope="session")
def tracker_files(robot, tmp_path_factory):
    """Calibration and validation CSVs written from simulated measurements of one hidden robot."""
    real = RealRobot.create(robot, 21, TruthConfig.ideal())
    rng = np.random.default_rng(21)
    ch = cd.chain_from_robot(robot)
    Q, _ = cd.random_candidates(ch, 45, rng)
    meas = ms.measure_simulated(real, Q, rng)
    Qv, _ = cd.random_candidates(ch, 150, rng)
    held = ms.measure_simulated(real, Qv, rng)
    d = tmp_path_factory.mktemp("tracker")
    return ms.write_csv(d / "calibration.csv", meas), ms.write_csv(d / "validation.csv", held), len(meas), len(held)


HELDOUT_KEYS = ("heldout_n_poses", "heldout_rms_position_error_before_m", "heldout_rms_position_error_after_m",
                "heldout_mean_position_error_after_m", "heldout_max_position_error_after_m",
                "heldout_max_position_error_before_m", "actual_over_predicted", "rms_after_over_sigma")


def test_measurement_file_without_validation_file_has_no_heldout_validation(robot, tracker_files):
    path, _, n_meas, _ = tracker_files
    cfg = _cfg(measurements_csv=str(path), n_heldout=200, identifiability_samples=60, index_name="O3",
               parameters="all")
    res = st.run(_Ctx(cfg, robot, 5))
    s = res.summary
    assert all(s[k] is None for k in HELDOUT_KEYS)
    assert s["validation_source"] is None
    assert "no held-out validation: give calibration.validation_csv" in res.report_md
    assert "Table 2" not in res.report_md
    assert not any(k.startswith("heldout_") for k in res.arrays)
    json.dumps(s)  # nulls, no NaN objects
    # the design fields describe the user's own configurations
    assert s["selection_method"] == "user file" and s["n_configurations"] == n_meas
    assert s["n_candidates"] is None and s["selection_time_s"] is None and s["n_configurations_not_visible"] is None
    back = ms.read_csv(path, robot)
    mm = measurement_model(robot, cfg)   # the design basis: geometric and compliance columns
    _, basis = st.identify_parameter_set(robot, mm, cfg, np.random.default_rng(0))
    basis = design_basis(mm, basis)
    T = pin.SE3(res.arrays["transform_tracker_to_base"])
    G = design_blocks(mm, back.Q, basis, T, back.payload_mounted).reshape(-1, basis.shape[1])
    assert s["index_value"] == pytest.approx(ix.evaluate(ix.IndexSpec("O3"), G.T @ G, len(back.Q)), rel=1e-6)
    assert s["index_value"] < ix.evaluate(ix.IndexSpec("O3"), 2 * G.T @ G, len(back.Q))  # not a constant
    # fit residuals and the covariance prediction are still reported
    sigma = float(np.sqrt(np.mean(back.sigma_m ** 2)))
    assert s["fit_rms_residual_after_m"] < 3 * sigma < s["fit_rms_residual_before_m"]
    assert 0.2 < s["chi2_per_dof"] < 5
    assert sigma < s["predicted_rms_position_error_m"] < 5 * sigma


def test_measurement_and_validation_files_validate_on_the_validation_file(robot, tracker_files):
    path, vpath, n_meas, n_val = tracker_files
    # the files come from TruthConfig.ideal(): the nominal masses are exact, no gravity-model uncertainty
    cfg = _cfg(measurements_csv=str(path), validation_csv=str(vpath), identifiability_samples=60,
               gravity_model_relative_sigma=0.0, gravity_model_com_sigma_m=0.0)
    out = st.calibrate(robot, _NoHiddenRobot(), cfg, np.random.default_rng(6))
    s = st.summary_of(out, cfg)
    assert s["heldout_n_poses"] == n_val and s["validation_source"] == str(vpath)
    assert out.prediction is None and out.validation["source"] == str(vpath)
    # the held-out errors are those of the file's poses: nominal model mm-level, calibrated at noise level
    assert s["heldout_rms_position_error_before_m"] > 5e-4
    assert s["heldout_rms_position_error_after_m"] <= 3 * s["noise_total_sigma_m"]
    assert 1 / 1.5 <= s["actual_over_predicted"] <= 1.5
    # the stage's result and quality gates of this outcome, as st.run makes them (its calibration is
    # this one: the same files, settings and seed)
    res = st.outputs(out, cfg, robot, time.perf_counter())
    gates = QualityGates(st.NAME)
    cg.check_gates(gates, res.summary, cfg)
    gates.finish(res)   # raises on a failed gate
    assert "Held-out validation" in res.report_md and str(vpath) in res.report_md
    assert "no held-out validation" not in res.report_md
    # the held-out gross-error test may reject a reading of clean data at its 99.9 % level, rarely
    rejected = res.summary["heldout_n_rejected"]
    assert rejected <= 2 and len(res.arrays["heldout_errors_after_m"]) == n_val - rejected


def test_report_says_how_many_selected_poses_were_not_visible(robot):
    Q = np.zeros((50, 6))
    meas = ms.Measurements(Q[:48], np.zeros((48, 3)), np.ones(48), "simulated tracker", None, 50, Q[48:])
    out = SimpleNamespace(measurements=meas, selection=object())
    text = st.visibility_sentence(out, robot)
    deg = np.rad2deg(robot.tracker.max_incidence_rad)
    assert f"2 of 50 selected poses were not visible to the tracker (beam blocked or incidence > {deg:.0f}°)" in text
    assert st.n_not_visible(out) == 2
