"""Bad values of the ``trajectory`` section are ConfigErrors naming the dotted field (and the file
or ``--set``) at load time or in ``stage.check`` before anything runs; good configs still pass."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

from pipeline.core.config import CONFIGS_DIR, REPO_ROOT, load_config
from pipeline.core.errors import ConfigError
from pipeline.robot.iso9283 import ISO_SEGMENTS
from pipeline.trajectory import stage
from pipeline.trajectory.config import CP_SEGMENTS, PTP_ENERGIES, TrajectoryConfig
from pipeline.trajectory.ptp import energy_weights

T = "trajectory."
BAD = [
    # (field, bad value, field named by the error)
    ("torque_reserve", -0.1, "torque_reserve"),
    ("torque_reserve", 1.0, "torque_reserve"),
    ("cp_segment", "rectangle", "cp_segment"),
    ("cp_points_m", [[0.9, 0.0, 0.3], [1.0, 0.1]], "cp_points_m[1]"),
    ("cp_edge_m", 0.0, "cp_edge_m"),
    ("cp_centre_m", [0.9, 0.0], "cp_centre_m"),
    ("cp_centre_m", [0.9, 0.0, float("inf")], "cp_centre_m[2]"),
    ("cp_plane", "bogus", "cp_plane"),
    ("cp_ik_points", 5, "cp_ik_points"),
    ("cp_ik_seed_deg", [], "cp_ik_seed_deg"),
    ("cp_max_ik_step_deg", 0.0, "cp_max_ik_step_deg"),
    ("cp_n_grid", 0, "cp_n_grid"),
    ("cp_torque_margin", -0.01, "cp_torque_margin"),
    ("cp_torque_margin", 1.0, "cp_torque_margin"),
    ("cp_smooth_intervals", 2, "cp_smooth_intervals"),
    ("cp_smooth_jerk_rise_time_s", 0.0, "cp_smooth_jerk_rise_time_s"),
    ("cp_smooth_torque_margin", -0.1, "cp_smooth_torque_margin"),
    ("ptp_start_deg", [], "ptp_start_deg"),
    ("ptp_goal_deg", [-45.0, 20.0, 30.0, 0.0, 40.0, 0.0], "ptp_goal_deg"),         # = start: no move
    ("ptp_n_intervals", 5, "ptp_n_intervals"),
    ("ptp_k1", -1.0, "ptp_k1"),
    ("ptp_k2", 0.0, "ptp_k2"),
    ("ptp_energy", "joules", "ptp_energy"),
    ("ptp_pareto_k2", [0.01, -1.0], "ptp_pareto_k2[1]"),
    ("ptp_pareto_k2", [0.0], "ptp_pareto_k2[0]"),
    ("ptp_jit_flags", ["O1"], "ptp_jit_flags[0]"),
    ("ptp_jit_flags", ["-O1 -g"], "ptp_jit_flags[0]"),
    ("ptp_coulomb_widths_rad_s", [1.0, 0.0], "ptp_coulomb_widths_rad_s[1]"),
    ("ptp_fixed_coulomb_widths_rad_s", [-0.3], "ptp_fixed_coulomb_widths_rad_s[0]"),
    ("motor_resistance_ohm", [0.6, 0.6, 0.0, 2.5, 2.5, 3.0], "motor_resistance_ohm[2]"),
    ("torque_constant_Nm_A", [0.9, -0.9, 0.6, 0.35, 0.3, 0.3], "torque_constant_Nm_A[1]"),
    ("ruckig_check_dt_s", 0.0, "ruckig_check_dt_s"),
    ("ruckig_check_dt_s", 1e-3, "ruckig_check_dt_s"),
    ("ruckig_jerk_ratios_1_s", [], "ruckig_jerk_ratios_1_s"),
    ("ruckig_jerk_ratios_1_s", [25.0, 0.0], "ruckig_jerk_ratios_1_s[1]"),
    ("ruckig_joint_rounds", -1, "ruckig_joint_rounds"),
    ("ruckig_refine_evaluations", -1, "ruckig_refine_evaluations"),
    ("fine_dt_s", 0.0, "fine_dt_s"),
    ("fine_dt_s", 0.01, "fine_dt_s"),
    ("violation_tolerance", -0.005, "violation_tolerance"),
    ("max_tightening_rounds", -1, "max_tightening_rounds"),
]


@pytest.mark.parametrize(("key", "value", "field_name"), BAD, ids=[f"{k}={v!r}" for k, v, _ in BAD])
def test_bad_value_is_a_config_error_naming_the_field(key, value, field_name):
    with pytest.raises(ConfigError) as err:
        load_config(CONFIGS_DIR / "quick.yaml", values={T + key: value})
    assert err.value.field == T + field_name
    assert err.value.file == "--set"


@pytest.mark.parametrize(("points", "field_name"), [([[0.9, 0.0, 0.3], [0.9, 0.1, 0.3]], "cp_points_m"),
                                                    ([[0.9, 0.0, 0.3], [0.9, 0.0, 0.3], [0.9, 0.1, 0.3]],
                                                     "cp_points_m[1]")])
def test_bad_spline_points(points, field_name):
    with pytest.raises(ConfigError) as err:
        load_config(values={T + "cp_segment": "spline", T + "cp_points_m": points})
    assert err.value.field == T + field_name


def test_good_configs_pass(rx130l, shipped_configs):
    for cfg, robot in shipped_configs:
        stage.check(cfg.trajectory, robot)
    # allowed edge values: no Pareto sweep, no continuation, k1 = 0, no tightening, spline
    ok = load_config(values={T + "ptp_pareto_k2": [], T + "ptp_coulomb_widths_rad_s": [], T + "ptp_k1": 0.0,
                             T + "ptp_fixed_coulomb_widths_rad_s": [], T + "ptp_jit_flags": [],
                             T + "max_tightening_rounds": 0, T + "torque_reserve": 0.0, T + "fine_dt_s": 5e-4,
                             T + "cp_segment": "spline",
                             T + "cp_points_m": [[0.9, -0.2, 0.3], [1.0, 0.0, 0.35], [0.9, 0.2, 0.3]]})
    stage.check(ok.trajectory, rx130l)
    TrajectoryConfig(ptp_pareto_k2=[]).validate()


@pytest.mark.parametrize(("field_name", "value", "match"),
                         [("ptp_start_deg", [0.0] * 5, "6 numbers"), ("ptp_goal_deg", [0.0] * 7, "6 numbers"),
                          ("cp_ik_seed_deg", [0.0, 17.0, 86.0], "6 numbers"),
                          ("motor_resistance_ohm", [1.0] * 5, "6 numbers"),
                          ("torque_constant_Nm_A", [1.0] * 7, "6 numbers"),
                          ("ptp_goal_deg", [0, 170, 0, 0, 0, 0], "joint 2")])
def test_robot_dependent_checks(rx130l, field_name, value, match):
    cfg = load_config(values={T + field_name: value}).trajectory       # robot-independent: accepted
    with pytest.raises(ConfigError, match=match) as err:
        stage.check(cfg, rx130l)
    assert err.value.field == T + field_name


def test_check_also_validates_configs_changed_in_python(rx130l):
    base = load_config().trajectory
    with pytest.raises(ConfigError) as err:
        stage.check(dataclasses.replace(base, max_tightening_rounds=-1), rx130l)
    assert err.value.field == T + "max_tightening_rounds"


def test_bad_robot_run_defaults_names_robot_yaml(tmp_path):
    robot = tmp_path / "myrobot"
    shutil.copytree(REPO_ROOT / "robots" / "staubli_tx40", robot)
    text = (robot / "robot.yaml").read_text()
    assert "cp_centre_m: [0.35, 0.0, 0.2]" in text
    (robot / "robot.yaml").write_text(text.replace("cp_centre_m: [0.35, 0.0, 0.2]", "cp_centre_m: [0.35, 0.0]"))
    with pytest.raises(ConfigError) as err:
        load_config(CONFIGS_DIR / "quick.yaml", values={"robot": str(robot)})
    assert err.value.field == T + "cp_centre_m"
    assert str(robot / "robot.yaml") in err.value.file
    # a later layer that sets the field repairs it
    load_config(CONFIGS_DIR / "quick.yaml", values={"robot": str(robot), T + "cp_centre_m": [0.35, 0.0, 0.2]})


def test_allowed_sets_match_the_planner(pm):
    assert set(CP_SEGMENTS) - {"spline"} <= set(ISO_SEGMENTS)    # smooth pieces the ISO path builder draws
    motors = {"motor_resistance_ohm": [1.0] * pm.nq, "torque_constant_Nm_A": [0.5] * pm.nq}   # no default
    cfg = TrajectoryConfig(**motors)
    for kind in PTP_ENERGIES:           # the planner knows every energy measure the config allows
        w = energy_weights(pm, kind, cfg.motor_resistance_ohm, cfg.torque_constant_Nm_A, np.ones(pm.nq))
        assert np.all(np.asarray(w) > 0)
