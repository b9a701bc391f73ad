"""``python -m pipeline export``: a bad run directory ends in one line, exit 2, nothing written; a motion
that leaves a limit is refused; the samples of moves and re-sampled plans keep the limits; servo_gains.yaml
reads back exactly, whatever the joints are called; the exported robot folder loads back as the model handed on."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy

from pipeline.cli import main
from pipeline.core.errors import InfeasibleError
from pipeline.core.yaml12 import load_yaml
from pipeline.exchange.joint_limits import JointLimitTable
from pipeline.exchange.motion import SampledMotion
from pipeline.exchange.parameter_table import read_parameter_table_csv
from pipeline.robot.defaults import ready_pose_rad
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.run import export_motions as em
from pipeline.run.export import calibration_parameters, robot_files, servo_gains_yaml
from pipeline.run.export_motions import ExportContext
from pipeline.stage_api import StageOutput


@pytest.mark.parametrize("make", ["missing", "empty", "not_a_run"])
def test_a_bad_run_directory_is_one_line_exit_2_and_nothing_written(tmp_path: Path, capsys, make: str) -> None:
    run = tmp_path / "run"
    if make != "missing":
        run.mkdir()
    if make == "not_a_run":
        (run / "config.yaml").write_text("seed: [unclosed\n")
    out = tmp_path / "out"
    assert main(["export", str(run), "--to", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and str(run) in err
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_moves_keep_the_limits_and_a_motion_over_a_limit_is_refused(rx130l) -> None:
    limits = JointLimitTable.of_model(rx130l)
    q0 = ready_pose_rad(rx130l)
    q1 = q0 + 0.3 * np.sign(0.5 * (limits.lower_rad + limits.upper_rad) - q0 + 1e-9)
    zero = np.zeros(rx130l.nq)
    t, q, v, a = em.move(rx130l, limits, (q0, zero, zero), (q1, zero, zero), 500.0, "move")
    np.testing.assert_allclose(q[[0, -1]], [q0, q1], atol=1e-12)
    np.testing.assert_allclose(v[[0, -1]], 0.0, atol=1e-9)
    assert np.all(np.abs(v) <= em.MOVE_LIMIT_FRACTION * limits.velocity_rad_s + 1e-9)
    motion = em.joined(rx130l, [(t, q, v, a)], rx130l)
    em.check_limits(motion, limits, "move")
    over = 1.01 / np.max(np.abs(motion.qd_rad_s) / limits.velocity_rad_s)    # one sample 1 % over
    fast = SampledMotion(motion.joint_names, motion.t_s, motion.q_rad, over * motion.qd_rad_s, motion.qdd_rad_s2,
                         motion.tau_ff_Nm)
    with pytest.raises(InfeasibleError, match="qd_rad_s of joint .* over its velocity limit"):
        em.check_limits(fast, limits, "move")


def test_a_stored_plan_resampled_keeps_its_samples_and_derivatives() -> None:
    t = np.linspace(0.0, 2.0, 201)
    q = np.column_stack([np.sin(t), t ** 3])
    tr, qr, vr, ar = em.resample_plan(t, q, 1000.0)
    assert tr[0] == 0.0 and tr[-1] == pytest.approx(2.0) and np.allclose(np.diff(tr)[:-1], 1e-3)
    stored = np.isin(np.round(tr, 9), np.round(t, 9))
    np.testing.assert_allclose(qr[stored], q, atol=1e-12)                     # the plan's own samples
    np.testing.assert_allclose(qr, np.column_stack([np.sin(tr), tr ** 3]), atol=2e-4)
    np.testing.assert_allclose(vr, np.column_stack([np.cos(tr), 3 * tr ** 2]), atol=1e-3)
    np.testing.assert_allclose(ar[20:-20], np.column_stack([-np.sin(tr), 6 * tr])[20:-20], atol=1e-3)


def test_a_plan_at_its_acceleration_limit_stays_within_it_when_resampled() -> None:
    """Bang-bang acceleration (a time-optimal profile): the differences never exceed the plan's bound."""
    t = np.linspace(0.0, 1.0, 401)
    a_true = np.where(t < 0.5, 2.0, -2.0)
    v = np.concatenate([[0.0], np.cumsum(0.5 * (a_true[1:] + a_true[:-1]) * np.diff(t))])
    q = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])[:, None]
    _, _, _, ar = em.resample_plan(t, q, 1000.0)
    assert np.max(np.abs(ar)) <= 2.0 + 1e-9


