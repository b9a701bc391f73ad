"""The identification stage in the quick profile, scored against the hidden robot (tests may
read the truth), and its handling of bad input."""

from __future__ import annotations

import json
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.core.config import CONFIGS_DIR, load_config, to_plain
from pipeline.core.errors import DataFileError, PipelineError, QualityGateError
from pipeline.identification import fourier, stage
from pipeline.identification.estimate import is_physically_consistent
from pipeline.identification.measure import load_joint_csv
from pipeline.robot.model import RobotModel
from pipeline.run import stages as stage_registry
from pipeline.run.runner import run_pipeline

from .helpers import NO_LOAD_FRICTION, quick_context, true_base

SUMMARY_KEYS = (
    "n_base_parameters", "cond_optimized", "cond_random_median", "validation_torque_rms_Nm",
    "torque_noise_sigma_Nm", "fraction_within_3sigma", "physically_consistent", "base_parameter_set",
    "quality_gates",
)
TX40_KEYS = ("tx40_heldout_rms_Nm_ols", "tx40_heldout_rms_Nm_physical", "tx40_physically_consistent")


#: session fixtures that take seconds and serve several tests: their tests run on one pytest-xdist
#: worker, so each is built once per ``make test`` (tests/conftest.py, pytest_collection_modifyitems)
SHARED_COSTLY_FIXTURES = frozenset({"quick_run"})


@pytest.fixture(scope="session")   # built once per worker, also when pytest-xdist comes back to this file
def quick_run(tmp_path_factory):
    ctx, real = quick_context(tmp_path_factory.mktemp("id"), truth=NO_LOAD_FRICTION)   # Stribeck, no load term
    return ctx, real, stage.run(ctx)


def test_summary_has_the_documented_keys_and_is_json(quick_run):
    _, _, res = quick_run
    for key in SUMMARY_KEYS:
        assert key in res.summary, key
    json.dumps(res.summary)
    json.dumps(res.data)
    assert 0.0 <= res.summary["fraction_within_3sigma"] <= 1.0  # scored after the estimate is final
    assert res.arrays["trajectory_excitation_q"].shape == (len(res.arrays["trajectory_excitation_t"]), 6)
    assert set(res.figures) >= {"convergence", "parameters", "validation_torques"}
    # the TX40 record is not fitted inside the RX130L's identification (run_tx40: None = auto)
    assert "tx40_heldout" not in res.figures and not any(k in res.summary for k in TX40_KEYS)
    assert res.summary["quality_gates"]["passed"] and not res.summary["accepted_poor"]


def test_tx40_record_only_for_the_tx40_or_when_asked():
    rx, tx = RobotModel.load("rx130l"), RobotModel.load("staubli_tx40")
    assert not stage.tx40_wanted(stage.Config(), rx)
    assert stage.tx40_wanted(stage.Config(), tx)
    assert stage.tx40_wanted(stage.Config(run_tx40=True), rx)
    assert not stage.tx40_wanted(stage.Config(run_tx40=False), tx)
    cfg = stage.Config()
    cfg.tx40.data_dir = "my/tx40/record"
    assert stage.tx40_wanted(cfg, rx)


