"""Measurements: the simulated laser tracker on the hidden robot, a CSV file or a recording (:func:`read_recording`).

CSV format (one row per configuration, comma separated, header recommended)::

    q1,q2,q3,q4,q5,q6,x,y,z[,rx,ry,rz]

(with a header: columns in any order, joints by the model's names too, units stated in the names and
converted, ``;`` or tab delimited: :mod:`pipeline.exchange.csv_header`; the orientation may be
``roll,pitch,yaw`` instead, ``R = Rz(yaw) Ry(pitch) Rx(roll)``, and FIGAROH's calibration CSV reads as it
is: ``x1,y1,z1`` the position, ``phix1,phiy1,phiz1`` roll, pitch, yaw, joints by name).
``q*`` joint angles in rad (Pinocchio order), ``x, y, z`` the reflector (marker) position in the
tracker frame in m, optional ``rx, ry, rz`` the rotation vector (axis * angle, rad; ``R = exp(r^)``,
scipy ``Rotation.from_rotvec``) of the marker frame in the tracker frame: ``R`` maps marker-frame
axes to tracker-frame axes, the marker frame being the reflector frame of robot.yaml (flange
orientation, at the reflector offset). Such 6-D readings (6-DOF tracker probe, motion capture)
enter the fit (:func:`expand_orientation`) and the validation reports orientation errors. Any problem (missing
file, wrong column count, non-numeric or NaN/inf value, too few rows, joint angles outside the
limits, values in the wrong unit: positions in mm, angles in degrees) raises
:class:`pipeline.core.errors.DataFileError` naming the file, the file line (1-based, as an editor shows
it) and column and the problem, before anything is written.

Without a file the simulated tracker measures the designed configurations
(:func:`measure_simulated`) and the held-out poses of the validation (:func:`heldout_measurements`).
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.calibration import candidates as cd
from pipeline.calibration.config import Config
from pipeline.calibration.estimate import Estimate
from pipeline.core.errors import DataFileError, InfeasibleError
from pipeline.exchange import ros2_bag
from pipeline.exchange.csv_header import is_number, number, parse_header, sniff_delimiter
from pipeline.exchange.recording import is_recording, read_recorded_joint_states
from pipeline.exchange.ros2_bag import is_bag
from pipeline.exchange.stationary import stationary_windows
from pipeline.robot.model import RobotModel
from pipeline.robot.payload import Payload

#: the columns of a pose CSV besides the joints, by kind (units in the header convert: x_mm, rx [deg]); the
#: orientation as a rotation vector or as roll, pitch, yaw (R = Rz(yaw) Ry(pitch) Rx(roll))
POSE_FIELDS = {"x": "length", "y": "length", "z": "length", "rx": "angle", "ry": "angle", "rz": "angle",
               "roll": "angle", "pitch": "angle", "yaw": "angle"}
ORIENTATION_FIELDS = ("rx", "ry", "rz")
RPY_FIELDS = ("roll", "pitch", "yaw")
#: FIGAROH's calibration CSV: the marker's position x1, y1, z1 and roll-pitch-yaw phix1, phiy1, phiz1
POSE_ALIASES = {"x1": "x", "y1": "y", "z1": "z", "phix1": "roll", "phiy1": "pitch", "phiz1": "yaw"}


@dataclass
class Measurements:
    """Joint configurations and tracker readings (tracker frame)."""

    Q: np.ndarray                 # (N, nq) rad
    Y: np.ndarray                 # (N, 3) m
    sigma_m: np.ndarray           # (N,) isotropic 1-sigma of each reading
    source: str                   # "simulated tracker" or the file path
    rotvec: np.ndarray | None = None   # (N, 3) optional orientation
    n_requested: int = 0          # configurations commanded (simulated), before visibility
    invisible: np.ndarray | None = None  # commanded configurations the tracker could not see
    #: (N,) bool: read with the known payload mounted (None: never)
    payload_mounted: np.ndarray | None = None
    #: (N,) file line of each row (CSV data), None for simulated readings
    lines: np.ndarray | None = None
    #: (N, 3) marker-point offset of each row in the reflector frame (6-D readings, expand_orientation)
    offset_m: np.ndarray | None = None
    #: (N,) row of the original record each row comes from (6-D readings), None: the identity
    pose_index: np.ndarray | None = None
    #: a bag: stationary windows found (each row is one used window), and each row's scatter (m)
    windows_found: int | None = None
    scatter_m: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.Q)


def measure_simulated(real, Q: np.ndarray, rng: np.random.Generator, payload: Payload | None = None
                      ) -> Measurements:
    """Command ``Q`` on the real robot (``payload`` mounted) and read the tracker; invisible rows are dropped."""
    Q = np.atleast_2d(np.asarray(Q, float))
    reading = real.tracker.measure(Q, rng, payload) if payload is not None else real.tracker.measure(Q, rng)
    vis = np.asarray(reading.visible, bool)
    mounted = np.full(int(vis.sum()), True) if payload is not None else None
    return Measurements(Q[vis], np.asarray(reading.position_m)[vis], np.asarray(reading.sigma_m)[vis],
                        "simulated tracker", None, len(Q), Q[~vis], mounted)


def write_simulated_record(real, Q_fit: np.ndarray, Q_validation: np.ndarray, folder: Path,
                           rng: np.random.Generator) -> tuple[Path, Path]:
    """The tracker's readings of the (hidden) arm ``real`` at ``Q_fit`` and ``Q_validation`` written as
    a user records them (:func:`write_csv`): ``folder/fit.csv`` and ``folder/validation.csv``, for
    ``calibration.measurements_csv`` and ``calibration.validation_csv``."""
    folder = Path(folder)
    fit, validation = (measure_simulated(real, Q, rng) for Q in (Q_fit, Q_validation))
    return write_csv(folder / "fit.csv", fit), write_csv(folder / "validation.csv", validation)


def concatenate(parts: list[Measurements], source: str) -> Measurements:
    """One record of several (payload flags filled with False where a part has none)."""
    mounted = None
    if any(p.payload_mounted is not None for p in parts):
        mounted = np.concatenate([p.payload_mounted if p.payload_mounted is not None else np.zeros(len(p), bool)
                                  for p in parts])
    nq = parts[0].Q.shape[1]
    invisible = np.vstack([p.invisible if p.invisible is not None else np.zeros((0, nq)) for p in parts])
    rot = None if any(p.rotvec is None for p in parts) else np.vstack([p.rotvec for p in parts])
    return Measurements(np.vstack([p.Q for p in parts]), np.vstack([p.Y for p in parts]),
                        np.concatenate([p.sigma_m for p in parts]), source, rot,
                        sum(p.n_requested for p in parts), invisible, mounted)


def heldout_measurements(robot: RobotModel, real, est: Estimate, cfg: Config,
                         rng: np.random.Generator) -> Measurements:
    """>= n_heldout visible random poses (predicted with the identified tracker pose), measured."""
    chain = cd.chain_from_robot(robot, est.transform_tracker_to_base)
    margins = cd.FilterMargins(cfg.margin_collision_m, math.radians(1.0), 0.005)
    parts: list[Measurements] = []
    have = 0
    for _ in range(10):
        need = cfg.n_heldout - have
        Q, _ = cd.random_candidates(chain, int(need * 1.1) + 10, rng, margins)
        m = measure_simulated(real, Q, rng)
        parts.append(m)
        have += len(m)
        if have >= cfg.n_heldout:
            break
    Q = np.concatenate([p.Q for p in parts])[: cfg.n_heldout]
    Y = np.concatenate([p.Y for p in parts])[: cfg.n_heldout]
    s = np.concatenate([p.sigma_m for p in parts])[: cfg.n_heldout]
    if len(Q) < cfg.n_heldout:
        raise InfeasibleError(None, "calibration.n_heldout", f"only {len(Q)} visible held-out poses found")
    return Measurements(Q, Y, s, "simulated tracker (held-out)", None, sum(p.n_requested for p in parts))


#: lever of the virtual marker points of a 6-D reading (m)
MARKER_LEVER_M = 1.0


def expand_orientation(meas: Measurements, orientation_sigma_rad: float,
                       lever_m: float = MARKER_LEVER_M) -> Measurements:
    """A 6-D record as three point readings per pose: the marker origin and two virtual points
    ``lever_m`` along the measured marker x and y axes, ``y + L R_meas e_k`` (tracker frame), whose
    model is the reflector frame's point ``dr + L e_k``. Their sigma is ``sqrt(sigma_p^2 + (L
    sigma_rot)^2)`` (the position noise they share with the origin is small against ``L sigma_rot``
    for a mocap-like 0.1 mm / 1 mrad: its correlation is neglected). Two axes fix the orientation,
    so a pose gives 6 independent equations; registration and fit see position and orientation."""
    if meas.rotvec is None:
        return meas
    n = len(meas)
    R = Rotation.from_rotvec(meas.rotvec).as_matrix()
    offsets = np.concatenate([np.zeros((n, 3)), np.tile([lever_m, 0.0, 0.0], (n, 1)),
                              np.tile([0.0, lever_m, 0.0], (n, 1))])
    Y = np.concatenate([meas.Y, meas.Y + lever_m * R[:, :, 0], meas.Y + lever_m * R[:, :, 1]])
    s_virtual = np.sqrt(meas.sigma_m ** 2 + (lever_m * orientation_sigma_rad) ** 2)
    return Measurements(np.concatenate([meas.Q] * 3), Y, np.concatenate([meas.sigma_m, s_virtual, s_virtual]),
                        meas.source, None, meas.n_requested, meas.invisible, _thrice(meas.payload_mounted),
                        _thrice(meas.lines), offsets, np.concatenate([np.arange(n)] * 3))


def _thrice(a: np.ndarray | None) -> np.ndarray | None:
    return None if a is None else np.concatenate([a, a, a])


def noise_model_sigma(robot: RobotModel, Y: np.ndarray) -> np.ndarray:
    """Sigma of the robot's tracker noise model at the range of each reading."""
    return robot.tracker.noise_const_m + robot.tracker.noise_per_m * np.linalg.norm(Y, axis=1)


