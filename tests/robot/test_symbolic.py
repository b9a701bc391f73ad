"""The symbolic bridge equals Pinocchio: FK (with and without kinematic errors), RNEA, CRBA,
torque regressor (plus rotor/friction/offset columns), on random states of both robots."""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from pipeline.core.errors import PipelineError, RobotFileError
from pipeline.robot.model import RobotModel
from pipeline.robot.parameters import (
    apply_kinematic_errors,
    dynamic_parameter_names,
    dynamic_parameter_problems,
    kinematic_parameter_names,
    pinocchio_dynamic_parameters,
    set_dynamic_parameters,
)
from pipeline.robot.symbolic import SymbolicRobot

REPO = Path(__file__).resolve().parents[2]
N_STATES = 100
TOL = 1e-9
ROBOTS = ("rx130l", "staubli_tx40")


@pytest.fixture(scope="module", params=ROBOTS)
def case(request):
    return SymbolicRobot(RobotModel.load(request.param))


def _model(sym: SymbolicRobot) -> pin.Model:
    return sym.model


def _states(model: pin.Model, rng: np.random.Generator, n: int = N_STATES):
    lo = np.maximum(model.lowerPositionLimit, -np.pi)
    hi = np.minimum(model.upperPositionLimit, np.pi)
    vmax = np.where(np.isfinite(model.velocityLimit) & (model.velocityLimit > 0),
                    model.velocityLimit, 3.0)
    for _ in range(n):
        q = rng.uniform(lo, hi)
        v = rng.uniform(-1.0, 1.0, model.nv) * vmax
        a = rng.normal(0.0, 5.0, model.nv)
        yield q, v, a


def _frames(sym: SymbolicRobot) -> list[str]:
    return [sym.flange_frame, *sym.tool_frames]


def _np(x) -> np.ndarray:
    return np.array(x, dtype=float)


def test_parameter_layout(case):
    sym = case
    nq = sym.nq
    names = sym.kinematic_parameter_names
    assert len(names) == sym.n_kin == 7 * nq + 12 == len(set(names))
    assert names[:6] == ["j1.dx", "j1.dy", "j1.dz", "j1.rx", "j1.ry", "j1.rz"]
    assert names[6 * nq] == "j1.dq" and names[7 * nq - 1] == f"j{nq}.dq"
    assert names[7 * nq] == "base.dx" and names[-1] == "tool.rz"
    dnames = sym.dynamic_parameter_names
    assert len(dnames) == sym.n_dyn == 14 * nq == len(set(dnames))
    assert dnames[:10] == [f"link1.{c}" for c in ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy",
                                                  "Ixz", "Iyz", "Izz")]
    assert dnames[10 * nq] == "j1.rotor_inertia" and dnames[-1] == f"j{nq}.offset"
    assert kinematic_parameter_names(nq) == names and dynamic_parameter_names(nq) == dnames


def test_fk_matches_pinocchio(case):
    sym = case
    model = _model(sym)
    data = model.createData()
    rng = np.random.default_rng(11)
    zero = np.zeros(sym.n_kin)
    frames = [*_frames(sym), model.frames[model.nframes - 1].name]
    fks = {f: sym.fk(f) for f in frames}
    err = 0.0
    for q, _, _ in _states(model, rng):
        pin.framesForwardKinematics(model, data, q)
        for f, fk in fks.items():
            pos, rot = fk(q, zero)
            ref = data.oMf[model.getFrameId(f)]
            err = max(err, np.abs(_np(pos).ravel() - ref.translation).max(),
                      np.abs(_np(rot) - ref.rotation).max())
    assert err <= TOL


