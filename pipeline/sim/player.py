"""``python -m pipeline arm play``: an exported motion played on the stand-in arm, logged as a real arm would.

The motion (a ``trajectory_msgs/JointTrajectory`` bag or a motion CSV of :mod:`pipeline.exchange`) is
run under the stand-in arm's drives (:mod:`pipeline.sim.drive`: the cascade of paper 004 §2.3 at
400 µs with its set-point timing; the file's ``tau_ff`` as the torque feedforward) on the hidden
robot of the run seed, with either engine (``pipeline``: the own plant, ``mujoco``: the MuJoCo arm).
The record is what the arm's logging would write:

- ``sensor_msgs/JointState`` at the logging rate (a bag folder, or a joint-state CSV when ``RECORD``
  ends in ``.csv``): encoder positions (noise and quantisation), the drive's velocity estimate, and
  the motor torque (actuator torque, saturated; the own plant's averaged over the control sample
  centred on the encoder reading) plus the torque sensor's noise;
- at every dwell of the motion (all joints at rest for at least ``dwell_min_s``, as the calibration
  tour stops at each pose), one laser-tracker reading of the reflector in the tracker frame, taken at
  the end of the dwell (after the arm has settled), as ``geometry_msgs/PointStamped`` on
  ``/tracker/reflector``: in the same bag as the joint states (as ``ros2 bag record /joint_states
  /tracker/reflector`` writes it), or beside a CSV record as a bag ``<RECORD>_tracker``; readings the
  tracker cannot see (incidence, a link in the beam) are not written.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.core.errors import DataFileError
from pipeline.exchange.joint_names import match_joint_names
from pipeline.exchange.motion import JointStates, SampledMotion, TrackerPoints
from pipeline.exchange.motion_csv import read_motion_csv, write_joint_states_csv
from pipeline.exchange.ros2_bag import is_bag, read_joint_trajectory, write_joint_states, write_points, write_recording
from pipeline.robot.example_robots import EXAMPLE_ARMS, example_arm_urdf
from pipeline.robot.loading import ROBOTS_DIR
from pipeline.robot.model import RobotModel
from pipeline.sim.drive import DriveSettings, drive_gains, drive_inputs
from pipeline.sim.mujoco_robot import create_hidden_robot
from pipeline.sim.truth import RealRobot, TruthConfig

#: joint speed below which a sample is at rest (rad/s), and the shortest dwell that gets a tracker reading
REST_SPEED_RAD_S = 1e-6
DWELL_MIN_S = 0.1
TRACKER_TOPIC = "/tracker/reflector"


@dataclass
class PlayRecord:
    """What the arm logged: joint states, tracker readings at the dwells, and where they were written."""

    states: JointStates
    tracker: TrackerPoints
    paths: list[Path]
    engine: str


def read_motion(path: str | Path) -> SampledMotion:
    """A motion from a ``JointTrajectory`` bag or a motion CSV."""
    path = Path(path)
    if is_bag(path):
        return read_joint_trajectory(path)
    if path.suffix.lower() == ".csv":
        return read_motion_csv(path)
    raise DataFileError(path, None, "neither a ROS 2 bag nor a motion CSV (.csv)")


def read_motion_for(robot: RobotModel, path: str | Path) -> SampledMotion:
    """The motion of ``path`` (:func:`read_motion`) in the model's joint order (:func:`_in_model_order`)."""
    return _in_model_order(read_motion(path), robot, str(path))


def _in_model_order(motion: SampledMotion, robot: RobotModel, source: str) -> SampledMotion:
    """``motion`` with the robot's joints (matched by name) in the model's order; positions, velocities and
    feedforward must be given."""
    names = list(robot.model.names[1:])
    mapping = match_joint_names(motion.joint_names, names, source=source)
    idx = [motion.joint_names.index(mapping[n]) for n in names]
    arrays = [getattr(motion, f)[:, idx] for f in ("q_rad", "qd_rad_s", "qdd_rad_s2", "tau_ff_Nm")]
    for field, x in zip(("q_rad", "qd_rad_s", "qdd_rad_s2", "tau_ff_Nm"), arrays, strict=True):
        if field != "qdd_rad_s2" and not np.all(np.isfinite(x)):
            raise DataFileError(source, field, "NaN values: the motion needs positions, velocities and feedforward")
    return SampledMotion(tuple(names), motion.t_s, *arrays)


def dwell_ends(t_s: np.ndarray, qd: np.ndarray, min_dwell_s: float = DWELL_MIN_S) -> np.ndarray:
    """Indices of the last sample of each run of rest samples lasting at least ``min_dwell_s``."""
    rest = np.all(np.abs(qd) <= REST_SPEED_RAD_S, axis=1)
    ends, k, n = [], 0, len(rest)
    while k < n:
        if not rest[k]:
            k += 1
            continue
        start = k
        while k + 1 < n and rest[k + 1]:
            k += 1
        if t_s[k] - t_s[start] >= min_dwell_s - 1e-12:
            ends.append(k)
        k += 1
    return np.asarray(ends, dtype=int)


