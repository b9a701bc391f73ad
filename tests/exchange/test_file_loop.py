"""The loop through files only: a designed experiment exported, played on the simulated arm by a player
that reads nothing but the exported bag (``pipeline.sim.player``), logged as ROS 2 bags, and the stage
run again from those bags. Identification: the base parameters agree with the in-process path within
their standard deviations. Calibration: the exported tour played and logged (joint states and
PointStamped readings in one bag) is read as ``calibration.measurements_file`` reads it: one measurement
per stationary window, each at a designed pose."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.calibration import candidates
from pipeline.calibration import measure as calibration_measure
from pipeline.calibration.config import Config as CalibrationConfig
from pipeline.exchange.joint_limits import JointLimitTable
from pipeline.exchange.ros2_bag import first_stamp_s, read_joint_states, read_points, write_recording
from pipeline.identification import stage
from pipeline.robot.defaults import ready_pose_rad
from pipeline.run.export import excitation_motion
from pipeline.run.export_motions import ExportContext
from pipeline.run.export_tour import calibration_files
from pipeline.sim.player import TRACKER_TOPIC, play_file, tracker_path
from pipeline.stage_api import StageOutput

from ..identification.helpers import NO_LOAD_FRICTION, quick_context

SEED = 1
#: small sizes: the linear friction model, two periods at 500 Hz (configs/quick.yaml)
SMALL = {"run_tx40": False, "friction_model": "viscous_coulomb"}


def _export_context(robot, staging: Path, rate_hz: float = 500.0) -> ExportContext:
    staging.mkdir(parents=True, exist_ok=True)
    return ExportContext(staging, staging, robot, robot, JointLimitTable.of_model(robot), ready_pose_rad(robot),
                         rate_hz, "sqlite3", "/rx130l/joint_trajectory")


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    ctx, real = quick_context(tmp_path_factory.mktemp("inproc"), SEED, overrides=SMALL, truth=NO_LOAD_FRICTION)
    return ctx, stage.run(ctx)


def test_identification_from_the_played_bag_agrees_with_the_in_process_path(in_process, tmp_path):
    ctx, result = in_process
    export = _export_context(ctx.robot, tmp_path / "export")
    output = StageOutput(result.summary, result.arrays, result.data, None, tmp_path)
    motion = excitation_motion(export, output, ctx.config.periods)
    export.write_motion("excitation", motion)
    record = play_file(tmp_path / "export" / "excitation", tmp_path / "joint_states", robot="rx130l",
                       engine="pipeline", seed=SEED, log_rate_hz=500.0, truth=NO_LOAD_FRICTION)
    assert record.paths[0] == tmp_path / "joint_states"
    ctx_file, _ = quick_context(tmp_path / "file", SEED, overrides={**SMALL, "data_file": str(record.paths[0])},
                                truth=NO_LOAD_FRICTION)
    ctx_file.real = None        # the recorded path never reaches the simulated world
    from_file = stage.run(ctx_file)
    beta, sigma = result.arrays["base_beta"], result.arrays["base_sigma"]
    beta_f, sigma_f = from_file.arrays["base_beta"], from_file.arrays["base_sigma"]
    # the played arm runs under its drives on the hidden robot's elastic joints, the in-process path follows
    # the excitation ideally: a few large gravity terms may differ by some sigma, the rest agree
    z = np.abs(beta_f - beta) / np.hypot(sigma, sigma_f)
    assert np.median(z) < 1.0
    assert np.mean(z < 2.0) >= 0.9
    assert np.all(z < 6.0), f"worst |z| {z.max():.2f} at base parameter {int(np.argmax(z))}"


def test_calibration_poses_from_the_played_tour(tmp_path, rx130l):
    chain = candidates.chain_from_robot(rx130l, rx130l.tracker.transform_tracker_to_base)
    poses, _ = candidates.random_candidates(chain, 6, np.random.default_rng(7), candidates.FilterMargins(0.02))
    export = _export_context(rx130l, tmp_path / "export", rate_hz=250.0)
    calibration = StageOutput({"selection_method": "index"}, {"configurations_selected": poses}, {},
                              None, tmp_path)
    calibration_files(export, calibration)
    header = (tmp_path / "export" / "calibration_measurements_template.csv").read_text().splitlines()[0]
    assert header == ",".join([f"q{i + 1}" for i in range(rx130l.nq)] + ["x", "y", "z"])
    record = play_file(tmp_path / "export" / "calibration_tour", tmp_path / "tour", robot="rx130l",
                       engine="pipeline", seed=SEED, log_rate_hz=250.0)
    t0 = first_stamp_s(record.paths[0])          # the two bags of the player on one clock
    states = read_joint_states(record.paths[0], t0_s=t0)
    points = read_points(tracker_path(record.paths[0]), t0_s=t0)
    bag = write_recording(tmp_path / "tour_recording", states, points, TRACKER_TOPIC)
    measured = calibration_measure.read_measurements(bag, rx130l, CalibrationConfig(measurements_file=str(bag)))
    assert measured.windows_found is not None and measured.windows_found >= len(measured) == points.n_samples
    ordered = np.loadtxt(tmp_path / "export" / "calibration_measurements_template.csv", delimiter=",",
                         skiprows=1, usecols=range(rx130l.nq), ndmin=2)
    visible = len(measured)
    assert visible >= 4
    # each window's mean joint position is one of the designed poses (the drive's settling error is small)
    distance = np.abs(measured.Q[:, None, :] - ordered[None, :, :]).max(axis=2)
    assert np.all(distance.min(axis=1) < 1e-3)