@pytest.mark.parametrize("scale", [1e-3, 0.3])
def test_fk_with_errors_matches_apply_kinematic_errors(case, scale):
    sym = case
    model = _model(sym)
    rng = np.random.default_rng(12)
    err = 0.0
    states = list(_states(model, rng))
    for k, (q, _, _) in enumerate(states):
        if k % 10 == 0:  # a new error vector every 10 states
            p_kin = rng.normal(0.0, scale, sym.n_kin)
            erred = apply_kinematic_errors(model, p_kin, sym.flange_frame, sym.tool_frames)
            data = erred.createData()
        pin.framesForwardKinematics(erred, data, q)
        for f in _frames(sym):
            pos, rot = sym.fk(f)(q, p_kin)
            ref = data.oMf[erred.getFrameId(f)]
            err = max(err, np.abs(_np(pos).ravel() - ref.translation).max(),
                      np.abs(_np(rot) - ref.rotation).max())
    assert err <= TOL
    # the errors really moved the frames (a no-op apply would pass the comparison above too)
    d0 = model.createData()
    pin.framesForwardKinematics(model, d0, states[-1][0])
    moved = np.linalg.norm(d0.oMf[model.getFrameId("tcp")].translation
                           - data.oMf[erred.getFrameId("tcp")].translation)
    assert moved > 0.1 * scale


def test_identification_jacobian(case):
    sym = case
    model = _model(sym)
    data = model.createData()
    rng = np.random.default_rng(13)
    frame = sym.tool_frames[0]
    fid = model.getFrameId(frame)
    jac = sym.fk_position_jacobian(frame)
    both = sym.fk_position_and_jacobian(frame)
    kin = sym.kin
    err_q = err_fd = 0.0
    for k, (q, _, _) in enumerate(_states(model, rng, 20)):
        j_kin, j_q = (_np(x) for x in jac(q, np.zeros(sym.n_kin)))
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        ref = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:3]
        err_q = max(err_q, np.abs(j_q - ref).max(), np.abs(j_kin[:, kin.joint_offsets] - ref).max())
        p, jk2, jq2 = (_np(x) for x in both(q, np.zeros(sym.n_kin)))
        assert np.array_equal(jk2, j_kin) and np.array_equal(jq2, j_q)
        if k < 3:  # central differences through the numeric error model
            h = 1e-6
            fd = np.zeros_like(j_kin)
            for i in range(sym.n_kin):
                dp = np.zeros(sym.n_kin)
                dp[i] = h
                pos = []
                for sgn in (1, -1):
                    m = apply_kinematic_errors(model, sgn * dp, sym.flange_frame, sym.tool_frames)
                    d = m.createData()
                    pin.framesForwardKinematics(m, d, q)
                    pos.append(d.oMf[fid].translation.copy())
                fd[:, i] = (pos[0] - pos[1]) / (2 * h)
            err_fd = max(err_fd, np.abs(fd - j_kin).max())
    assert err_q <= TOL
    assert err_fd <= 1e-7


def _rigid_parameters(sym: SymbolicRobot) -> np.ndarray:
    """Nominal parameters with friction and offsets zeroed (what pin.rnea models)."""
    p = sym.nominal_dynamic_parameters()
    p[sym.dyn.viscous] = 0.0
    p[sym.dyn.coulomb] = 0.0
    p[sym.dyn.offset] = 0.0
    return p


def test_rnea_matches_pinocchio(case):
    sym = case
    model = _model(sym)
    assert np.abs(model.armature).max() > 0  # rotor inertia is exercised
    data = model.createData()
    rng = np.random.default_rng(14)
    p = _rigid_parameters(sym)
    err = err_g = err_h = 0.0
    for q, v, a in _states(model, rng):
        tau = _np(sym.rnea(q, v, a, p)).ravel()
        err = max(err, np.abs(tau - pin.rnea(model, data, q, v, a)).max())
        g = _np(sym.gravity(q, p)).ravel()
        err_g = max(err_g, np.abs(g - pin.computeGeneralizedGravity(model, data, q)).max())
        h = _np(sym.nonlinear_effects(q, v, p)).ravel()
        c = _np(sym.coriolis(q, v, p)).ravel()
        err_h = max(err_h, np.abs(h - pin.nonLinearEffects(model, data, q, v)).max(),
                    np.abs(c + g - h).max())
    assert err <= TOL and err_g <= TOL and err_h <= TOL


def test_mass_matrix_matches_crba(case):
    sym = case
    model = _model(sym)
    data = model.createData()
    rng = np.random.default_rng(15)
    p = sym.nominal_dynamic_parameters()
    err = 0.0
    for q, _, _ in _states(model, rng):
        m_pin = pin.crba(model, data, q)
        m_pin = np.triu(m_pin) + np.triu(m_pin, 1).T
        err = max(err, np.abs(_np(sym.mass_matrix(q, p)) - m_pin).max())
    assert err <= TOL