def reflector_reach_m(robot: RobotModel) -> float:
    """Upper bound of the reflector's distance from the robot base origin (m): the sum of the
    joint placement offsets plus the reflector offset (revolute chain; exact bound, no sampling)."""
    model = robot.model
    reach = sum(float(np.linalg.norm(model.jointPlacements[j].translation)) for j in range(1, model.njoints))
    frame = model.frames[model.getFrameId(robot.frame_reflector)]
    return reach + float(np.linalg.norm(frame.placement.translation))


def read_measurements(path: str | Path, robot: RobotModel, cfg: Config, min_rows: int = 1) -> Measurements:
    """A measurement CSV of poses (:func:`read_csv`), or a recording read in its stationary windows
    (:func:`read_recording`): a ROS 2 bag, or a joint-state CSV with ``calibration.tracker_file``."""
    if is_recording(path):
        return read_recording(path, robot, cfg, min_rows)
    if cfg.tracker_file:
        raise DataFileError(path, "calibration.tracker_file", "names the tracker readings of a recording of joint "
                            "states (a bag, or the joint-state CSV t_s,q_<joint>_rad,...); this file is a CSV of "
                            "poses, which holds its own readings")
    return read_csv(path, robot, min_rows=min_rows)


def read_validation(path: str | Path, robot: RobotModel, cfg: Config) -> Measurements:
    """The held-out poses (``calibration.validation_csv``): a CSV of poses, or a recording of both topics in
    one bag (:func:`read_recording`; ``calibration.tracker_file`` belongs to the measurements file)."""
    if is_bag(path):
        return read_recording(path, robot, replace(cfg, tracker_file=None))
    return read_csv(path, robot, min_rows=1)


