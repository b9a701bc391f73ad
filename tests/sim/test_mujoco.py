"""The hidden arm in MuJoCo (truth.engine: mujoco): truth read back, the servo loop, a short identification."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from pipeline.cli import main as cli_main
from pipeline.core.errors import ConfigError
from pipeline.exchange.motion import SampledMotion
from pipeline.exchange.motion_csv import read_joint_states_csv, write_motion_csv
from pipeline.exchange.ros2_bag import read_points
from pipeline.identification.estimate import wls
from pipeline.identification.measure import JointRecord, process_periodic
from pipeline.identification.regressor import RegressorModel, base_parameters
from pipeline.identification.validate import truth_scores
from pipeline.robot.model import RobotModel
from pipeline.run.stage_run import make_real
from pipeline.run.stages import load_config
from pipeline.sim.drive import DriveSettings, drive_gains, drive_inputs
from pipeline.sim.mujoco_robot import MujocoRealRobot, create_hidden_robot
from pipeline.sim.player import play_file, tracker_path
from pipeline.sim.truth import RealRobot, TruthConfig


@pytest.fixture(scope="module")
def tx40() -> RobotModel:
    return RobotModel.load("staubli_tx40")


@pytest.fixture(scope="module")
def mj(tx40: RobotModel) -> MujocoRealRobot:
    real = create_hidden_robot(tx40, 5, TruthConfig(engine="mujoco"))
    assert isinstance(real, MujocoRealRobot)
    return real


def test_truth_read_back_from_mjmodel_equals_what_was_set(tx40: RobotModel, mj: MujocoRealRobot) -> None:
    drawn = RealRobot.create(tx40, 5, TruthConfig(engine="mujoco"))
    # the same deviations as the own simulator draws for this seed, read back from the compiled model
    assert np.allclose(mj.dynamic_parameters, drawn.dynamic_parameters, rtol=1e-12, atol=1e-12)
    assert not np.allclose(mj.dynamic_parameters, RealRobot.create(tx40, 6).dynamic_parameters)
    for placed, truth in zip(mj.joint_placements, list(drawn.truth.model.jointPlacements)[1:], strict=True):
        assert np.allclose(placed.homogeneous, truth.homogeneous, atol=1e-12)
    rng = np.random.default_rng(0)
    Q = rng.uniform(tx40.limits.lower_rad, tx40.limits.upper_rad, (20, tx40.nq))
    for frame in ("tcp", "reflector", "flange"):
        assert np.allclose(mj.plant.measure_tcp(Q, frame), drawn.truth.positions(Q, frame), atol=1e-12)
    # MuJoCo's own inverse dynamics in motion = the truth's with dry friction (frictionloss is a soft
    # constraint: its full value once the joint slides at more than a few mrad/s)
    m, d = mj.arm.model, mujoco.MjData(mj.arm.model)
    q, a = Q[3], rng.normal(size=tx40.nq)
    v = rng.choice([-1.0, 1.0], tx40.nq) * rng.uniform(0.5, 2.0, tx40.nq)
    d.qpos[mj.arm.qpos_address], d.qvel[mj.arm.dof_address], d.qacc[mj.arm.dof_address] = q, v, a
    mujoco.mj_inverse(m, d)
    model = drawn.truth.model
    rigid = pin.rnea(model, model.createData(), q, v, a) + drawn.truth.actuation.viscous_Nms_rad * v
    dry = drawn.truth.actuation.coulomb_Nm * np.sign(v)
    assert np.allclose(d.qfrc_inverse[mj.arm.dof_address], rigid + dry, rtol=1e-4, atol=1e-4)


def test_default_engine_is_the_own_plant_and_the_choice_is_checked(tx40: RobotModel) -> None:
    own = create_hidden_robot(tx40, 5)
    assert type(own) is RealRobot
    assert np.array_equal(own.dynamic_parameters, RealRobot.create(tx40, 5).dynamic_parameters)
    with pytest.raises(ConfigError, match="truth.engine"):
        TruthConfig(engine="bullet").validate()


def test_mujoco_arm_follows_a_move_under_the_servo_like_the_own_rigid_plant(tx40: RobotModel,
                                                                            mj: MujocoRealRobot) -> None:
    """The same cascade (ServoLaw) and encoder noise on both engines: the arms move alike; what is left
    is the dry friction (MuJoCo's frictionloss constraint against the own tanh) and the integrators."""
    own = RealRobot.create(tx40, 5, TruthConfig.ideal())
    s = DriveSettings(settle_time_s=0.02)
    t = np.arange(0.0, 0.2, s.sample_time_s)
    shape = 0.5 - 0.5 * np.cos(np.pi * t / t[-1])
    rate = 0.5 * np.pi / t[-1] * np.sin(np.pi * t / t[-1])
    curvature = 0.5 * (np.pi / t[-1]) ** 2 * np.cos(np.pi * t / t[-1])
    q0, dq = np.array([0.1, -0.3, 1.2, 0.2, 0.5, 0.0]), np.array([0.3, 0.2, -0.2, 0.4, -0.3, 0.5])
    q, v, a = q0 + shape[:, None] * dq, rate[:, None] * dq, curvature[:, None] * dq
    tau = np.array([tx40.inverse_dynamics(*x) for x in zip(q, v, a, strict=True)])
    inputs = drive_inputs(t, q, v, tau, s)
    gains = drive_gains(tx40, q0, s)
    runs = [real.plant.run_servo(gains, s.sample_time_s, s.velocity_samples, s.measurement_delay_samples, s.alpha,
                                 inputs.q_d_fb, inputs.v_ff, inputs.tau_ff, inputs.q_d[0],
                                 np.random.default_rng(1), engine="python", measure_tcp=False)
            for real in (mj, own)]
    lag = [float(np.abs(r.q_meas - inputs.q_d).max()) for r in runs]
    assert max(lag) < 1e-2                      # both track the move (the lag: the nominal model's feedforward)
    assert abs(lag[0] - lag[1]) < 0.25 * max(lag)
    assert np.abs(runs[0].q_meas - runs[1].q_meas).max() < 0.25 * max(lag)


def test_short_identification_in_mujoco_scored_against_the_mjmodel(tx40: RobotModel, mj: MujocoRealRobot) -> None:
    """Two periods of a 1.5 s multi-sine on the MuJoCo arm: WLS base parameters within 3 sigma of the
    base parameters read from the mjModel, far off those of another seed's arm."""
    period, dt = 1.5, 4e-4
    t = np.arange(int(round(2 * period / dt))) * dt
    rng = np.random.default_rng(3)
    w = 2 * np.pi / period * np.array([1, 2, 3])
    amp = rng.uniform(0.1, 0.35, (3, tx40.nq)) / np.arange(1, 4)[:, None]
    phase = rng.uniform(0, 2 * np.pi, (3, tx40.nq))
    centre = np.array([0.0, 0.3, 1.4, 0.0, 0.6, 0.0])
    q = centre + np.einsum("hj,thj->tj", amp, np.sin(w[None, :, None] * t[:, None, None] + phase))
    v = np.einsum("hj,thj->tj", amp * w[:, None], np.cos(w[None, :, None] * t[:, None, None] + phase))
    a = -np.einsum("hj,thj->tj", amp * w[:, None] ** 2, np.sin(w[None, :, None] * t[:, None, None] + phase))
    meas = mj.execute_joint_trajectory(t, q, v, a, np.random.default_rng(4))
    act = tx40.actuation
    reg = RegressorModel(tx40.model, np.eye(tx40.nq), act.coulomb_smoothing_rad_s)
    base = base_parameters(reg, np.random.default_rng(0), lower=tx40.limits.lower_rad, upper=tx40.limits.upper_rad)
    data = process_periodic(JointRecord(meas.t_s, meas.q_rad, meas.tau_Nm, "mujoco"), reg, int(round(period / dt)),
                            8.0, 5)
    fit = wls(base.base_regressor(data.Y), data.y, tx40.nq)
    sigma = np.sqrt(np.diag(fit.covariance))
    scores = truth_scores(mj, base, fit.beta, sigma)
    assert scores["fraction_within_3sigma"] >= 0.9, scores["z"]
    other = truth_scores(RealRobot.create(tx40, 6), base, fit.beta, sigma)
    assert other["fraction_within_3sigma"] < scores["fraction_within_3sigma"]


def test_short_play_records_joint_states_and_a_tracker_reading_per_dwell(tmp_path) -> None:
    """A motion CSV (rest, move, rest, move, rest) played on the MuJoCo TX40: joint states at the logging
    rate that follow the motion, effort near the gravity torque at rest, one tracker reading per dwell."""
    robot = RobotModel.load("staubli_tx40")
    dt, rest, move = 2e-3, 0.15, 0.1
    q0 = np.array([0.19, 0.21, 0.86, -0.16, 0.79, 0.11])            # both poses seen by the tracker
    q1 = q0 + np.array([0.1, 0.1, -0.1, 0.1, -0.1, 0.2])
    segments = [(q0, q0, rest), (q0, q1, move), (q1, q1, rest), (q1, q0, move), (q0, q0, rest)]
    t, q, v, a = [], [], [], []
    t_start = 0.0
    for start, end, duration in segments:
        s = np.arange(int(round(duration / dt))) * dt
        x = s / duration
        shape, rate, curv = 10 * x**3 - 15 * x**4 + 6 * x**5, (30 * x**2 - 60 * x**3 + 30 * x**4) / duration, \
            (60 * x - 180 * x**2 + 120 * x**3) / duration**2
        t.append(t_start + s)
        q.append(start + shape[:, None] * (end - start))
        v.append(rate[:, None] * (end - start))
        a.append(curv[:, None] * (end - start))
        t_start += duration
    t, q, v, a = (np.concatenate(x) for x in (t, q, v, a))
    tau = np.array([robot.inverse_dynamics(*x) for x in zip(q, v, a, strict=True)])
    names = tuple(robot.model.names[1:])
    motion_csv = write_motion_csv(tmp_path / "motion.csv", SampledMotion(names, t, q, v, a, tau))
    record = play_file(motion_csv, tmp_path / "record.csv", robot="staubli_tx40", engine="mujoco", seed=2,
                       log_rate_hz=500.0)
    states = read_joint_states_csv(tmp_path / "record.csv")
    assert states.joint_names == names
    assert abs(states.sample_rate_hz - 500.0) < 1e-6 * 500
    assert np.abs(np.interp(states.t_s, t, q[:, 1]) - states.q_rad[:, 1]).max() < 5e-3
    at_rest = states.t_s < 0.1
    gravity = robot.gravity_torque(q0)
    assert np.allclose(states.effort_Nm[at_rest].mean(axis=0), gravity, atol=0.2 * np.abs(gravity).max())
    assert record.tracker.n_samples == 3                           # three dwells, each seen once
    points = read_points(tracker_path(tmp_path / "record.csv"))
    assert np.allclose(points.xyz_m, record.tracker.xyz_m)


def test_arm_play_refuses_to_overwrite_a_record(tmp_path, capsys) -> None:
    (tmp_path / "record.csv").write_text("t_s\n")
    assert cli_main(["arm", "play", str(tmp_path / "motion.csv"), "--out", str(tmp_path / "record.csv")]) == 2
    assert "exists already" in capsys.readouterr().err
    assert (tmp_path / "record.csv").read_text() == "t_s\n"


def test_a_run_with_truth_engine_mujoco_gets_the_mujoco_arm(tx40: RobotModel) -> None:
    assert type(make_real(tx40, load_config(None, ["robot=staubli_tx40"]))) is RealRobot
    assert isinstance(make_real(tx40, load_config(None, ["robot=staubli_tx40", "truth.engine=mujoco"])),
                      MujocoRealRobot)