def test_regressor_matches_pinocchio_and_friction_columns(case):
    sym = case
    model = _model(sym)
    data = model.createData()
    rng = np.random.default_rng(16)
    nq, dyn = sym.nq, sym.dyn
    p_nom = sym.nominal_dynamic_parameters()
    err_inertial = err_extra = err_lin = 0.0
    for q, v, a in _states(model, rng):
        y = _np(sym.regressor(q, v, a))
        assert y.shape == (nq, sym.n_dyn)
        y_pin = pin.computeJointTorqueRegressor(model, data, q, v, a)
        err_inertial = max(err_inertial, np.abs(y[:, dyn.inertial] - y_pin).max())
        expected = [
            (dyn.rotor, np.diag(a)),
            (dyn.viscous, np.diag(v)),
            (dyn.coulomb, np.diag(np.tanh(v / sym.coulomb_smoothing_rad_s))),
            (dyn.offset, np.eye(nq)),
        ]
        for sl, block in expected:
            err_extra = max(err_extra, np.abs(y[:, sl] - block).max())
        p = p_nom * rng.uniform(0.5, 1.5, sym.n_dyn) + rng.normal(0.0, 1.0, sym.n_dyn) * (
            np.arange(sym.n_dyn) >= dyn.offset.start
        )
        tau = _np(sym.rnea(q, v, a, p)).ravel()
        err_lin = max(err_lin, np.abs(y @ p - tau).max())
    assert err_inertial <= TOL and err_extra <= TOL and err_lin <= TOL


def test_mapped_functions_match_single_calls(case):
    sym = case
    rng = np.random.default_rng(17)
    states = list(_states(sym.model, rng, 8))
    q, v, a = (np.array([s[k] for s in states]).T for k in range(3))
    p = sym.nominal_dynamic_parameters()
    tau_map = _np(sym.rnea.map(8)(q, v, a, p))
    y_map = _np(sym.regressor.map(8)(q, v, a))
    for k in range(8):
        np.testing.assert_array_equal(tau_map[:, k], _np(sym.rnea(q[:, k], v[:, k], a[:, k], p)).ravel())
        np.testing.assert_array_equal(
            y_map[:, k * sym.n_dyn:(k + 1) * sym.n_dyn], _np(sym.regressor(q[:, k], v[:, k], a[:, k]))
        )


def test_dynamic_parameters_round_trip(case):
    sym = case
    model = _model(sym)
    rng = np.random.default_rng(18)
    p_nom = pinocchio_dynamic_parameters(model)
    assert np.allclose(p_nom[sym.dyn.inertial], sym.nominal_dynamic_parameters()[sym.dyn.inertial])
    # a physically consistent perturbation: scale mass and inertia, move the centre of mass
    p = p_nom.copy()
    for i in range(1, sym.nq + 1):
        inertia = pin.Inertia.FromDynamicParameters(p_nom[sym.dyn.link(i)])
        mass = max(inertia.mass, 0.1) * rng.uniform(0.8, 1.2)
        lever = inertia.lever + rng.normal(0.0, 0.01, 3)
        rot = pin.exp3(rng.normal(0.0, 0.1, 3))
        i_c = rot @ (inertia.inertia + 1e-3 * np.eye(3)) @ rot.T * rng.uniform(0.8, 1.2)
        p[sym.dyn.link(i)] = pin.Inertia(mass, lever, i_c).toDynamicParameters()
    p[sym.dyn.rotor] = rng.uniform(0.01, 1.0, sym.nq)
    assert dynamic_parameter_problems(p, sym.nq) == []
    new = set_dynamic_parameters(model, p)
    np.testing.assert_allclose(pinocchio_dynamic_parameters(new)[: 11 * sym.nq], p[: 11 * sym.nq],
                               rtol=0, atol=1e-12)
    data = new.createData()
    err = 0.0
    for q, v, a in _states(new, rng, 20):
        err = max(err, np.abs(_np(sym.rnea(q, v, a, p)).ravel() - pin.rnea(new, data, q, v, a)).max())
    assert err <= TOL
    # the original model is untouched
    np.testing.assert_array_equal(pinocchio_dynamic_parameters(model), p_nom)


