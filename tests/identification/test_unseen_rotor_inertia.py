"""A rotor inertia the torques do not show (the physically consistent fit puts it on its bound): the model
handed on keeps robot.yaml's value there and says so; every other joint is handed on as fitted."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from pipeline.identification import estimate as est_mod
from pipeline.identification.experiment import regressors
from pipeline.identification.handed_on import (
    ROTOR_INERTIA_KEY,
    keep_unseen_rotor_inertia,
    label_kept_assumptions,
    unseen_rotor_inertia_joints,
    unseen_rotor_note,
    with_stated_rotor_inertia,
)
from pipeline.identification.joints import select_joints
from pipeline.identification.outcome import identified_robot
from pipeline.identification.regressor import standard_parameters
from pipeline.robot.assumed_values import value_digest
from pipeline.robot.model import RobotModel

from .helpers import quick_context


def test_rotor_inertias_on_their_bound_are_listed_and_named_with_robot_yaml_values(tmp_path):
    ctx, _ = quick_context(tmp_path, overrides={"run_tx40": False})
    regs = regressors(ctx, ctx.config)
    robot, nq = ctx.robot, ctx.robot.nq
    off = 10 * (robot.model.njoints - 1)
    act = robot.actuation
    p = standard_parameters(robot.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    assert np.all(p[off : off + nq] > 1e-3)
    assert len(unseen_rotor_inertia_joints(regs, p)) == 0       # every rotor inertia away from its bound

    on_bound = p.copy()
    on_bound[off + np.array([0, 3, 5])] = 0.99 * est_mod.POSITIVE_LOWER_BOUND   # IPOPT ends a hair outside
    on_bound[off + 4] = 3.0 * est_mod.POSITIVE_LOWER_BOUND                      # small, off the bound
    listed = unseen_rotor_inertia_joints(regs, on_bound)
    assert listed.tolist() == [0, 3, 5]

    names = [str(n) for n in robot.model.names[1:]]
    regs.selection = select_joints(names[1:4], names, {})                      # joints 2-4 measured
    assert unseen_rotor_inertia_joints(regs, on_bound).tolist() == [3]

    note = unseen_rotor_note(robot, listed)
    assert all(f"joint {j + 1} {act.rotor_inertia_kgm2[j]:.3g} kg m²" in note for j in listed)
    assert "joint 5" not in note and "ASSUMED" not in note                   # the RX130L states its values
    assert unseen_rotor_note(robot, np.zeros(0, int)) == ""

    fits = SimpleNamespace(phys=SimpleNamespace(p=on_bound), stated_rotor_joints=None)   # the fields it reads
    keep_unseen_rotor_inertia(ctx.config, regs, fits)
    assert fits.stated_rotor_joints.tolist() == [3]
    keep_unseen_rotor_inertia(replace(ctx.config, unseen_rotor_inertia="fitted"), regs, fits)
    assert fits.stated_rotor_joints.tolist() == []


def test_the_robot_handed_on_keeps_robot_yaml_rotor_inertia_only_on_the_listed_joints(tmp_path):
    ctx, _ = quick_context(tmp_path, overrides={"run_tx40": False})
    robot, nq = ctx.robot, ctx.robot.nq
    act = robot.actuation
    p = standard_parameters(robot.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm) * 1.3
    off = 10 * (robot.model.njoints - 1)
    p[off : off + nq] = 0.99 * est_mod.POSITIVE_LOWER_BOUND
    kept = np.array([1, 4])
    p_out = with_stated_rotor_inertia(robot, p, kept)
    assert p[off + 1] < 1e-5                                             # the input is left as it was
    handed = identified_robot(robot, p_out).actuation.rotor_inertia_kgm2
    for j in range(nq):
        assert handed[j] == (act.rotor_inertia_kgm2[j] if j in kept else p[off + j]), j
    np.testing.assert_array_equal(np.delete(p_out, off + kept), np.delete(p, off + kept))
    np.testing.assert_array_equal(with_stated_rotor_inertia(robot, p, np.zeros(0, int)), p)


def test_an_assumed_rotor_inertia_kept_on_some_joints_reads_back_as_assumed(tmp_path):
    ctx, _ = quick_context(tmp_path, overrides={"run_tx40": False})
    robot = ctx.robot
    act = robot.actuation
    robot.spec.assumed[ROTOR_INERTIA_KEY] = {"rule": "0.005 s² x effort limit",     # as robot init writes it
                                             "sha256": value_digest([float(v) for v in act.rotor_inertia_kgm2])}
    p = standard_parameters(robot.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    off = 10 * (robot.model.njoints - 1)
    p[off : off + robot.nq] *= 0.5                                       # identified on every joint ...
    kept = np.array([2, 5])
    handed = identified_robot(robot, with_stated_rotor_inertia(robot, p, kept))   # ... but joints 3 and 6
    label_kept_assumptions(robot, handed, {"rotor_inertia_kgm2": kept, "viscous_Nms_rad": kept})
    back = RobotModel.load(handed.save(tmp_path / "handed"))
    entry = back.spec.assumed[ROTOR_INERTIA_KEY]                             # in force on reading back
    assert "joint(s) 3, 6" in entry["rule"] and entry["rule"].startswith("0.005 s² x effort limit")
    np.testing.assert_array_equal(back.actuation.rotor_inertia_kgm2[kept], act.rotor_inertia_kgm2[kept])
    assert "actuation.viscous_Nms_rad" not in back.spec.assumed              # robot.yaml stated it: a fact

    fitted = identified_robot(robot, p)                                  # every joint identified: a fact
    label_kept_assumptions(robot, fitted, {"rotor_inertia_kgm2": np.zeros(0, int)})
    assert ROTOR_INERTIA_KEY not in RobotModel.load(fitted.save(tmp_path / "fitted")).spec.assumed


def test_a_fitted_link_under_the_moment_floor_is_handed_on_as_it_is_read_back(tmp_path):
    """A physically consistent fit can leave a light link's principal moments a little under the floor loading
    keeps (the UR10 record's wrist: 0.73-0.88e-6 kg m²): the robot handed on is the one read back."""
    ctx, _ = quick_context(tmp_path, overrides={"run_tx40": False})
    robot = ctx.robot
    act = robot.actuation
    p = standard_parameters(robot.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    last = 10 * (robot.model.njoints - 2)                 # the last link: I about its centre of mass
    mass, com = p[last], p[last + 1 : last + 4] / p[last]
    under = np.diag([7.3e-7, 8.4e-7, 8.8e-7]) + mass * (com @ com * np.eye(3) - np.outer(com, com))
    p[last + 4 : last + 10] = under[[0, 0, 1, 0, 1, 2], [0, 1, 1, 2, 2, 2]]   # Ixx Ixy Iyy Ixz Iyz Izz
    handed = identified_robot(robot, p)
    moments = np.linalg.eigvalsh(handed.model.inertias[robot.model.njoints - 1].inertia)
    np.testing.assert_allclose(moments, 1e-6, rtol=1e-9)
    back = RobotModel.load(handed.save(tmp_path / "handed"))
    assert not [a for a in back.assumptions if "repaired" in a]
    np.testing.assert_allclose(back.model.inertias[robot.model.njoints - 1].inertia,
                               handed.model.inertias[robot.model.njoints - 1].inertia, atol=1e-12)
