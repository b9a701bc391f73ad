"""Gravity-model uncertainty in the elastostatic measurement covariance."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.calibration import candidates as cd
from pipeline.calibration import error_model as em
from pipeline.calibration import measure as ms
from pipeline.calibration.gravity_uncertainty import GravityCovariance, GravityPrior, Whitener
from pipeline.calibration.robust import robust_estimate
from pipeline.robot.model import RobotModel
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad
from pipeline.sim.truth import RealRobot, TruthConfig

PRIOR = GravityPrior(0.15, 0.02)


@pytest.fixture(scope="session")
def robot() -> RobotModel:
    return RobotModel.load("rx130l")


@pytest.fixture(scope="session")
def mm(robot) -> em.MeasurementModel:
    return em.MeasurementModel(robot, compliance=True)


def _x_nominal_compliance(mm: em.MeasurementModel) -> np.ndarray:
    x = np.zeros(mm.n)
    x[mm.sl_compliance] = 1.0 / nominal_joint_stiffness_Nm_rad(mm.robot)
    return x


def test_no_gravity_term_for_a_rigid_model_or_zero_compliance(robot, mm):
    Q = em.random_configurations(robot, 5, np.random.default_rng(0))
    T = robot.tracker.transform_tracker_to_base
    rigid = GravityCovariance(em.MeasurementModel(robot), PRIOR)
    assert not rigid.active and rigid.factors(Q, np.zeros(rigid.mm.n), T).shape == (5, 3, 0)
    g = GravityCovariance(mm, PRIOR)
    assert g.active
    assert np.all(g.blocks(Q, np.zeros(mm.n), T) == 0)
    assert np.any(g.blocks(Q, _x_nominal_compliance(mm), T) != 0)
    assert np.all(GravityCovariance(mm, GravityPrior(0.0, 0.0)).blocks(Q, _x_nominal_compliance(mm), T) == 0)


def test_predicted_deflection_covariance_matches_sampled_inertia_errors(robot, mm):
    """Monte Carlo: readings under randomly perturbed inertias (mass log-normal, COM shifted, the
    prior's magnitudes) scatter with the covariance A Sigma_pi A^T of the linearised prior."""
    rng = np.random.default_rng(1)
    Q = em.random_configurations(robot, 4, rng)
    T = robot.tracker.transform_tracker_to_base
    x = _x_nominal_compliance(mm)
    predicted = GravityCovariance(mm, PRIOR).blocks(Q, x, T)
    nominal = mm.gravity_model
    samples = []
    try:
        for _ in range(400):
            model = nominal.copy()
            for j in range(1, model.njoints):
                inertia = nominal.inertias[j]
                model.inertias[j] = pin.Inertia(inertia.mass * float(np.exp(0.15 * rng.standard_normal())),
                                                inertia.lever + 0.02 * rng.standard_normal(3), inertia.inertia)
            mm.set_gravity_model(model)
            samples.append(mm.predict(Q, x, T))
    finally:
        mm.set_gravity_model(nominal)
    S = np.array(samples)                       # (samples, N, 3)
    d = S - S.mean(axis=0)
    sampled = np.einsum("snI,snJ->nIJ", d, d) / (len(S) - 1)
    tr_p, tr_s = np.trace(predicted, axis1=1, axis2=2), np.trace(sampled, axis1=1, axis2=2)
    assert np.all(tr_p > 0)
    assert np.allclose(tr_s, tr_p, rtol=0.25), (tr_s, tr_p)
    # the largest principal direction agrees too
    for P, Ssm in zip(predicted, sampled, strict=True):
        u = np.linalg.eigh(P)[1][:, -1]
        v = np.linalg.eigh(Ssm)[1][:, -1]
        assert abs(u @ v) > 0.9


def test_whitener_without_factors_is_the_scalar_sigma():
    rng = np.random.default_rng(2)
    e = rng.standard_normal((6, 3))
    sigma = rng.uniform(1e-5, 2e-5, 6)
    w = Whitener(sigma)
    assert np.allclose(w.vector(e), (e / sigma[:, None]).reshape(-1))
    assert np.allclose(w.reading_norm(e), np.linalg.norm(e, axis=1) / sigma)
    B = rng.standard_normal((6, 3, 4)) * 1e-5
    wb = Whitener(sigma, B)
    cov = sigma[:, None, None] ** 2 * np.eye(3) + np.einsum("nir,njr->nij", B, B)
    md = np.einsum("ni,nij,nj->n", e, np.linalg.inv(cov), e)
    assert np.allclose(wb.reading_norm(e) ** 2, md)


def test_ideal_truth_fit_barely_changes_with_the_gravity_term(robot, mm):
    """Rigid joints: the compliances fit to ~0, so the gravity-model term is ~0."""
    real = RealRobot.create(robot, 3, TruthConfig.ideal())
    rng = np.random.default_rng(3)
    Q, _ = cd.random_candidates(cd.chain_from_robot(robot), 60, rng)
    meas = ms.measure_simulated(real, Q, rng)
    basis = np.eye(mm.n)
    rep = em.identifiability(mm.jacobian(em.random_configurations(robot, 100, rng), np.zeros(mm.n),
                                         robot.tracker.transform_tracker_to_base)[1].reshape(-1, mm.n), mm.names)
    basis = em.parameter_basis(rep, mm.n, basis)
    plain, _ = robust_estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis)
    grav, _ = robust_estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis, gravity=GravityCovariance(mm, PRIOR))
    assert abs(grav.chi2_per_dof - plain.chi2_per_dof) < 0.1 * plain.chi2_per_dof
    assert np.all(np.abs(grav.theta - plain.theta) < 0.5 * plain.std)
