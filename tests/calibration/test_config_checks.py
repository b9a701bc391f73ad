"""Range checks of every calibration setting (load time: ``Config.validate``; robot-dependent:
``stage.check``, before anything is written) and unit checks of the measurement CSV reader."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.calibration import candidates as cd
from pipeline.calibration import measure as ms
from pipeline.calibration import stage as st
from pipeline.cli import main
from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.core.errors import ConfigError, DataFileError, InfeasibleError
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot

QUICK = CONFIGS_DIR / "quick.yaml"
GRADIENT = ["calibration.selection_method=gradient", "calibration.index_name=A"]


@pytest.fixture(scope="session")
def robot():
    return RobotModel.load("rx130l")


def _load(*values: str):
    return load_config(QUICK, list(values))


# ------------------------------------------------------------------ load time (robot-independent)
@pytest.mark.parametrize(("values", "field", "words"), [
    ([*GRADIENT, "calibration.n_pilot=-3"], "n_pilot", (">= 0", "-3")),
    (["calibration.n_pilot=-1"], "n_pilot", (">= 0",)),
    ([*GRADIENT, "calibration.n_pilot=2"], "n_pilot", (">= 3", "got 2")),
    ([*GRADIENT, "calibration.n_pilot=40"], "n_pilot", ("n_configurations = 40",)),
    (["calibration.selection_method=gradient", "calibration.index_name=O3"], "selection_method", ("A-type", "'O3'")),
    (["calibration.working_region=sphere"], "working_region", ("iso_cube",)),
    (["calibration.working_region=box"], "working_box_m", ("[[xmin",)),
    (["calibration.gradient_max_iterations=0"], "gradient_max_iterations", (">= 1",)),
    (["calibration.max_lm_iterations=-1"], "max_lm_iterations", (">= 1",)),
    (["calibration.n_heldout=0"], "n_heldout", (">= 1",)),
    (["calibration.n_working_configurations=0"], "n_working_configurations", (">= 1",)),
    (["calibration.identifiability_samples=0"], "identifiability_samples", (">= 1",)),
    (["calibration.identifiability_samples=10000000"], "identifiability_samples", ("at most",)),
    (["calibration.identifiability_rel_tol=0"], "identifiability_rel_tol", ("(0, 1)",)),
    (["calibration.identifiability_rel_tol=2"], "identifiability_rel_tol", ("(0, 1)",)),
    (["calibration.n_random_candidates=10"], "n_random_candidates", ("10", "n_configurations = 40")),
    (["calibration.n_random_candidates=100000000"], "n_random_candidates", ("at most",)),
    (["calibration.grid_per_axis=1"], "grid_per_axis", ("at least 2",)),
    (["calibration.n_initial=41"], "n_initial", ("[1, n_configurations = 40]",)),
    (["calibration.n_initial=0"], "n_initial", ("[1, n_configurations = 40]",)),
    (["calibration.margin_collision_m=-0.01"], "margin_collision_m", ("[0, 1) m",)),
    (["calibration.margin_collision_m=10"], "margin_collision_m", ("[0, 1) m",)),
    (["calibration.margin_beam_m=.nan"], "margin_beam_m", ("[0, 1) m",)),
    (["calibration.margin_incidence_deg=95"], "margin_incidence_deg", ("[0, 90)",)),
    (["calibration.margin_incidence_deg=-1"], "margin_incidence_deg", ("[0, 90)",)),
])
def test_bad_value_names_set_and_field_at_load_time(values, field, words):
    with pytest.raises(ConfigError) as info:
        _load(*values)
    message = str(info.value)
    assert message.startswith(f"--set: calibration.{field}: "), message
    for word in words:
        assert word in message, (word, message)


def test_quick_defaults_pass_all_checks(robot):
    cfg = _load()
    cfg.calibration.validate("quick.yaml")
    st.check(cfg.calibration, robot)
    st.check(st.Config(), robot)           # the full profile's defaults too
    st.check(_load(*GRADIENT).calibration, robot)


def test_user_file_skips_the_design_checks(robot, tmp_path):
    """With a measurement file the design fields are unused: no candidate/configuration checks."""
    cfg = _load("calibration.n_random_candidates=10", "calibration.measurements_csv=x.csv")
    assert cfg.calibration.n_random_candidates == 10


# ------------------------------------------------------------------ check() (robot-dependent)
@pytest.mark.parametrize(("values", "field", "words"), [
    # default parameters "all": 27 geometric + 4 compliances (joints 2-5; joint 1 and 6 carry no gravity load)
    (["calibration.n_configurations=5"], "n_configurations", ("at least 10", "29 identifiable", "got 5")),
    (["calibration.n_initial=4"], "n_initial", ("at least 10", "got 4")),
    ([*GRADIENT, "calibration.n_pilot=35"], "n_pilot", ("40 - 35", "at least 10")),
    (["calibration.parameters=geometric", "calibration.n_configurations=5"], "n_configurations",
     ("at least 9", "27 identifiable")),
    (["calibration.margin_incidence_deg=40"], "margin_incidence_deg", ("30 deg",)),
    (["calibration.identifiability_samples=10"], "identifiability_samples", ("at least 23",)),
    (["calibration.candidates=grid", "calibration.grid_per_axis=30"], "grid_per_axis", ("30^6",)),
])
def test_robot_dependent_checks_name_the_field(robot, values, field, words):
    cfg = _load(*values)
    with pytest.raises(ConfigError) as info:
        st.check(cfg.calibration, robot)
    assert info.value.field == f"calibration.{field}", str(info.value)
    for word in words:
        assert word in info.value.problem, (word, info.value.problem)


def test_cli_too_few_configurations_is_reported_before_anything_is_written(tmp_path, capsys):
    code = main(["run", "--config", str(QUICK), "--stages", "calibration", "--out", str(tmp_path / "runs"),
                 "--set", "calibration.n_configurations=5"])
    err = capsys.readouterr().err
    assert code == 2
    assert "--set: calibration.n_configurations: need at least 10" in err
    assert "Traceback" not in err
    assert not (tmp_path / "runs").exists()


def test_too_few_feasible_candidates_speaks_in_the_users_fields(robot):
    cfg = _load("calibration.candidates=grid", "calibration.grid_per_axis=3").calibration
    cfg.figures = False
    with pytest.raises(InfeasibleError) as info:
        st.calibrate(robot, RealRobot.create(robot, 1), cfg, np.random.default_rng(0))
    message = str(info.value)
    assert info.value.field == "calibration.grid_per_axis", message
    assert "40 configurations" in message and "3^6" in message
    assert "26" not in message   # not the internal initial subset size


# ------------------------------------------------------------------ measurement CSV: units, lines
@pytest.fixture(scope="session")
def measured(robot):
    """Simulated readings of the hidden robot (its tracker pose differs from the nominal one)."""
    rng = np.random.default_rng(0)
    Q, _ = cd.random_candidates(cd.chain_from_robot(robot), 40, rng)
    return ms.measure_simulated(RealRobot.create(robot, 3), Q, rng)


def _copy(m, **kw):
    d = {"Q": m.Q.copy(), "Y": m.Y.copy(), "sigma_m": m.sigma_m, "source": m.source}
    d.update(kw)
    return ms.Measurements(**d)


def test_good_file_passes(robot, measured, tmp_path):
    path = ms.write_csv(tmp_path / "good.csv", measured)
    back = ms.read_csv(path, robot, min_rows=27)
    np.testing.assert_allclose(back.Y, measured.Y)


def test_positions_in_millimetres_are_detected(robot, measured, tmp_path):
    path = ms.write_csv(tmp_path / "mm.csv", _copy(measured, Y=measured.Y * 1000))
    with pytest.raises(DataFileError) as info:
        ms.read_csv(path, robot, min_rows=27)
    message = str(info.value)
    assert message.startswith(f"{path}: x,y,z: values look like millimetres"), message
    assert "the file must be in metres" in message
    # without a header the columns are named by number
    text = path.read_text().splitlines()[1:]
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(DataFileError, match="columns 7-9: values look like millimetres"):
        ms.read_csv(path, robot)


def test_one_far_reading_names_its_file_line(robot, measured, tmp_path):
    Y = measured.Y.copy()
    Y[4] *= 40.0     # 100 m from the tracker
    path = ms.write_csv(tmp_path / "far.csv", _copy(measured, Y=Y))
    with pytest.raises(DataFileError) as info:
        ms.read_csv(path, robot)
    assert info.value.field == "line 6, x,y,z", str(info.value)   # header = line 1, row 4 = line 6
    assert "from the tracker" in info.value.problem


def test_joint_angles_in_degrees_are_detected(robot, measured, tmp_path):
    path = ms.write_csv(tmp_path / "deg.csv", _copy(measured, Q=np.degrees(measured.Q) * 0.3))
    with pytest.raises(DataFileError) as info:
        ms.read_csv(path, robot)
    assert "must be in rad" in str(info.value) and "line " in info.value.field


def test_rotation_vector_in_degrees_is_detected(robot, measured, tmp_path):
    m = _copy(measured)
    m.rotvec = np.tile([0.0, 0.0, 90.0], (len(m.Q), 1))
    path = ms.write_csv(tmp_path / "rot.csv", m)
    with pytest.raises(DataFileError, match=r"line 2, rx,ry,rz: rotation vector .* look like degrees"):
        ms.read_csv(path, robot)


def test_errors_give_the_file_line_counting_blank_lines(robot, measured, tmp_path):
    path = ms.write_csv(tmp_path / "lines.csv", measured)
    lines = path.read_text().splitlines()
    lines.insert(3, "")          # blank lines: the file line is what an editor shows
    lines.insert(3, "   ")
    bad = lines[10].split(",")
    bad[2] = "abc"
    lines[10] = ",".join(bad)    # file line 11
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFileError) as info:
        ms.read_csv(path, robot)
    assert info.value.field == "line 11, q3", str(info.value)
    lines[10] = ",".join(bad[:-1])
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFileError, match="line 11: expected 9 columns, got 8"):
        ms.read_csv(path, robot)


def test_too_few_rows_names_the_reason(robot, measured, tmp_path):
    path = ms.write_csv(tmp_path / "few.csv", _copy(measured, Q=measured.Q[:5], Y=measured.Y[:5]))
    cfg = _load(f"calibration.measurements_csv={path}").calibration
    with pytest.raises(DataFileError, match="5 measurement rows, need at least 10 .3 equations per position row"):
        st.check(cfg, robot)


def test_the_grid_per_axis_default_follows_the_number_of_axes():
    """None: the paper's 13 values per axis for 6 axes, and no larger a grid for more axes."""
    cfg = _load().calibration
    assert cfg.grid_per_axis is None and cfg.grid_points_per_axis(6) == 13
    for nq in (5, 7, 8):
        k = cfg.grid_points_per_axis(nq)
        assert k**nq <= 13**6 < (k + 1) ** nq