def test_excitation_beats_random(quick_run):
    _, _, res = quick_run
    s = res.summary
    assert s["cond_optimized"] < min(res.arrays["cond_random"])   # better than the best random one
    assert s["excitation"].startswith("optimised") and s["excitation_fallback_reason"] is None
    assert all(st["status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
               for st in res.data["excitation"]["starts"] if st["cond_end"] == s["cond_optimized"])
    # one structural base set (decided on the nominal model) for design and fit
    assert s["n_base_parameters"] == s["n_base_parameters_structural"] > 30


def test_fitted_condition_number_within_2x_of_the_design(quick_run):
    _, _, res = quick_run
    s = res.summary
    assert 0.5 * s["cond_optimized"] <= s["cond_base_regressor_data"] <= 2.0 * s["cond_optimized"]


def test_base_parameters_within_three_sigma_of_the_truth(quick_run):
    _, real, res = quick_run
    beta_true = true_base(real, res.arrays["base_matrix_E"])
    z = (res.arrays["base_beta"] - beta_true) / res.arrays["base_sigma"]
    assert np.mean(np.abs(z) <= 3) >= 0.95
    assert res.summary["fraction_within_3sigma"] == pytest.approx(np.mean(np.abs(z) <= 3))
    assert 0.5 < np.sqrt(np.mean(z**2)) < 2.0  # sigmas neither optimistic nor pessimistic


def test_validation_torques_at_noise_level(quick_run):
    _, _, res = quick_run
    rms = np.asarray(res.summary["validation_torque_rms_Nm"])
    sigma = np.asarray(res.summary["torque_noise_sigma_Nm"])
    assert np.all(rms <= 1.3 * sigma)


def test_handed_on_robot_is_physical_and_round_trips(quick_run, tmp_path):
    ctx, real, res = quick_run
    robot = res.robot
    assert res.summary["physically_consistent"]
    p = res.arrays["standard_parameters_physical"]
    for i in range(6):
        assert is_physically_consistent(p[10 * i : 10 * i + 10])
    act = robot.actuation
    assert np.all(act.rotor_inertia_kgm2 > 0) and np.all(act.viscous_Nms_rad > 0) and np.all(act.coulomb_Nm > 0)
    # closer to the truth's torques than the nominal model on random states
    rng = np.random.default_rng(0)
    err_id, err_nom = [], []
    for _ in range(50):
        q = rng.uniform(robot.limits.lower_rad, robot.limits.upper_rad)
        v, a = rng.normal(size=(2, 6))
        tau = real.truth.inverse_dynamics(q, v, a)
        err_id.append(robot.inverse_dynamics(q, v, a) - tau)
        err_nom.append(ctx.robot.inverse_dynamics(q, v, a) - tau)
    assert np.sqrt(np.mean(np.square(err_id))) < 0.5 * np.sqrt(np.mean(np.square(err_nom)))
    back = RobotModel.load(robot.save(tmp_path / "robot"))
    np.testing.assert_allclose(back.model.armature, robot.model.armature)
    np.testing.assert_allclose(back.actuation.viscous_Nms_rad, act.viscous_Nms_rad)


def _write_csv(path, t, q, tau):
    header = "t," + ",".join(f"q{i + 1}" for i in range(6)) + "," + ",".join(f"tau{i + 1}" for i in range(6))
    np.savetxt(path, np.column_stack([t, q, tau]), delimiter=",", header=header, comments="")


#: problem -> words the error must contain (file lines: header = line 1, q[k] is on line k + 2)
BAD_FILES = {
    "nan": ("q3", "line 125"),
    "short_row": ("line 101", "12 values, expected 13"),
    "too_few": ("samples", "too few"),
    "outside_limits": ("q1", "line 202"),
    "not_a_number": ("line 52", "tau2", "'abc' is not a number"),
    "header_only": ("no data rows",),
    "missing_column": ("missing columns", "tau6"),
    "time_not_increasing": ("t", "line 12"),
}


def _bad_record(tmp_path, problem):
    t = np.arange(400) * 0.01
    q = 0.1 * np.sin(np.outer(t, np.arange(1, 7)))
    tau = np.cos(np.outer(t, np.arange(1, 7)))
    path = tmp_path / "record.csv"
    if problem == "nan":
        q[123, 2] = np.nan
    if problem == "too_few":
        t, q, tau = t[:40], q[:40], tau[:40]
    if problem == "outside_limits":
        q[200, 0] = 4.0
    if problem == "time_not_increasing":
        t[10] = t[9]
    _write_csv(path, t, q, tau)
    lines = path.read_text().splitlines()
    if problem == "short_row":
        lines[100] = ",".join(lines[100].split(",")[:-1])
    if problem == "not_a_number":
        cells = lines[51].split(",")
        cells[8] = "abc"  # t, q1..q6, tau1, tau2
        lines[51] = ",".join(cells)
    if problem == "header_only":
        lines = lines[:1]
    if problem == "missing_column":
        lines = [",".join(ln.split(",")[:-1]) for ln in lines]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("problem", sorted(BAD_FILES))
def test_bad_data_files_raise_and_write_nothing(tmp_path, problem):
    path = _bad_record(tmp_path, problem)
    ctx, _ = quick_context(tmp_path / "run", overrides={
        "data_file": str(path), "run_tx40": False,
        "excitation": {"n_samples": 30, "n_starts": 1, "n_random": 2, "max_iter": 3}})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # e.g. numpy's "input contained no data"
        with pytest.raises(DataFileError) as info:
            stage.run(ctx)
        message = str(info.value)
        assert "record.csv" in message
        for word in BAD_FILES[problem]:
            assert word in message, (word, message)
        assert "usecols" not in message
        # the runner's early check gives the same error
        with pytest.raises(DataFileError) as early:
            stage.check(ctx.config, ctx.robot)
    assert early.value.one_line() == message
    assert not any(ctx.out_dir.iterdir())


def test_infeasible_excitation_limits_raise(tmp_path):
    # 5 % of the torque limits: no excitation moves the arm enough; the stage stops naming
    # identification.excitation (no feasible centre, or a random start the motion gate refuses)
    # the quick profile's small excitation problem with the margin changed and fewer random trajectories
    # and IPOPT iterations (a bare {"torque_margin": ...} section would fall back to the default-profile
    # excitation sizes): whatever IPOPT does within 5 % of the limits, the arm hardly moves
    quick_excitation = to_plain(load_config(CONFIGS_DIR / "quick.yaml").identification.excitation)
    ctx, _ = quick_context(tmp_path, overrides={"run_tx40": False, "excitation": {
        **quick_excitation, "torque_margin": 0.05, "n_random": 2, "max_iter": 5}})
    with pytest.raises(PipelineError, match="identification.excitation"):
        stage.run(ctx)
    assert not any(ctx.out_dir.iterdir())


def test_bad_config_values(tmp_path):
    ctx, _ = quick_context(tmp_path, overrides={"sample_time_s": 0.003})
    with pytest.raises(PipelineError, match="does not divide"):
        stage.run(ctx)


class _NoHiddenRobot:
    """Stands for ``ctx.real`` in user-data mode: any use of the hidden robot fails the test."""

    def __getattr__(self, name):
        raise AssertionError(f"the stage read ctx.real.{name} in user-data mode")


def test_stage_runs_on_a_joint_csv_record_and_a_failed_gate_raises(tmp_path):
    """A user record (CSV, joint side) instead of the simulated experiment: no excitation is
    designed, validation is on the record's held-out tail, the hidden robot is never used.

    The same run is held to a validation threshold no model can meet (0.2 x the noise; the gates only
    read the finished result, so the result is the one an ordinary threshold hands on): the stage
    fails naming the figure and threshold, writes nothing, and the unaccepted result rides on the
    error (the record's checks below read it there); --accept-poor: test_gates.py."""
    # the linear friction model: the record's path is what this test is about (the Stribeck and load-friction
    # fits on a record's held-out tail: the TIAGo record test, test_tiago_record.py)
    ctx, real = quick_context(tmp_path / "run", overrides={"run_tx40": False, "friction_model": "viscous_coulomb",
                                                           "max_validation_rms_over_noise": 0.2})
    ctx.run.accept_poor = False
    robot = ctx.robot
    limits = fourier.ExcitationLimits.from_robot(robot, 0.95, 0.95, 0.95, 0.8, 0.05, 0.02)
    traj = fourier.random_feasible_trajectories(robot, limits, 5, 0.1, 1, np.random.default_rng(7))[0]
    t = np.arange(2 * 5000) * 0.002
    meas = real.execute_joint_trajectory(t, *traj.evaluate(t), np.random.default_rng(8))
    path = tmp_path / "record.csv"
    _write_csv(path, t, meas.q_rad, meas.tau_Nm)
    ctx.config.data_file = str(path)
    ctx.real = _NoHiddenRobot()
    with pytest.raises(QualityGateError) as info:
        stage.run(ctx)
    msg = str(info.value)
    assert "validation_rms_over_noise" in msg and "0.2" in msg and "--accept-poor" in msg
    assert not any(ctx.out_dir.iterdir())
    res = info.value.result
    assert res is not None and res.summary["quality_gates"]["passed"] is False
    s = res.summary
    assert s["data_source"] == str(path)
    assert s["physically_consistent"]
    # no excitation design: no optimised/random condition numbers, no convergence figure
    assert s["cond_optimized"] is None and s["cond_random_median"] is None
    assert s["excitation"] == "from the user's record"
    assert "from the user's record" in res.report_md and "optimised vs" not in res.report_md
    assert "convergence" not in res.figures and "excitation_coefficients" not in res.arrays
    # the condition number is the one of the user's data
    assert 1 < s["cond_base_regressor_data_structural"] <= s["cond_base_regressor_data"]
    # validation on the held-out tail of the record (30 %), not on the simulated ISO path
    assert "held-out" in s["validation_trajectory"]
    n_val = res.arrays["validation_tau_measured_Nm"].shape[0]
    assert n_val == s["n_samples_fit"] - int(0.7 * s["n_samples_fit"])
    t_val = res.arrays["validation_t_s"]
    assert t_val[0] >= 0.69 * s["n_samples_fit"] * np.median(np.diff(t_val))  # the tail of the record
    sigma = np.asarray(meas.tau_sigma_Nm)
    # the fit residual of the low-passed torques is below the raw noise
    assert s["fit_rms_Nm_wls"] < np.sqrt(np.mean(sigma**2))
    rms = np.asarray(s["validation_torque_rms_Nm"])
    assert np.all(rms <= 1.5 * sigma)
    # noise from the residuals (low-passed torques: well below the raw sensor sigma), and the
    # held-out error at that level
    noise = np.asarray(s["torque_noise_sigma_Nm"])
    assert "residuals" in s["torque_noise_source"]
    assert np.all(noise < sigma)
    assert np.all(rms < 1.5 * noise)
    # the viewer replays the user's (processed) trajectory: it lies on the recorded path
    q_rep, t_rep = res.arrays["trajectory_excitation_q"], res.arrays["trajectory_excitation_t"]
    assert q_rep.shape == (len(t_rep), 6) and t_rep[0] == 0 and t_rep[-1] > 0.8 * t[-1]
    gap = [np.min(np.max(np.abs(meas.q_rad - qk), axis=1)) for qk in q_rep[::40]]
    assert max(gap) < 0.01
    assert np.ptp(q_rep, axis=0).min() > 0.05


def test_motor_side_csv_is_converted_with_the_gear_matrix(tmp_path):
    tx40 = RobotModel.load("staubli_tx40")
    K = tx40.actuation.gear_matrix
    rng = np.random.default_rng(9)
    q, tau = rng.normal(size=(2, 50, 6))
    t = np.arange(50) * 0.01
    _write_csv(tmp_path / "motor.csv", t, q @ K.T, np.linalg.solve(K.T, tau.T).T)
    rec = load_joint_csv(tmp_path / "motor.csv", tx40, side="motor")
    np.testing.assert_allclose(rec.q_rad, q, atol=1e-12)
    np.testing.assert_allclose(rec.tau_Nm, tau, atol=1e-12)


def test_runner_leaves_no_stage_directory_on_bad_input(tmp_path, monkeypatch):
    """Through the runner (calibration left out of the dependencies to keep this fast)."""
    path = tmp_path / "record.csv"
    t = np.arange(400) * 0.01
    q = 0.1 * np.sin(np.outer(t, np.arange(1, 7)))
    q[10, 3] = np.nan
    _write_csv(path, t, q, np.cos(np.outer(t, np.arange(1, 7))))
    wrapper = SimpleNamespace(NAME=stage.NAME, DEPENDS=("model",), Config=stage.Config, run=stage.run,
                              __file__=stage.__file__)
    cfg = load_config(CONFIGS_DIR / "quick.yaml", stages=["identification"],
                      values={"identification.data_file": str(path), "identification.run_tx40": False})
    registry = {"model": stage_registry.STAGES["model"], "identification": wrapper}
    monkeypatch.setattr(stage_registry, "STAGES", registry)
    with pytest.raises(DataFileError, match="record.csv"):
        run_pipeline(cfg, out_root=tmp_path / "runs")
    run_dir = tmp_path / "runs" / cfg.name
    assert (run_dir / "model" / "summary.json").exists()
    assert not (run_dir / "identification").exists()
    assert not [p for p in run_dir.iterdir() if "identification" in p.name]
