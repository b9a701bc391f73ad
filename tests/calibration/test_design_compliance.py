"""The pose design covers the joint compliances of the elastostatic error model.

Properties: the extended candidate Jacobian (closed-form geometric columns plus
``-tau_j dy/dq_j``) equals the CasADi Jacobian of :class:`MeasurementModel` with compliances; the
TCP working Jacobian's compliance columns match a finite difference of the deflected TCP; a V
design identifies the compliances (non-singular information on them) and predicts them no worse
than random sets of the same size.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import indices as ix
from pipeline.calibration import stage as st
from pipeline.calibration import task_space as ts
from pipeline.calibration.elastostatic import (
    design_basis,
    design_blocks,
    design_torques,
    measurement_model,
    payload_poses,
)
from pipeline.calibration.error_model import se3_to_vector
from pipeline.robot.parameters import pinocchio_dynamic_parameters


@pytest.fixture(scope="session")
def setup(rx130l_generic_stiffness):
    robot = rx130l_generic_stiffness
    cfg = st.Config(candidates="random", n_random_candidates=600, identifiability_samples=80,
                    n_region_configurations=80, payload_mass_kg=10.0, payload_com_m=[0.0, 0.0, 0.1],
                    payload_fraction=0.5)
    mm = measurement_model(robot, cfg)
    rng = np.random.default_rng(5)
    _, basis = st.identify_parameter_set(robot, mm, cfg, rng)
    dbasis = design_basis(mm, basis)
    cs = st.build_candidates(robot, cfg, dbasis, rng, design_torques(mm))
    spec, Qw = st.index_spec(cfg, robot, mm, dbasis, rng)
    return robot, cfg, mm, dbasis, cs, spec, Qw


def compliance_columns(mm, dbasis: np.ndarray) -> np.ndarray:
    return np.flatnonzero(np.any(dbasis[mm.sl_compliance] != 0, axis=0))


def test_design_basis_holds_the_identifiable_compliances(setup):
    _, _, mm, dbasis, cs, _, _ = setup
    assert mm.compliance and len(compliance_columns(mm, dbasis)) >= 3
    assert cs.G.shape[2] == dbasis.shape[1]


def test_extended_candidate_jacobian_equals_the_casadi_one(setup):
    robot, _, mm, dbasis, cs, _, _ = setup
    Q = cs.Q[:6]
    T0 = robot.tracker.transform_tracker_to_base
    Y_ref, J_ref = mm.jacobian(Q, np.zeros(mm.n), T0)
    Y, J = cd.nominal_jacobian(cd.chain_from_robot(robot), Q, T0)
    J = cd.with_compliance_columns(J, mm.static_torques(Q))
    assert J.shape == J_ref.shape
    scale = np.abs(J_ref).max(axis=(0, 1)) + 1e-12
    assert np.max(np.abs(J - J_ref) / scale) < 1e-8
    assert np.allclose(Y, Y_ref, atol=1e-9)
    sigma = cd.noise_sigma(cd.chain_from_robot(robot), Y_ref)
    assert np.allclose(cs.G[:6], (J_ref @ dbasis) / sigma[:, None, None], rtol=1e-8,
                       atol=1e-8 * np.abs(cs.G[:6]).max())


def test_working_jacobian_compliance_columns_match_a_finite_difference(setup):
    robot, _, mm, dbasis, _, _, Qw = setup
    Q = Qw[:4]
    Jw = ts.tcp_jacobian(mm, Q, dbasis).reshape(len(Q), 3, -1)
    tau = mm.static_torques(Q)
    unit = np.where(dbasis[mm.sl_compliance] != 0, dbasis[mm.sl_compliance], np.nan)   # c per theta
    for col in compliance_columns(mm, dbasis):
        j = int(np.flatnonzero(dbasis[mm.sl_compliance][:, col])[0])
        h = 1e-5 * unit[j, col]           # central difference, theta = +-1e-5
        Qp, Qm = Q.copy(), Q.copy()
        Qp[:, j] -= h * tau[:, j]
        Qm[:, j] += h * tau[:, j]
        fd = (robot.positions(Qp, robot.frame_tcp) - robot.positions(Qm, robot.frame_tcp)) / 2e-5
        assert np.allclose(Jw[:, :, col], fd, rtol=1e-4, atol=1e-9)


def test_v_design_identifies_the_compliances_better_than_random_sets(setup):
    _, cfg, mm, dbasis, cs, spec, _ = setup
    n = 30
    rng = np.random.default_rng(11)
    sel = ds.select("remove_and_replace", cs.G, spec, n, rng, n_initial=20).selected

    def compliance_std(idx: np.ndarray) -> np.ndarray:
        G = cs.G[idx].reshape(-1, dbasis.shape[1])
        M = G.T @ G
        ev = np.linalg.eigvalsh(M)
        if ev[0] <= 1e-12 * ev[-1]:
            return np.full(len(compliance_columns(mm, dbasis)), np.inf)
        return np.sqrt(np.diag(np.linalg.inv(M)))[compliance_columns(mm, dbasis)]

    designed = compliance_std(sel)
    assert np.all(np.isfinite(designed))     # the selected set identifies every compliance
    random = np.array([compliance_std(rng.choice(len(cs), n, replace=False)) for _ in range(7)])
    assert np.sqrt(np.mean(designed**2)) <= np.median(np.sqrt(np.mean(random**2, axis=1)))


def test_gradient_design_information_has_the_compliance_columns(setup):
    robot, _, mm, dbasis, cs, _, _ = setup
    q = ca.SX.sym("q", mm.nq)
    tau = mm.sym.gravity(q, pinocchio_dynamic_parameters(mm.gravity_model))
    T0 = robot.tracker.transform_tracker_to_base
    _, J = mm.hj(q, ca.DM.zeros(mm.n), ca.DM(se3_to_vector(T0)), tau)
    f = ca.Function("J", [q], [J])
    for k in range(3):
        sigma = cd.noise_sigma(cd.chain_from_robot(robot), cs.Y[k : k + 1])[0]
        G = np.asarray(f(cs.Q[k])) @ dbasis / sigma
        assert np.allclose(G, cs.G[k], rtol=1e-7, atol=1e-7 * np.abs(cs.G[k]).max())


def test_the_design_chooses_the_payload_poses(setup):
    robot, _, mm, dbasis, cs, spec, _ = setup
    rng = np.random.default_rng(2)
    Q = cs.Q[ds.select("remove_and_replace", cs.G, spec, 24, rng, n_initial=20).selected]
    T0 = robot.tracker.transform_tracker_to_base

    def value(idx: np.ndarray) -> float:
        QQ = np.concatenate([Q, Q[idx]])
        mounted = np.r_[np.zeros(len(Q), bool), np.ones(len(idx), bool)]
        G = design_blocks(mm, QQ, dbasis, T0, mounted).reshape(-1, dbasis.shape[1])
        return ix.evaluate(spec, G.T @ G, len(QQ))

    first = payload_poses(mm, Q, 1, dbasis, spec)
    assert value(first) == pytest.approx(min(value(np.array([i])) for i in range(len(Q))), rel=1e-9)
    chosen = payload_poses(mm, Q, 8, dbasis, spec)
    assert len(np.unique(chosen)) == 8
    assert value(chosen) < value(np.zeros(0, int))
    assert value(chosen) <= np.median([value(rng.choice(len(Q), 8, replace=False)) for _ in range(7)])
