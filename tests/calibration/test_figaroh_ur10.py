"""FIGAROH's UR10 6-D motion-capture record (recorded, data/figaroh_ur10_mocap): the URDF as shipped,
robot.yaml from `robot init` unedited, the CSV converted in layout only (tools/mocap_rpy_csv.py)."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.calibration import error_model as em
from pipeline.calibration import marker_frame as mf
from pipeline.calibration import measure as ms
from pipeline.calibration import model_selection as msel
from pipeline.calibration import stage as st
from pipeline.calibration import validate as va
from pipeline.calibration.config import Config
from pipeline.calibration.estimate import estimate, register_points
from pipeline.exchange.motion import JointStates, TrackerPoints
from pipeline.exchange.ros2_bag import POSE_STAMPED, write_recording
from pipeline.robot.model import RobotModel
from pipeline.robot.yaml_init import write_robot_yaml

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "data" / "figaroh_ur10_mocap"
JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint"]
#: FIGAROH 1.0.2's leave-one-out held-out RMS on this record (README): the selection's cross-validation
#: holds out whole neighbourhoods of joint space (spatial folds), a harder test than leaving one pose out
FIGAROH_POSITION_M = 4.15e-3
TARGET_ORIENTATION_RAD = np.radians(0.5)


def _converter():
    spec = importlib.util.spec_from_file_location("mocap_rpy_csv", REPO / "tools" / "mocap_rpy_csv.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def record(tmp_path_factory) -> tuple[RobotModel, ms.Measurements]:
    folder = tmp_path_factory.mktemp("ur10")
    shutil.copy(DATA / "robot.urdf", folder / "robot.urdf")
    write_robot_yaml(folder / "robot.urdf")
    robot = RobotModel.load(folder)
    path = _converter().convert(DATA / "calibration.csv", folder / "ur10.csv", JOINTS)
    return robot, ms.read_csv(path, robot)


def _orientation_gap_rad(robot: RobotModel, meas: ms.Measurements) -> float:
    """RMS angle between the read orientations and the nominal reflector frame's (tracker registered)."""
    mm = em.MeasurementModel(robot, marker_points=True)
    P, R_refl = mm.base_positions(meas.Q, np.zeros(mm.n), None, np.zeros((len(meas), 3)))
    T = register_points(meas.Y, P)
    R_meas = Rotation.from_rotvec(meas.rotvec).as_matrix()
    R_pred = np.einsum("ji,njk->nik", T.rotation, R_refl)
    ang = np.linalg.norm(Rotation.from_matrix(np.einsum("nji,njk->nik", R_pred, R_meas)).as_rotvec(), axis=1)
    return float(np.sqrt(np.mean(ang ** 2)))


def test_conversion_keeps_every_value(record):
    robot, meas = record
    assert len(meas) == 23 and meas.rotvec is not None
    raw = np.genfromtxt(DATA / "calibration.csv", delimiter=",", names=True)
    assert np.array_equal(meas.Y, np.column_stack([raw["x1"], raw["y1"], raw["z1"]]))
    R = Rotation.from_euler("xyz", np.column_stack([raw["phix1"], raw["phiy1"], raw["phiz1"]])).as_matrix()
    assert np.allclose(Rotation.from_rotvec(meas.rotvec).as_matrix(), R, atol=1e-12)


def test_figarohs_own_csv_reads_as_it_is_shipped(record):
    """FIGAROH's layout (x1,y1,z1, roll-pitch-yaw phix1..phiz1, joints by name) is read without the converter."""
    robot, meas = record
    direct = ms.read_csv(DATA / "calibration.csv", robot)
    np.testing.assert_array_equal(direct.Q, meas.Q)
    np.testing.assert_array_equal(direct.Y, meas.Y)
    assert direct.rotvec is not None and meas.rotvec is not None
    np.testing.assert_allclose(direct.rotvec, meas.rotvec, rtol=0, atol=1e-15)