def read_recording(path: str | Path, robot: RobotModel, cfg: Config, min_rows: int = 1) -> Measurements:
    """A recording of ``sensor_msgs/JointState`` (a ROS 2 bag, or the joint-state CSV ``t_s, q_<joint>_rad,
    ...``) and a tracker topic (``PointStamped``, ``PoseStamped`` or ``TransformStamped``, positions in m
    in the tracker frame; a pose's or transform's orientation too, when not all the identity: 6-D
    readings) in the same bag or in ``calibration.tracker_file`` (a bag stamped on the recording's
    clock): one row per stationary window
    (:func:`pipeline.exchange.stationary.stationary_windows`, the ``calibration.stationary_*`` settings),
    the joint positions and the readings averaged over the window, their scatter kept."""
    tracker = cfg.tracker_file or path
    if not is_bag(tracker):
        raise DataFileError(path, "calibration.tracker_file",
                            "a joint-state CSV holds no tracker readings: name the ROS 2 bag of the tracker topic "
                            "(arm play writes it beside the CSV as <name>_tracker)" if tracker == path else
                            f"{tracker} is not a ROS 2 bag (a folder with metadata.yaml, a .db3 or a .mcap)")
    if not cfg.tracker_file and not any(msgtype in ros2_bag.TRACKER_TYPES for _, msgtype, _ in ros2_bag.topics(path)):
        raise DataFileError(path, "calibration.tracker_file",
                            f"the bag holds no tracker topic ({' / '.join(ros2_bag.TRACKER_TYPES)}): record it in the "
                            "same bag or name the bag that holds it")
    states, t0 = read_recorded_joint_states(path, [str(n) for n in robot.model.names[1:]], cfg.joint_names or None,
                                            field="calibration.joint_names")
    points = ros2_bag.read_points(tracker, t0_s=t0)
    windows = stationary_windows(states, points, cfg.stationary_speed_rad_s, cfg.stationary_min_s,
                                 cfg.stationary_settle_s, cfg.stationary_min_readings, str(path))
    if windows.n_used < min_rows:
        raise DataFileError(path, "stationary windows", f"{windows.n_used} used ({windows.n_found} found), "
                            f"need at least {min_rows}")
    Q, Y = windows.q_rad, windows.xyz_m
    lines = np.arange(1, windows.n_used + 1)
    _check_joint_angles(Path(path), Q, robot, lines)
    _check_tracker_positions(Path(path), Y, robot, lines, True)
    return Measurements(Q, Y, noise_model_sigma(robot, Y), str(path), windows.rotvec_rad, len(Q),
                        np.zeros((0, robot.nq)), None, lines, windows_found=windows.n_found,
                        scatter_m=windows.scatter_m)