def test_servo_gains_yaml_reads_back_exactly_with_any_joint_names(tmp_path: Path) -> None:
    names = ["1", "yes", "a: b", "joint 4"]
    rng = np.random.default_rng(0)
    arrays = {key: rng.uniform(1.0, 1e4, len(names)) for key in ("servo_kp_1_s", "servo_kv_Nms_rad", "servo_ki_Nm_rad")}
    summary = {"sample_time_s": 4e-4, "velocity_sample_time_s": 4e-4,
               "delay_samples": {"setpoint": 2, "measurement": 1}, "feedforward_advanced": True}
    back = load_yaml(servo_gains_yaml(StageOutput(summary, arrays, {}, None, tmp_path), names))
    assert list(back["axes"]) == names
    assert back["sample_time_s"] == 4e-4 and back["setpoint_delay_samples"] == 2
    assert back["feedforward_advanced"] is True
    for key in ("kp_1_s", "kv_Nms_rad", "ki_Nm_rad"):
        column = f"servo_{key}"
        assert [back["axes"][name][key] for name in names] == arrays[column].tolist()


def _handed_on(robot: RobotModel) -> RobotModel:
    """``robot`` as a stage hands it on: placements calibrated, inertias and friction identified."""
    rng = np.random.default_rng(7)
    model = robot.model.copy()
    for j in range(1, model.njoints):
        model.jointPlacements[j] = model.jointPlacements[j] * pin.exp6(1e-3 * rng.normal(size=6))
        inertia = model.inertias[j]
        model.inertias[j] = pin.Inertia(1.1 * inertia.mass, inertia.lever + 1e-3, 1.2 * inertia.inertia)
    handed = robot.with_model(model)
    act = handed.spec.actuation
    act.viscous_Nms_rad = act.viscous_Nms_rad * 1.3 + 0.01
    act.coulomb_Nm = act.coulomb_Nm * 0.7 + 0.02
    handed.model.armature = np.asarray(handed.model.armature) * 1.1 + 1e-4
    return handed


@pytest.mark.parametrize("arm", ["rx130l", "kinova"])
def test_the_exported_robot_folder_loads_back_as_the_model_handed_on(tmp_path: Path, rx130l, arm: str) -> None:
    """``export/robot`` read by ``RobotModel.load``: placements, inertias, rotor inertia, friction, limits
    as handed on (continuous joints of the source continuous again, the same one-turn limits on loading);
    the URDF's ``<dynamics>`` hold the friction for simulators that read URDF."""
    if arm == "kinova":
        source = example_arm_urdf("kinova_description/robots/kinova.urdf")
        if source is None:
            pytest.skip("example-robot-data is not installed")
        nominal = RobotModel.load(source)
    else:
        nominal = rx130l
    handed = _handed_on(nominal)
    ctx = ExportContext(tmp_path, tmp_path, nominal, handed, JointLimitTable.of_model(nominal),
                        ready_pose_rad(nominal), 100.0, "sqlite3", "/arm/joint_trajectory")
    robot_files(ctx)
    back = RobotModel.load(tmp_path / "robot")
    for j in range(1, handed.model.njoints):
        assert back.model.jointPlacements[j].isApprox(handed.model.jointPlacements[j], 1e-12)
        assert back.model.inertias[j].isApprox(handed.model.inertias[j], 1e-12)
    np.testing.assert_allclose(back.model.armature, handed.model.armature, rtol=1e-15)
    for field in ("viscous_Nms_rad", "coulomb_Nm", "gear_ratio"):
        np.testing.assert_array_equal(getattr(back.spec.actuation, field), getattr(handed.spec.actuation, field))
    for field in ("lower_rad", "upper_rad", "velocity_rad_s", "effort_Nm"):
        np.testing.assert_allclose(getattr(back.limits, field), getattr(handed.limits, field), rtol=1e-15)
    urdf = yourdfpy.URDF.load(str(tmp_path / "robot" / f"{handed.name}.urdf"), build_scene_graph=False,
                              load_meshes=False)
    for k, name in enumerate(handed.model.names[1:]):
        assert float(urdf.joint_map[name].dynamics.damping) == handed.spec.actuation.viscous_Nms_rad[k]
        assert float(urdf.joint_map[name].dynamics.friction) == handed.spec.actuation.coulomb_Nm[k]


def test_calibration_parameters_are_the_arms_identified_ones_with_units(tmp_path: Path, rx130l) -> None:
    identified = {"j2.dq": [1.5e-3, 2e-6], "tracker.dx": [-3e-4, 7e-6], "j2.c": [1.3e-7, 1.5e-8],
                  "reflector.dz": [5.2e-4, 5.7e-6]}
    ctx = ExportContext(tmp_path, tmp_path, rx130l, rx130l, JointLimitTable.of_model(rx130l), ready_pose_rad(rx130l),
                        100.0, "sqlite3", "/arm/joint_trajectory")
    calibration_parameters(ctx, StageOutput({}, {}, {"identified": identified}, None, tmp_path))
    table = read_parameter_table_csv(tmp_path / "calibration_parameters.csv")
    assert table.names == ("j2.dq", "j2.c", "reflector.dz")             # the tracker's pose is the set-up's
    assert table.units == ("rad", "rad/(N m)", "m")
    assert table.values.tolist() == [1.5e-3, 1.3e-7, 5.2e-4] and table.stds.tolist() == [2e-6, 1.5e-8, 5.7e-6]
    assert ctx.written == ["calibration_parameters.csv"]