def test_the_record_as_a_ros2_recording_reads_as_the_csv(record, tmp_path):
    """The 23 poses as a mocap setup logs them: JointState at 100 Hz (1 s quintic moves, 1.5 s dwells) and
    the marker's PoseStamped at 50 Hz during each dwell, the first 0.1 s of it 1 cm and 0.1 rad off (the arm
    settling). Read in its stationary windows: the CSV's joint angles, positions and orientations."""
    robot, meas = record
    names = tuple(str(n) for n in robot.model.names[1:])
    t, q, tp, xyz, rv = [], [], [], [], []
    clock, previous = 0.0, meas.Q[-1]
    for k in range(len(meas)):
        for s in np.arange(0.0, 1.0, 0.01):                 # the move from the previous pose
            x = s / 1.0
            t.append(clock + s)
            q.append(previous + (10 * x**3 - 15 * x**4 + 6 * x**5) * (meas.Q[k] - previous))
        clock += 1.0
        for s in np.arange(0.0, 1.5, 0.01):                 # the dwell
            t.append(clock + s)
            q.append(meas.Q[k])
        for s in np.arange(0.005, 1.4, 0.02):
            off = s < 0.1
            tp.append(clock + s)
            xyz.append(meas.Y[k] + (0.01 if off else 0.0))
            rv.append((Rotation.from_rotvec([0.1, 0, 0]) * Rotation.from_rotvec(meas.rotvec[k])).as_rotvec()
                      if off else meas.rotvec[k])
        clock += 1.5
        previous = meas.Q[k]
    t = np.array(t)
    states = JointStates(names, t, np.array(q), np.full((len(t), len(names)), np.nan), np.zeros((len(t), len(names))))
    bag = write_recording(tmp_path / "mocap", states, TrackerPoints(np.array(tp), np.array(xyz), "mocap", np.array(rv)),
                          "/mocap/marker/pose", msgtype=POSE_STAMPED)
    read = ms.read_measurements(bag, robot, Config(measurements_file=str(bag)))
    assert read.windows_found == len(read) == len(meas)
    np.testing.assert_allclose(read.Q, meas.Q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(read.Y, meas.Y, rtol=0, atol=1e-12)
    np.testing.assert_allclose(Rotation.from_rotvec(read.rotvec).as_matrix(),
                               Rotation.from_rotvec(meas.rotvec).as_matrix(), rtol=0, atol=1e-12)


def test_marker_rotation_on_the_flange_is_found_in_closed_form(record):
    """The marker is turned about 30 deg on the flange (README); after the alignment the readings
    agree with the nominal reflector frame to the nominal arm's own errors (a few degrees)."""
    robot, meas = record
    R_m, aligned, _ = mf.align_records(robot, meas, None)
    assert 20.0 < mf.mount_rotation_deg(R_m) < 40.0
    before, after = _orientation_gap_rad(robot, meas), _orientation_gap_rad(robot, aligned)
    assert before > np.radians(15.0) and after < 0.2 * before


def _robot_with_reflector_at(folder: Path, offset_m: list[float]) -> RobotModel:
    folder.mkdir()
    shutil.copy(DATA / "robot.urdf", folder / "robot.urdf")
    write_robot_yaml(folder / "robot.urdf")
    text = (folder / "robot.yaml").read_text()
    start = text.index("reflector_offset_m: [")
    end = text.index("]", start)
    (folder / "robot.yaml").write_text(text[:start] + f"reflector_offset_m: {offset_m}" + text[end + 1:])
    return RobotModel.load(folder)


def test_marker_rotation_does_not_depend_on_the_stated_reflector_offset(record, tmp_path):
    """The marker sits about 12 cm off the last joint's axis: registered on the record's own marker
    origins, the closed-form rotation is the same for a reflector stated on that axis at 0 or 100 mm,
    and differs from the rotation registered on the nominal origin by more than a degree."""
    _, meas = record
    rotations, origins = [], []
    for k, z in enumerate((0.0, 0.1)):
        robot = _robot_with_reflector_at(tmp_path / f"z{k}", [0.0, 0.0, z])
        mm = em.MeasurementModel(robot, marker_points=True)
        rotations.append(mf.marker_rotation_on_flange(mm, meas))
        P, R_refl = mm.base_positions(meas.Q, np.zeros(mm.n), None, np.zeros((len(meas), 3)))
        d = mf.record_marker_origin(P, R_refl, meas.Y)
        assert d is not None
        origins.append(np.array([0.0, 0.0, z]) + d)    # the reflector frame is tool0's, unturned
    assert np.allclose(rotations[0], rotations[1], atol=1e-9)
    assert np.allclose(origins[0], origins[1], atol=1e-9) and np.hypot(*origins[0][:2]) > 0.1
    R_nominal = mf.project_to_rotation(np.einsum(
        "nji,jk,nkl->nil", R_refl, register_points(meas.Y, P).rotation,
        Rotation.from_rotvec(meas.rotvec).as_matrix()).sum(axis=0))
    assert mf.mount_rotation_deg(R_nominal.T @ rotations[1]) > 1.0


#: session fixtures that take seconds and serve several tests: their tests run on one pytest-xdist
#: worker, so each is built once per ``make test`` (tests/conftest.py, pytest_collection_modifyitems)
SHARED_COSTLY_FIXTURES = frozenset({"selection"})


@pytest.fixture(scope="session")
def selection(record) -> msel.ModelSelection:
    """parameters auto on the record with every default: the sensor sigma of robot.yaml, the noise
    model's REML remainder per training fold and the orientation weight by cross-validation (nested
    for the held-out figures)."""
    robot, meas = record
    cfg = st.Config(measurements_csv="recorded", figures=False)
    _, aligned, _ = mf.align_records(robot, meas, None)
    chosen_cfg, sel = msel.choose_parameters(robot, cfg, aligned, True, np.random.default_rng(0),
                                             st.identify_parameter_set)
    assert sel is not None and chosen_cfg.parameters == sel.chosen.parameters
    return sel


def test_auto_meets_the_published_figures_over_all_poses(selection):
    """One test of the selection (the costliest fit of the suite: built once, not once per test
    worker): the nested figures over all poses (each fold's orientation weight chosen on its own
    training poses), and the final fit's weight the best factor tried on the whole record."""
    cv = selection.cross_validation()
    assert selection.folds == 5 and cv["n_poses"] + cv["n_gross_left_out"] == 23
    assert cv["rms_position_error_all_poses_m"] <= FIGAROH_POSITION_M
    assert cv["rms_orientation_error_all_poses_rad"] <= TARGET_ORIENTATION_RAD
    # every candidate scored every held-out pose, in position and orientation
    for s in selection.scores:
        assert s.valid and np.all(np.isfinite(s.orientation_error_rad))
    # 23 poses cannot support joint compliances on top of the geometry
    assert selection.chosen.parameters != "all"
    assert "one-standard-error" in selection.markdown() and "(chosen)" in selection.markdown()
    # the summary's excess of each candidate, recomputed from the table's own CV figures (MSE = RMS^2
    # and the best's SE, position and orientation): the chosen one within the band, every simpler
    # one beyond it
    rows = selection.as_dict()["candidates"]
    excess = np.zeros(len(rows))
    for rms, se in (("rms_position_error_m", "se_position_mse_m2"), ("rms_orientation_error_rad",
                                                                     "se_orientation_mse_rad2")):
        mse = np.array([r[rms] ** 2 for r in rows])
        best = int(np.argmin(mse))
        excess = np.maximum(excess, (mse - mse[best]) / rows[best][se])
    assert [r["standard_errors_above_best"] for r in rows] == pytest.approx(list(excess), rel=1e-9, abs=1e-9)
    band = max(1.0, float(excess.min()))
    chosen = next(r for r in rows if r["candidate"] == selection.chosen.name)
    assert chosen["standard_errors_above_best"] <= band
    assert all(r["standard_errors_above_best"] > band for r in rows if r["n_parameters"] < chosen["n_parameters"])
    # the factor on the marker-point rows' sigma minimises the relative CV score among those tried
    tried = {k: (p, r) for k, p, r in selection.orientation_scales_tried}
    assert 1.0 in tried and selection.orientation_scale in tried and len(tried) >= 3
    p1, r1 = tried[1.0]
    score = {k: (p / p1) ** 2 + (r / r1) ** 2 for k, (p, r) in tried.items()}
    assert score[selection.orientation_scale] == min(score.values())
    assert "orientation weight" in selection.markdown()
    # nested: the reported figures are the chosen model's with each fold's own weight, chosen by an
    # inner cross-validation of that fold's training poses; the folds' training sets differ and so
    # do their weights, so the figures are not those of the table (one weight chosen on every fold)
    per_fold = selection.fold_orientation_scales
    assert per_fold is not None and len(per_fold) == 5 and cv["orientation_weight_scale_per_fold"] == per_fold
    assert set(per_fold) <= set(msel.ORIENTATION_SCALES) and len(set(per_fold)) > 1
    nested = selection.nested
    assert nested is not None and nested.candidate == selection.chosen
    assert cv["rms_position_error_all_poses_m"] == pytest.approx(np.sqrt(np.mean(nested.position_error_m ** 2)))
    table = selection.score_of(selection.chosen)
    assert not np.allclose(nested.position_error_m, table.position_error_m)
    assert "nested" in selection.markdown()


def test_two_gross_readings_of_four_held_out_are_left_out_and_still_counted(record, tmp_path):
    """A recorded held-out file of four poses, two of them shifted by 25 mm (about 15 sigma): the
    screen scales its chi-square bound by the calibration fit's residual scale, not by a median over
    the four held-out readings (which the two gross ones break), so exactly those two are left out of
    the gated figures, within max_outlier_fraction of the whole record; the errors over every
    held-out pose stand beside them."""
    robot, _ = record
    src = _converter().convert(DATA / "calibration.csv", tmp_path / "ur10.csv", JOINTS).read_text().splitlines()
    head, rows = src[0], src[1:]
    held_idx, drop = [3, 8, 13, 18], {14, 19}    # 14, 19: the record's own far-off poses, out of the test
    shifted = []
    for k, i in enumerate(held_idx):
        v = rows[i].split(",")
        if k < 2:
            v[6] = repr(float(v[6]) + 0.025)
        shifted.append(",".join(v))
    train = tmp_path / "train.csv"
    train.write_text("\n".join([head] + [r for i, r in enumerate(rows) if i not in drop and i not in held_idx]) + "\n")
    val = tmp_path / "val.csv"
    val.write_text("\n".join([head] + shifted) + "\n")
    cfg = st.Config(measurements_csv=str(train), validation_csv=str(val), parameters="joint_offsets", figures=False)
    cfg.validate()
    out = st.calibrate(robot, None, cfg, np.random.default_rng(0))
    v = out.validation
    assert v["n_poses"] == 4 and v["rejected_rows"] == [0, 1]
    assert v["after_all_poses"]["rms"] > 3 * v["after"]["rms"] and v["after"]["rms"] < 6e-3
    assert "Over every held-out reading" in va.table_markdown(v)


def test_a_heldout_file_of_one_far_off_pose_is_scored_not_emptied(record, tmp_path):
    """Leave-one-out through the stage: a held-out file of the far-off pose 19 alone. The screen
    would leave it out (within the record's allowance), which leaves nothing to score; it leaves
    out no reading of a file whose every reading fails, so the pose is scored as it is."""
    robot, _ = record
    src = _converter().convert(DATA / "calibration.csv", tmp_path / "ur10.csv", JOINTS).read_text().splitlines()
    head, rows = src[0], src[1:]
    (tmp_path / "train.csv").write_text("\n".join([head] + [r for i, r in enumerate(rows) if i != 19]) + "\n")
    (tmp_path / "val.csv").write_text("\n".join([head, rows[19]]) + "\n")
    cfg = st.Config(measurements_csv=str(tmp_path / "train.csv"), validation_csv=str(tmp_path / "val.csv"),
                    parameters="geometric", figures=False)
    cfg.validate()
    v = st.calibrate(robot, None, cfg, np.random.default_rng(0)).validation
    assert v["n_poses"] == 1 and v["n_rejected"] == 0
    assert v["after_all_poses"]["rms"] == pytest.approx(v["after"]["rms"])
    assert v["after"]["rms"] > 5e-3      # the pose is 6-9 mm off under every model of the record


def test_six_d_heldout_file_reports_orientation_and_every_reading_in_the_summary(record, tmp_path):
    """A held-out file of the record's own poses, 14 and 19 among them (the far-off pair the
    outlier test leaves out): the summary holds the held-out orientation error (screened, and
    over every reading) and the position error over every reading, equal to the validation's own
    figures recomputed from the readings, so a comparison with a published figure needs no report
    parsing."""
    robot, _ = record
    src = _converter().convert(DATA / "calibration.csv", tmp_path / "ur10.csv", JOINTS).read_text().splitlines()
    head, rows = src[0], src[1:]
    held = [2, 6, 14, 19, 21]
    (tmp_path / "train.csv").write_text("\n".join([head] + [r for i, r in enumerate(rows) if i not in held]) + "\n")
    (tmp_path / "val.csv").write_text("\n".join([head] + [rows[i] for i in held]) + "\n")
    cfg = st.Config(measurements_csv=str(tmp_path / "train.csv"), validation_csv=str(tmp_path / "val.csv"),
                    parameters="geometric", figures=False)
    cfg.validate()
    out = st.calibrate(robot, None, cfg, np.random.default_rng(0))
    s, v = st.summary_of(out, cfg), out.validation
    # recomputed here from the held-out readings and the handed-on estimate
    train = ms.read_csv(tmp_path / "train.csv", robot)
    _, _, val = mf.align_records(robot, train, ms.read_csv(tmp_path / "val.csv", robot))   # as the stage does
    mm = em.MeasurementModel(robot, marker_points=True)
    est = out.estimate
    e = (val.Y - mm.predict(val.Q, est.x, est.registration, None, np.zeros((len(val), 3))))
    every_pos = float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))))
    assert s["heldout_rms_position_error_all_poses_after_m"] == pytest.approx(every_pos, rel=1e-6)
    every_rot = va.orientation_stats(mm, est.x, est.transform_tracker_to_base.rotation, val.Q, val.rotvec)
    assert every_rot["rms"] < np.radians(2.0)
    assert s["heldout_rms_orientation_error_all_poses_after_rad"] == pytest.approx(every_rot["rms"], rel=1e-9)
    assert s["heldout_rms_orientation_error_after_rad"] == v["after"]["orientation_rad"]["rms"]
    assert s["heldout_rms_orientation_error_before_rad"] > 3 * s["heldout_rms_orientation_error_after_rad"]
    assert 0 < s["heldout_predicted_rms_orientation_error_rad"] < s["heldout_rms_orientation_error_before_rad"]
    # the camera's orientation noise comes from the fit, far above robot.yaml's stated 1 mrad
    assert s["heldout_orientation_noise_sigma_rad"] > 2 * cfg.orientation_sigma_rad
    ratio = s["heldout_rms_orientation_error_after_rad"] / s["heldout_predicted_rms_orientation_error_rad"]
    assert 1 / 1.5 < ratio < 1.5
    # the far-off pair is left out of the screened figures and counted in the every-reading ones
    assert v["n_rejected"] >= 1
    assert s["heldout_rms_position_error_all_poses_after_m"] > s["heldout_rms_position_error_after_m"]
    assert "orientation RMS" in va.table_markdown(v)


def test_orientation_noise_needs_more_orientation_rows_than_parameters(record):
    """The orientation remainder is estimated on the poses the fit kept; with no more of their rows
    than fitted parameters there is nothing to estimate and the stated sigma stands."""
    robot, meas = record
    _, aligned, _ = mf.align_records(robot, meas, None)
    mm = em.MeasurementModel(robot, marker_points=True)
    rec = ms.expand_orientation(aligned, 1e-3)
    _, basis = st.identify_parameter_set(robot, mm, st.Config(identifiability_samples=60), np.random.default_rng(0))
    est = estimate(mm, rec.Q, rec.Y, np.full(len(rec), 2e-3), basis, "ur10", 50, None, rec.offset_m)
    sigma, tau = va.orientation_noise_rad(mm, est, rec, np.zeros(0, int), 1e-3)
    assert tau > 1e-3 and sigma == pytest.approx(np.hypot(1e-3, tau))
    all_but_two = np.flatnonzero(rec.pose_index >= 2)
    assert va.orientation_noise_rad(mm, est, rec, all_but_two, 1e-3) == (1e-3, 0.0)