def read_csv(path: str | Path, robot: RobotModel, min_rows: int = 1, min_rows_field: str | None = None) -> Measurements:
    """Read and validate a measurement CSV (format in the module docstring).

    Errors name the file, the 1-based file line (``line 51``) and the column. Values in the wrong
    unit are caught up front: joint angles in degrees, tracker positions in millimetres (farther
    from the tracker, or spread wider, than the robot's reach allows), rotation vectors in degrees.
    ``min_rows_field``: the configuration field that sets ``min_rows`` (named in the message)."""
    path = Path(path)
    nq = robot.nq
    names = [f"q{i}" for i in range(1, nq + 1)] + ["x", "y", "z"]
    if not path.is_file():
        raise DataFileError(path, "file", "does not exist" if not path.exists() else "is not a file")
    rows: list[tuple[int, list[str]]] = []   # (file line, cells), blank lines skipped
    try:
        text = path.read_text(encoding="utf-8-sig")
        delimiter = sniff_delimiter(next((ln for ln in text.splitlines() if ln.strip()), ""))
        reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
        first = 1
        for r in reader:
            if r and any(c.strip() for c in r):
                rows.append((first, r))
            first = reader.line_num + 1
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DataFileError(path, "file", f"cannot be read as CSV ({exc})") from None
    if not rows:
        raise DataFileError(path, "rows", "the file is empty")
    # a spreadsheet's trailing delimiter: an empty last column in the header and every row, dropped
    while rows[0][1] and not rows[0][1][-1].strip() and all(r and not r[-1].strip() for _, r in rows):
        rows = [(ln, r[:-1]) for ln, r in rows]
    header_line, header_cells = rows[0]
    has_header = any(not is_number(c, delimiter) for c in header_cells)
    if has_header:
        layout = parse_header(path, header_line, header_cells, [str(n) for n in robot.model.names[1:]],
                              POSE_FIELDS, optional=(ORIENTATION_FIELDS, RPY_FIELDS), aliases=POSE_ALIASES)
        ncol = layout.n_columns
        data_rows = rows[1:]
        columns = [c.strip() for c in header_cells]
        rotation = [f for f in (*ORIENTATION_FIELDS, *RPY_FIELDS) if f in layout.fields]
        if len(rotation) > 3:
            raise DataFileError(path, f"line {header_line}", "two orientations, rx,ry,rz and roll,pitch,yaw: "
                                "give one")
        rpy = rotation == list(RPY_FIELDS)
        order = [*layout.joints, *(layout.fields[f] for f in (*names[nq:], *rotation))]
        factors = np.array([*layout.joint_factors, *(layout.field_factors[f] for f in (*names[nq:], *rotation))])
    else:
        ncol = len(header_cells)
        if ncol not in (nq + 3, nq + 6):
            raise DataFileError(path, f"line {header_line}", f"expected {nq + 3} or {nq + 6} columns "
                                f"({','.join(names)}[,rx,ry,rz]), got {ncol}")
        data_rows = rows
        columns = (names + ["rx", "ry", "rz"])[:ncol]
        order, factors = list(range(ncol)), np.ones(ncol)
        rpy = False
    raw = np.empty((len(data_rows), ncol))
    lines = np.array([ln for ln, _ in data_rows], dtype=int)
    for k, (line, r) in enumerate(data_rows):
        if len(r) != ncol:
            raise DataFileError(path, f"line {line}", f"expected {ncol} columns, got {len(r)}")
        for j, c in enumerate(r):
            try:
                v = number(c, delimiter)
            except ValueError:
                raise DataFileError(path, f"line {line}, {columns[j]}", f"not a number: {c.strip()!r}") from None
            if not np.isfinite(v):
                raise DataFileError(path, f"line {line}, {columns[j]}", f"NaN or infinite value {c.strip()!r}")
            raw[k, j] = v
    if not len(raw):
        raise DataFileError(path, "rows", "no measurement rows")
    values = raw[:, order] * factors[None, :]
    ncol = len(order)
    _check_stated_units(path, values, factors, robot)
    if rpy:   # roll, pitch, yaw: extrinsic x, y, z (R = Rz Ry Rx) as the rotation vector of the same R
        angles = values[:, nq + 3:]
        if np.abs(angles).max() > np.pi + 1e-6:
            k = int(np.argmax(np.abs(angles).max(axis=1)))
            raise DataFileError(path, f"line {lines[k]}, roll,pitch,yaw", f"an angle of {np.abs(angles[k]).max():.4g} "
                                "> pi: roll, pitch and yaw must be in rad (or state the unit: roll_deg)"
                                + (" (the values look like degrees)" if np.abs(angles).max() <= 180 + 1e-6 else ""))
        values[:, nq + 3:] = Rotation.from_euler("xyz", angles).as_rotvec()
    if len(values) < min_rows:
        who = f" ({min_rows_field})" if min_rows_field else ""
        raise DataFileError(path, "rows", f"{len(values)} measurement rows, need at least {min_rows}{who}")
    Q = values[:, :nq]
    _check_joint_angles(path, Q, robot, lines)
    Y = values[:, nq : nq + 3]
    _check_tracker_positions(path, Y, robot, lines, has_header)
    rot = values[:, nq + 3 : nq + 6] if ncol == nq + 6 else None
    if rot is not None:
        norm = np.linalg.norm(rot, axis=1)
        k = int(np.argmax(norm))
        if norm[k] > np.pi + 1e-6:
            cols = "rx,ry,rz" if has_header else f"columns {nq + 4}-{nq + 6}"
            raise DataFileError(path, f"line {lines[k]}, {cols}",
                                f"rotation vector of norm {norm[k]:.4g} > pi: a rotation vector (axis * angle) "
                                "must be in rad" + (" (the values look like degrees)" if norm.max() <= 180 + 1e-6
                                                    else ""))
    return Measurements(Q, Y, noise_model_sigma(robot, Y), str(path), rot, len(Q), np.zeros((0, nq)), None, lines)


