"""``python -m pipeline arm verify MOTION RECORD``: a recorded execution of an exported motion, judged.

The motion (a ``JointTrajectory`` bag or motion CSV, :mod:`pipeline.exchange`) is what the controller was
sent; the record (a ``JointState`` bag or joint-state CSV) what the arm logged while it ran it. Both are
read with the model's joints matched by name.

1. **Time offset.** The record's clock is not the motion's: the offset ``tau`` is found from the onset of
   motion (in each, the first sample ``ONSET_RAD`` away from the start pose after one at it), then
   refined on a grid of ``REFINE_STEP_S`` within ``REFINE_HALF_WIDTH_S`` by the least RMS of
   ``q_rec(t + tau) - q_plan(t)`` over the motion (the record linearly interpolated; its times from
   its first sample).
2. **Tracking.** Over the motion's duration: per joint the largest and the RMS joint error, and the
   largest TCP deviation (the model's kinematics at the recorded and the planned angles; encoder side:
   a link deflection the encoders do not see is not in it).
3. **Torque.** The largest recorded effort against each joint's effort limit, and the recorded effort
   against the motion's feedforward torque (RMS per joint; the
   feedforward is the model's torque along the plan, so the difference is what the servo had to add:
   model error, friction the model lacks, and the tracking corrections). A logged effort is the drive's
   torque plus the sensor's noise: a drive at its limit (a time-optimal plan is, by design) logs samples
   a little above it. The limit counts as exceeded when the largest effort passes it by more than
   ``NOISE_SIGMAS`` times the record's own noise, ``sigma = 1.4826 MAD(diff(effort)) / sqrt(2)`` per joint
   (the median absolute deviation of the sample-to-sample differences: robust to the torque's steps).
   Before that, the record's efforts must be joint torques in N·m: per joint the effort is regressed on the
   feedforward with an offset, viscous and Coulomb columns free, and the median ratio of the joints where
   the feedforward explains enough of it must read as torques
   (:func:`pipeline.identification.effort_unit.ratio_to_model`, the identification's check against its
   nominal model). Motor currents (a UR driver's ``effort``) or motor-side torques are not judged against
   torque limits; ``--effort-scale`` states joint-side N·m per logged unit.
4. **Settling**, as the trajectory stage counts it (:mod:`pipeline.trajectory.settling`): after the
   motion's end, the time from which the TCP (the model's kinematics at the recorded angles) stays within
   50 µm of the pose it comes to rest at, the mean of the record's last ``REST_WINDOW_S``
   (:func:`pipeline.control.validate.settling_time`; inf: not within the record); that rest pose's
   distance from the planned end is the static offset.

The check fails (exit 3) when a recorded effort exceeds its limit so; bad files end with exit 2. A record
without efforts (positions only, as some drivers log), or with efforts in another unit, is judged on its
tracking and settling, and says that its torques were not judged and why.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.control.validate import SETTLING_POSITION_TOLERANCE_M, settling_time
from pipeline.core.errors import DataFileError
from pipeline.exchange.motion import JointStates, SampledMotion
from pipeline.exchange.recording import read_recorded_joint_states
from pipeline.identification.effort_unit import median_ratio, ratio_to_model, within_band
from pipeline.robot.model import RobotModel
from pipeline.sim.player import read_motion_for

#: a joint this far from the start pose (rad) has begun to move
ONSET_RAD = 1e-3
#: the refinement of the time offset: half width of the search (s) and its step (s)
REFINE_HALF_WIDTH_S = 0.1
REFINE_STEP_S = 2.5e-4
#: a recorded effort exceeds its limit when it passes it by more than this many of its noise's sigmas
NOISE_SIGMAS = 3.0
#: at most about this many of the motion's samples score each trial offset
OFFSET_SAMPLES = 2000
#: the end of the record whose mean TCP position is the rest pose (s)
REST_WINDOW_S = 0.05
#: the record may start or end this many of its sample intervals inside the motion (a logger's last sample)
COVER_INTERVALS = 2
#: the Coulomb column's smoothing width of the effort-unit check (rad/s)
COULOMB_WIDTH_RAD_S = 0.01


@dataclass(frozen=True)
class Verification:
    """The recorded execution against the motion (module docstring); per-joint arrays in model order."""

    joint_names: tuple[str, ...]
    time_offset_s: float
    duration_s: float
    tracking_max_rad: np.ndarray
    tracking_rms_rad: np.ndarray
    tcp_deviation_max_m: float
    effort_ratio_max: np.ndarray
    effort_ratio_time_s: np.ndarray
    #: (n,) N m: the record's effort noise (module docstring, step 3)
    effort_noise_Nm: np.ndarray
    effort_limit_Nm: np.ndarray
    effort_minus_feedforward_rms_Nm: np.ndarray
    #: after the motion's end (inf: not settled within the record; None: the record ends with the motion)
    settle_time_s: float | None
    static_offset_m: float | None
    #: (n,) the recorded effort per unit of feedforward (NaN: no effort) and the median that counts (None: none)
    effort_per_feedforward: np.ndarray
    effort_per_feedforward_median: float | None

    @property
    def effort_logged(self) -> bool:
        return bool(np.all(np.isfinite(self.effort_ratio_max)))

    @property
    def effort_recorded(self) -> bool:
        """Efforts logged, and in N·m as far as the feedforward tells (module docstring, step 3)."""
        median = self.effort_per_feedforward_median
        return self.effort_logged and (median is None or within_band(median))

    @property
    def limits_kept(self) -> bool:
        """No recorded effort over its limit beyond the noise (True when the record holds no effort)."""
        excess = (self.effort_ratio_max - 1.0) * self.effort_limit_Nm
        return not self.effort_recorded or bool(np.all(excess <= NOISE_SIGMAS * self.effort_noise_Nm))

    def lines(self) -> list[str]:
        """The headline first, then one line per joint."""
        worst = int(np.argmax(self.effort_ratio_max)) if self.effort_recorded else 0
        band = f"{1e6 * SETTLING_POSITION_TOLERANCE_M:.0f} µm"
        settle = ("the record ends with the motion" if self.settle_time_s is None or self.static_offset_m is None
                  else f"not settled within {band} in the record" if not np.isfinite(self.settle_time_s)
                  else f"settled within {band} {self.settle_time_s:.3f} s after the end, "
                       f"{1e6 * self.static_offset_m:.1f} µm from the planned end")
        effort = (f"{'limits kept' if self.limits_kept else 'EFFORT LIMIT EXCEEDED'}: largest effort "
                  f"{self.effort_ratio_max[worst]:.3f} of the limit ({self.joint_names[worst]} at "
                  f"t = {self.effort_ratio_time_s[worst]:.3f} s, the record's noise {NOISE_SIGMAS:g} sigma = "
                  f"{NOISE_SIGMAS * self.effort_noise_Nm[worst]:.3g} N m)" if self.effort_recorded else
                  "torques not judged: the record holds no effort for every joint and sample" if not self.effort_logged
                  else f"torques not judged: the record's efforts are {self.effort_per_feedforward_median:.3g}x the "
                       "motion's feedforward (median), not joint torques in N·m (motor currents or motor-side "
                       "torques?); --effort-scale states joint-side N·m per logged unit")
        out = [f"{effort}; TCP deviation max "
               f"{1e3 * self.tcp_deviation_max_m:.3f} mm; {settle}",
               f"the motion ({self.duration_s:.3f} s) starts {self.time_offset_s:.4f} s after the record's first "
               "sample",
               f"{'joint':<24}{'tracking max mrad':>18}{'rms mrad':>10}{'effort/limit':>14}{'effort-ff rms N m':>19}"]
        for k, name in enumerate(self.joint_names):
            out.append(f"{name:<24}{1e3 * self.tracking_max_rad[k]:>18.3f}{1e3 * self.tracking_rms_rad[k]:>10.3f}"
                       f"{self.effort_ratio_max[k]:>14.3f}{self.effort_minus_feedforward_rms_Nm[k]:>19.3f}")
        return out


def _onset_s(t_s: np.ndarray, q: np.ndarray, start: np.ndarray) -> float | None:
    """The first time ``q`` leaves ``start`` by ``ONSET_RAD`` after it has been there (a record may begin
    with the arm on its way to the start pose); None when it never is there or never leaves."""
    away = np.max(np.abs(q - start), axis=1) > ONSET_RAD
    there = np.flatnonzero(~away)
    if not there.size:
        return None
    moving = np.flatnonzero(away[there[0]:])
    return float(t_s[there[0] + moving[0]]) if moving.size else None


def _at(t_s: np.ndarray, values: np.ndarray, t_query: np.ndarray) -> np.ndarray:
    """``values`` (N, n) linearly interpolated at ``t_query``."""
    return np.column_stack([np.interp(t_query, t_s, values[:, j]) for j in range(values.shape[1])])


def time_offset_s(motion: SampledMotion, record: JointStates, source: str) -> float:
    """The offset ``tau`` with ``t_record = t_motion + tau``, record times from its first sample (module
    docstring, step 1)."""
    t_plan = motion.t_s - motion.t_s[0]
    onset_plan = _onset_s(t_plan, motion.q_rad, motion.q_rad[0])
    onset_rec = _onset_s(record.t_s, record.q_rad, motion.q_rad[0])
    if onset_plan is None:
        raise DataFileError(None, "motion", "the motion never leaves its start pose: nothing to align")
    if onset_rec is None:
        raise DataFileError(source, "position", f"the arm is never at the motion's start pose, or never leaves it, by "
                            f"{ONSET_RAD:g} rad: the record is not of this motion")
    guess = onset_rec - onset_plan
    offsets = guess + np.arange(-REFINE_HALF_WIDTH_S, REFINE_HALF_WIDTH_S + 0.5 * REFINE_STEP_S, REFINE_STEP_S)
    every = slice(None, None, max(1, t_plan.size // OFFSET_SAMPLES))
    t_fit, q_fit = t_plan[every], motion.q_rad[every]
    costs = [float(np.mean((_at(record.t_s, record.q_rad, t_fit + tau) - q_fit) ** 2)) for tau in offsets]
    return float(offsets[int(np.argmin(costs))])


def verify(motion: SampledMotion, record: JointStates, robot: RobotModel, source: str = "record") -> Verification:
    """``record`` (the model's joints, model order) of an execution of ``motion`` (model order) on ``robot``."""
    tau = time_offset_s(motion, record, source)
    t_all = motion.t_s - motion.t_s[0]
    slack = COVER_INTERVALS * float(np.median(np.diff(record.t_s)))
    if t_all[0] + tau < record.t_s[0] - slack or t_all[-1] + tau > record.t_s[-1] + slack:
        raise DataFileError(source, "t", f"the record ({record.t_s[-1] - record.t_s[0]:.3f} s) does not cover the "
                            f"motion ({t_all[-1]:.3f} s from {tau:.3f} s on its clock)")
    covered = (t_all + tau >= record.t_s[0]) & (t_all + tau <= record.t_s[-1])
    t_plan = t_all[covered]
    motion = SampledMotion(motion.joint_names, motion.t_s[covered], motion.q_rad[covered], motion.qd_rad_s[covered],
                           motion.qdd_rad_s2[covered], motion.tau_ff_Nm[covered])
    q_rec = _at(record.t_s, record.q_rad, t_plan + tau)
    error = q_rec - motion.q_rad
    tcp = np.linalg.norm(robot.positions(q_rec) - robot.positions(motion.q_rad), axis=1)
    during = (record.t_s >= tau) & (record.t_s <= t_all[-1] + tau)
    effort = record.effort_Nm if np.all(np.isfinite(record.effort_Nm)) else np.full_like(record.effort_Nm, np.nan)
    ratio = np.abs(effort[during]) / np.asarray(robot.limits.effort_Nm, float)
    worst = np.argmax(np.nan_to_num(ratio, nan=0.0), axis=0)
    effort_at_plan = _at(record.t_s, effort, t_plan + tau)
    settle: float | None = None
    offset: float | None = None
    t_end = t_all[-1] + tau
    if np.any(record.t_s > t_end):
        tail = record.t_s >= min(t_end, record.t_s[-1])
        tcp_tail = robot.positions(record.q_rad[tail])
        rest = np.mean(tcp_tail[record.t_s[tail] >= record.t_s[-1] - REST_WINDOW_S], axis=0)
        settle = settling_time(record.t_s[tail], tcp_tail, rest, t_end)
        offset = float(np.linalg.norm(rest - robot.positions(motion.q_rad[-1:])[0]))
    steps = np.diff(effort, axis=0)
    noise = 1.4826 * np.median(np.abs(steps - np.median(steps, axis=0)), axis=0) / np.sqrt(2.0)
    feedforward_rms = np.sqrt(np.mean((effort_at_plan - motion.tau_ff_Nm) ** 2, axis=0))
    per_ff, median = effort_per_feedforward(effort_at_plan, motion)
    return Verification(motion.joint_names, tau, float(t_all[-1]), np.max(np.abs(error), axis=0),
                        np.sqrt(np.mean(error ** 2, axis=0)), float(np.max(tcp)), np.max(ratio, axis=0),
                        record.t_s[during][worst] - tau, noise, np.asarray(robot.limits.effort_Nm, float),
                        feedforward_rms, settle, offset, per_ff, median)


def effort_per_feedforward(effort: np.ndarray, motion: SampledMotion) -> tuple[np.ndarray, float | None]:
    """Per joint the recorded effort ``effort`` (at the motion's samples) per unit of the feedforward, with
    an offset, viscous and Coulomb columns free, and the median over the joints where it counts (module
    docstring, step 3); NaN and None without efforts."""
    n = effort.shape[1]
    if not np.all(np.isfinite(effort)):
        return np.full(n, np.nan), None
    v = motion.qd_rad_s
    pairs = [ratio_to_model(effort[:, j], motion.tau_ff_Nm[:, j],
                            np.column_stack([np.ones(len(v)), v[:, j], np.tanh(v[:, j] / COULOMB_WIDTH_RAD_S)]))
             for j in range(n)]
    c, r2 = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    return c, median_ratio(c, r2)[1]


def verify_files(motion_path: str | Path, record_path: str | Path, robot: RobotModel,
                 name_map: dict[str, str] | None = None, effort_scale: list[float] | None = None) -> Verification:
    """:func:`verify` on a motion file and a record file (module docstring); ``effort_scale``: joint-side N·m
    per logged effort unit, per joint in the model's order (motor currents: ``k_t x gear ratio``)."""
    motion = read_motion_for(robot, motion_path)
    record, _ = read_recorded_joint_states(record_path, list(motion.joint_names), name_map, field="--joint-names")
    if effort_scale is not None:
        if len(effort_scale) != robot.nq or not all(np.isfinite(k) and k > 0 for k in effort_scale):
            raise DataFileError(None, "--effort-scale", f"needs {robot.nq} numbers > 0 (joint-side N·m per logged "
                                f"unit, one per joint of {robot.name}), got {effort_scale}")
        record = JointStates(record.joint_names, record.t_s, record.q_rad, record.qd_rad_s,
                             record.effort_Nm * np.asarray(effort_scale, float)[None, :])
    return verify(motion, record, robot, str(record_path))