def test_dynamic_parameter_checks(case):
    sym = case
    p = pinocchio_dynamic_parameters(sym.model)
    bad = p.copy()
    bad[sym.dyn.link(2).start] = -1.0
    with pytest.raises(PipelineError, match="link2.m"):
        set_dynamic_parameters(sym.model, bad)
    assert any("link2.m" in s for s in dynamic_parameter_problems(bad, sym.nq))
    bad = p.copy()
    bad[sym.dyn.link(3).start + 4] = -5.0  # Ixx < 0
    bad[sym.dyn.rotor.start] = -0.1
    problems = dynamic_parameter_problems(bad, sym.nq)
    assert any(s.startswith("link3:") for s in problems)
    assert any(s.startswith("j1.rotor_inertia") for s in problems)
    with pytest.raises(PipelineError, match="p_dyn"):
        set_dynamic_parameters(sym.model, p[:-1])


def _hand_built_model() -> pin.Model:
    """Three joints of the other kinds: revolute about an unaligned axis, prismatic y,
    prismatic along an unaligned axis; random inertias; tool frames on the last joint."""
    rng = np.random.default_rng(5)
    model = pin.Model()
    model.name = "hand_built"
    axis = np.array([0.3, -0.5, 0.8])
    joints = [
        pin.JointModelRevoluteUnaligned(axis / np.linalg.norm(axis)),
        pin.JointModelPY(),
        pin.JointModelPrismaticUnaligned(np.array([0.6, 0.0, 0.8])),
        pin.JointModelRX(),
    ]
    parent = 0
    for k, joint in enumerate(joints):
        placement = pin.SE3(pin.exp3(rng.normal(0, 1, 3)), rng.normal(0, 0.3, 3))
        parent = model.addJoint(parent, joint, placement, f"joint_{k + 1}")
        inertia = pin.Inertia(rng.uniform(1, 3), rng.normal(0, 0.1, 3),
                              np.diag(rng.uniform(0.01, 0.1, 3)))
        model.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
    model.armature = rng.uniform(0.1, 0.5, model.nv)
    for name, xyz in (("flange", [0.0, 0.0, 0.1]), ("tcp", [0.0, 0.1, 0.3]),
                      ("reflector", [0.05, 0.0, 0.2])):
        model.addFrame(pin.Frame(name, parent, 0, pin.SE3(pin.exp3(rng.normal(0, 0.3, 3)),
                                                          np.array(xyz)), pin.FrameType.OP_FRAME))
    return model


def test_unaligned_and_prismatic_joints():
    model = _hand_built_model()
    sym = SymbolicRobot(model)
    data = model.createData()
    rng = np.random.default_rng(19)
    p = sym.nominal_dynamic_parameters()
    err = 0.0
    for k in range(N_STATES):
        q, v, a = rng.normal(0, 1, (3, model.nq))
        pin.framesForwardKinematics(model, data, q)
        pos, rot = sym.fk("tcp")(q, np.zeros(sym.n_kin))
        ref = data.oMf[model.getFrameId("tcp")]
        err = max(err, np.abs(_np(pos).ravel() - ref.translation).max(),
                  np.abs(_np(rot) - ref.rotation).max())
        err = max(err, np.abs(_np(sym.rnea(q, v, a, p)).ravel() - pin.rnea(model, data, q, v, a)).max())
        m_pin = pin.crba(model, data, q)
        m_pin = np.triu(m_pin) + np.triu(m_pin, 1).T
        err = max(err, np.abs(_np(sym.mass_matrix(q, p)) - m_pin).max())
        y = _np(sym.regressor(q, v, a))[:, sym.dyn.inertial]
        err = max(err, np.abs(y - pin.computeJointTorqueRegressor(model, data, q, v, a)).max())
        if k % 10 == 0:
            p_kin = rng.normal(0, 0.05, sym.n_kin)
            erred = apply_kinematic_errors(model, p_kin)
            de = erred.createData()
            pin.framesForwardKinematics(erred, de, q)
            for f in ("flange", "tcp", "reflector"):
                pos, rot = sym.fk(f)(q, p_kin)
                ref = de.oMf[erred.getFrameId(f)]
                err = max(err, np.abs(_np(pos).ravel() - ref.translation).max(),
                          np.abs(_np(rot) - ref.rotation).max())
    assert err <= TOL