#: readings spread over less than this fraction of the reach, or joints spanning less than this angle (rad; angles
#: in rad read as deg span at most 2 pi deg = 0.11 rad),
#: under a header that states mm or deg: the values are in m or rad (the unit stated by mistake)
MIN_SPREAD_OVER_REACH = 0.01
MIN_JOINT_SPAN_RAD = 0.2


def _check_stated_units(path: Path, values: np.ndarray, factors: np.ndarray, robot: RobotModel) -> None:
    """A unit the header states that shrinks the values (mm, deg) must leave a spread a calibration can use:
    values already in m or rad under such a header shrink to a few mm or a few degrees."""
    nq = robot.nq
    if np.any(factors[nq:nq + 3] < 1.0):
        Y = values[:, nq:nq + 3]
        spread = float(np.max(np.linalg.norm(Y - Y.mean(axis=0), axis=1))) if len(Y) > 1 else np.inf
        if spread < MIN_SPREAD_OVER_REACH * reflector_reach_m(robot):
            raise DataFileError(path, "x,y,z", f"the readings spread over {1e3 * spread:.3g} mm only, under a header "
                                "stating mm: the values look like metres (drop the unit from the header)")
    if np.any(factors[:nq] < 1.0):
        span = float(np.max(np.ptp(values[:, :nq], axis=0))) if len(values) > 1 else np.inf
        if span < MIN_JOINT_SPAN_RAD:
            raise DataFileError(path, "joints", f"no joint spans more than {np.degrees(span):.3g} deg, under a header "
                                "stating deg: the values look like radians (drop the unit from the header)")