def play(motion: SampledMotion, real: RealRobot, robot: RobotModel, rng: np.random.Generator,
         log_rate_hz: float | None = None, drive: DriveSettings | None = None) -> tuple[JointStates, TrackerPoints]:
    """Run ``motion`` (model joint order) on ``real`` under the drives tuned on ``robot``; the logged record."""
    s = drive if drive is not None else DriveSettings()
    inputs = drive_inputs(motion.t_s, motion.q_rad, motion.qd_rad_s, motion.tau_ff_Nm, s)
    rec = real.plant.run_servo(drive_gains(robot, np.mean(motion.q_rad, axis=0), s), s.sample_time_s,
                               s.velocity_samples, s.measurement_delay_samples, s.alpha, inputs.q_d_fb, inputs.v_ff,
                               inputs.tau_ff, inputs.q_d[0], rng, measure_tcp=False, v0=inputs.v0)
    effort = robot.limits.effort_Nm
    if rec.actuator_torque_Nm is not None:      # MuJoCo: the force right after the encoder sample
        tau = rec.actuator_torque_Nm
    else:
        # the own loop's torque row k is the mean over [t_k, t_k + T), its encoder row the reading at t_k:
        # logged with it is the mean over the sample centred on t_k (a half-sample offset, 0.2 ms at
        # 400 µs, biases the parameters fitted to a long record by about a sigma)
        tau = np.clip(rec.tau_cmd, -effort, effort)
        tau = np.vstack([tau[:1], 0.5 * (tau[1:] + tau[:-1])])
    keep = slice(inputs.n_settle, None)
    t = inputs.t_s[keep] - inputs.t_s[inputs.n_settle]
    q, v, tau = rec.q_meas[keep], rec.v_est[keep], tau[keep]
    step = 1 if log_rate_hz is None else max(1, int(round(1.0 / (log_rate_hz * s.sample_time_s))))
    idx = np.arange(0, len(t), step)
    states = JointStates(motion.joint_names, t[idx], q[idx], v[idx], real.torque_sensor.read(tau[idx], rng))
    grid_qd = np.stack([np.interp(t, motion.t_s - motion.t_s[0], motion.qd_rad_s[:, j])
                        for j in range(q.shape[1])], axis=1)
    ends = dwell_ends(t, grid_qd)
    if ends.size:
        reading = real.tracker.measure(q[ends], rng)
        seen = reading.visible
        points = TrackerPoints(t[ends][seen], reading.position_m[seen], "tracker")
    else:
        points = TrackerPoints(np.zeros(0), np.zeros((0, 3)), "tracker")
    return states, points


def load_robot(robot: str | Path) -> RobotModel:
    """A built-in robot, a robot folder or URDF, or an example-robot-data arm by short name (``panda``)."""
    example = example_arm_urdf(str(robot)) if str(robot) in EXAMPLE_ARMS else None
    return RobotModel.load(example if example is not None and not (ROBOTS_DIR / str(robot)).is_dir() else robot)


def is_csv_record(record: Path) -> bool:
    """The record is written as CSV (``RECORD`` ends in ``.csv``), else as a bag."""
    return record.suffix.lower() == ".csv"


def tracker_path(record: Path) -> Path:
    """Where the tracker readings of a CSV record go: ``<record stem>_tracker`` (a bag folder) beside it."""
    return record.with_name(f"{record.stem}_tracker")


def held(motion: SampledMotion, hold_s: float) -> SampledMotion:
    """``motion`` followed by ``hold_s`` of its last pose at rest (the controller holding its last set-point, with
    the last feedforward torque), at the motion's median sample interval."""
    if hold_s <= 0.0 or motion.n_samples < 2:
        return motion
    dt = float(np.median(np.diff(motion.t_s)))
    extra = np.arange(1, int(np.ceil(hold_s / dt)) + 1)
    n = motion.q_rad.shape[1]

    def tail(x: np.ndarray) -> np.ndarray:
        return np.vstack([x, np.tile(x[-1], (extra.size, 1))])

    zeros = np.zeros((extra.size, n))
    return SampledMotion(motion.joint_names, np.concatenate([motion.t_s, motion.t_s[-1] + dt * extra]),
                         tail(motion.q_rad), np.vstack([motion.qd_rad_s, zeros]), np.vstack([motion.qdd_rad_s2, zeros]),
                         tail(motion.tau_ff_Nm))


def play_file(motion_path: str | Path, out: str | Path, robot: str | Path = "rx130l", engine: str = "mujoco",
              seed: int = 1, log_rate_hz: float | None = None, truth: TruthConfig | None = None,
              hold_s: float = 0.0) -> PlayRecord:
    """``arm play``: read the motion, play it on the hidden robot of ``seed`` with ``engine`` (then hold its
    last pose for ``hold_s``, :func:`held`), write the record."""
    out = Path(out)
    targets = [out, tracker_path(out)] if is_csv_record(out) else [out]
    for target in targets:
        if target.exists():
            raise DataFileError(target, None, "exists already; the record is written only to a new path")
    if log_rate_hz is not None and not (np.isfinite(log_rate_hz) and log_rate_hz > 0):
        raise DataFileError(None, "--log-rate-hz", f"must be a positive number, got {log_rate_hz!r}")
    if not (np.isfinite(hold_s) and hold_s >= 0):
        raise DataFileError(None, "--hold-s", f"must be a number >= 0, got {hold_s!r}")
    nominal = load_robot(robot)
    motion = held(read_motion_for(nominal, motion_path), hold_s)
    config = truth if truth is not None else TruthConfig()
    config.engine = engine
    real = create_hidden_robot(nominal, seed, config)
    states, points = play(motion, real, nominal, np.random.default_rng([int(seed), 0x706C6179]), log_rate_hz)
    if not is_csv_record(out):
        if points.n_samples:
            write_recording(out, states, points, TRACKER_TOPIC)
        else:
            write_joint_states(out, states)
        return PlayRecord(states, points, [out], engine)
    write_joint_states_csv(out, states)
    written = [out]
    if points.n_samples:
        written.append(write_points(tracker_path(out), points, TRACKER_TOPIC))
    return PlayRecord(states, points, written, engine)