def test_bad_models_and_frames_raise():
    model = pin.Model()
    model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "free")
    with pytest.raises(RobotFileError, match="one-dof"):
        SymbolicRobot(model)
    with pytest.raises(RobotFileError, match="frame nope"):
        SymbolicRobot(_hand_built_model(), tool_frames=("nope",))
    sym = SymbolicRobot(_hand_built_model())
    with pytest.raises(RobotFileError, match="frame nope"):
        sym.fk("nope")
    with pytest.raises(PipelineError, match="p_kin"):
        apply_kinematic_errors(sym.model, np.zeros(3))
    with pytest.raises(PipelineError, match="coulomb_smoothing"):
        SymbolicRobot(_hand_built_model(), coulomb_smoothing_rad_s=0.0)


def test_jit_matches_sx(tmp_path):
    model = _hand_built_model()
    sym = SymbolicRobot(model)
    jit = SymbolicRobot(model, jit=True, cache_dir=tmp_path)
    rng = np.random.default_rng(20)
    p = sym.nominal_dynamic_parameters()
    for _ in range(10):
        q, v, a = rng.normal(0, 1, (3, model.nq))
        np.testing.assert_allclose(_np(jit.rnea(q, v, a, p)), _np(sym.rnea(q, v, a, p)),
                                   rtol=0, atol=1e-12)
    libs = list((tmp_path / "casadi").glob("rnea_*.so"))
    assert len(libs) == 1
    # two compiled functions with the same name ("fk") in one process stay distinct
    p_kin = rng.normal(0, 0.05, sym.n_kin)
    for frame in ("tcp", "reflector", "tcp"):
        for out_jit, out_sx in zip(jit.fk(frame)(q, p_kin), sym.fk(frame)(q, p_kin), strict=True):
            np.testing.assert_allclose(_np(out_jit), _np(out_sx), rtol=0, atol=1e-12)
    # a second robot object reuses the cached library; mapped and MX use work
    again = SymbolicRobot(model, jit=True, cache_dir=tmp_path)
    q, v, a = rng.normal(0, 1, (3, model.nq, 5))
    tau = _np(again.rnea.map(5)(q, v, a, p))
    x = ca.MX.sym("x", model.nq)
    f = ca.Function("f", [x], [again.rnea(x, v[:, 0], a[:, 0], p)])
    np.testing.assert_allclose(_np(f(q[:, 0])).ravel(), tau[:, 0], rtol=0, atol=1e-12)
    assert list((tmp_path / "casadi").glob("rnea_*.so")) == libs


def test_agrees_with_robot_model_dynamics(case):
    """With a RobotModel, the nominal symbolic dynamics are the RobotModel's (friction included)."""
    sym = case
    robot = sym.robot
    assert np.array_equal(sym.coulomb_smoothing_rad_s, robot.actuation.coulomb_smoothing_rad_s)
    rng = np.random.default_rng(21)
    p = sym.nominal_dynamic_parameters()
    err = 0.0
    for q, v, a in _states(sym.model, rng, 50):
        err = max(err, np.abs(_np(sym.rnea(q, v, a, p)).ravel() - robot.inverse_dynamics(q, v, a)).max(),
                  np.abs(_np(sym.mass_matrix(q, p)) - robot.mass_matrix(q)).max(),
                  np.abs(_np(sym.fk("tcp")(q, np.zeros(sym.n_kin))[0]).ravel()
                         - robot.fk(q, "tcp").translation).max())
    assert err <= TOL


def test_coulomb_columns_switch_with_each_joints_width(rx130l: RobotModel) -> None:
    """Coulomb smoothing stated per joint (an identified record's): each joint's Coulomb column of the
    symbolic regressor is ``tanh(v_j / w_j)`` with its own width."""
    robot = rx130l.copy()
    widths = np.array([0.2, 0.05, 0.01, 0.1, 0.002, 0.03])
    robot.spec.actuation.coulomb_smoothing_rad_s = widths
    sym = SymbolicRobot(robot)
    v = np.linspace(-0.05, 0.05, robot.nq)
    y = _np(sym.regressor(np.zeros(robot.nq), v, np.zeros(robot.nq)))
    np.testing.assert_allclose(y[:, sym.dyn.coulomb], np.diag(np.tanh(v / widths)), rtol=1e-12, atol=1e-15)