def _check_joint_angles(path: Path, Q: np.ndarray, robot: RobotModel, lines: np.ndarray) -> None:
    lo, hi = np.asarray(robot.limits.lower_rad, float), np.asarray(robot.limits.upper_rad, float)
    out = (Q < lo - 1e-9) | (Q > hi + 1e-9)
    if not out.any():
        return
    k, j = (int(i) for i in np.argwhere(out)[0])
    Qr = np.radians(Q)
    hint = (" (the values look like degrees)" if not np.any((Qr < lo - 1e-9) | (Qr > hi + 1e-9))
            else "")
    raise DataFileError(path, f"line {lines[k]}, q{j + 1}",
                        f"{Q[k, j]:.6g} is outside the joint limits [{lo[j]:.4f}, {hi[j]:.4f}] rad: joint "
                        f"angles must be in rad{hint}")


def _check_tracker_positions(path: Path, Y: np.ndarray, robot: RobotModel, lines: np.ndarray, has_header: bool) -> None:
    """Reflector positions must fit the robot: at most ``|tracker position| + reach`` from the
    tracker (nominal pose of robot.yaml, with a factor 1.5 of slack for a moved tracker) and spread
    over at most the reach sphere's diameter (independent of the tracker pose)."""
    nq = robot.nq
    cols = "x,y,z" if has_header else f"columns {nq + 1}-{nq + 3}"
    reach = reflector_reach_m(robot)
    tracker = float(np.linalg.norm(robot.tracker.transform_tracker_to_base.translation))
    max_dist = 1.5 * (tracker + reach)
    max_spread = 1.1 * 2.0 * reach
    dist = np.linalg.norm(Y, axis=1)
    # the centroid lies inside the reach sphere, so every reading is within its diameter of it
    dev = np.linalg.norm(Y - Y.mean(axis=0), axis=1)
    spread = float(dev.max())
    facts = (f"the reflector of {robot.name} is at most about {tracker + reach:.2f} m from the tracker "
             f"(tracker {tracker:.2f} m from the base in robot.yaml, reach {reach:.2f} m)")
    if dist.max() > max_dist or spread > max_spread:
        # all readings scaled by 1000 (not one bad row): millimetres
        if np.median(dist) > max_dist and dist.max() / 1000 <= max_dist and spread / 1000 <= max_spread:
            raise DataFileError(path, cols,
                                f"values look like millimetres (largest distance from the tracker "
                                f"{dist.max():.6g}, but {facts}); the file must be in metres")
        if dist.max() > max_dist:
            k = int(np.argmax(dist))
            raise DataFileError(path, f"line {lines[k]}, {cols}",
                                f"reflector {dist[k]:.6g} m from the tracker, but {facts}: positions must "
                                "be in m in the tracker frame")
        k = int(np.argmax(dev))
        raise DataFileError(path, f"line {lines[k]}, {cols}",
                            f"reading {spread:.6g} m from the mean of all readings, but the robot's reflector "
                            f"stays within a sphere of {2 * reach:.2f} m diameter (reach {reach:.2f} m): "
                            "positions must be in m, all in the same tracker frame")


def write_csv(path: str | Path, meas: Measurements) -> Path:
    """Write measurements in the format :func:`read_csv` reads."""
    path = Path(path)
    nq = meas.Q.shape[1]
    header = [f"q{i}" for i in range(1, nq + 1)] + ["x", "y", "z"]
    cols = [meas.Q, meas.Y]
    if meas.rotvec is not None:
        header += ["rx", "ry", "rz"]
        cols.append(meas.rotvec)
    data = np.concatenate(cols, axis=1)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for row in data:
            w.writerow([repr(float(v)) for v in row])
    return path


def min_configurations(n_identifiable: int) -> int:
    """Fewest configurations whose 3 tracker coordinates each can determine ``n_identifiable``
    parameters (no redundancy: a few more are needed when the tracker cannot see some)."""
    return -(-n_identifiable // 3)


def check_rows(use_orientation: bool, user: Measurements, p: int, robot: RobotModel) -> None:
    """Enough independent equations (3 per position row, 6 per 6-D row) for the ``p`` parameters."""
    per_row = 6 if user.rotvec is not None and use_orientation else 3
    need = -(-p // per_row)
    if len(user) < need:
        kind = "position + orientation" if per_row == 6 else "position"
        raise DataFileError(user.source, "rows", f"{len(user)} measurement rows, need at least {need} ({per_row} "
                            f"equations per {kind} row for the {p} identifiable parameters of {robot.name}; "
                            "calibration.parameters selects fewer)")
