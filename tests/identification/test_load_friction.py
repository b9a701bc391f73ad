"""Load-dependent Coulomb friction ``fl |tau_load| tanh(v / w)`` (Bittencourt & Gunnarsson 2012):
the nested fit recovers a known coefficient and keeps the zero-load Coulomb friction unbiased where
the model without it is not; the identified model carries it (saved, loaded back) and evaluates it
with its own torque as the load in the inverse and forward dynamics and the control feedforward."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.control.simulate import feedforward_torque
from pipeline.identification import stage
from pipeline.identification.friction import (
    LoadFriction,
    fit_load_friction,
    fit_stribeck,
    load_column_values,
    stribeck_torque,
)
from pipeline.identification.regressor import standard_parameters
from pipeline.robot.exact import load_exact_robot, robots_equal, save_exact_robot
from pipeline.robot.model import RobotModel

WIDTH = 0.01
SIGMA = np.array([0.05, 0.03])
FL = np.array([0.02, 0.05])
#: columns per joint: 3 'rigid-body', viscous, Coulomb, offset
NCOL = 6


def _data(rng, n, fl, fs=None, vs=None):
    """Two joints; the load torque is the linear model's torque without the offsets (module doc)."""
    v = rng.uniform(-1.0, 1.0, (n, 2)) * rng.choice([0.05, 1.0], (n, 2))
    W = np.zeros((n, 2, 2 * NCOL))
    for j in range(2):
        c = NCOL * j
        W[:, j, c : c + 3] = rng.normal(size=(n, 3)) * 3.0 + 2.0   # a load of one sign mostly: close to Coulomb's
        W[:, j, c + 3] = v[:, j]
        W[:, j, c + 4] = np.tanh(v[:, j] / WIDTH)
        W[:, j, c + 5] = 1.0
    beta = np.array([1.0, -2.0, 0.5, 3.0, 4.0, 0.3, 0.7, 1.5, -1.0, 2.0, 2.5, -0.2])
    offsets = np.zeros(2 * NCOL, bool)
    offsets[[NCOL - 1, 2 * NCOL - 1]] = True
    st = 0.0 if fs is None else stribeck_torque(v, fs, vs, WIDTH)
    load = (W[:, :, ~offsets].reshape(-1, 2 * NCOL - 2) @ beta[~offsets]).reshape(n, 2) + st
    tau = (W.reshape(-1, 2 * NCOL) @ beta).reshape(n, 2) + st + fl * load_column_values(load, v, WIDTH)
    return W.reshape(-1, 2 * NCOL), tau + rng.normal(size=tau.shape) * SIGMA, v, beta, offsets


def _coulomb(beta):
    return beta[[4, NCOL + 4]]


@pytest.mark.parametrize("stribeck", [False, True])
def test_load_fit_recovers_the_coefficient(stribeck):
    rng = np.random.default_rng(0)
    fs, vs = (np.array([2.0, 1.0]), np.array([0.1, 0.2])) if stribeck else (None, None)
    W, tau, v, beta, offsets = _data(rng, 3000, FL, fs, vs)
    y = tau.ravel()
    w = np.tile(1.0 / SIGMA, len(tau))
    b0 = np.linalg.lstsq(W * w[:, None], y * w, rcond=None)[0]
    fit0 = fit_stribeck(W, y, v, b0, SIGMA, WIDTH) if stribeck else None
    lf = fit_load_friction(W, y, v, b0 if fit0 is None else fit0.beta, fit0, SIGMA, WIDTH, offsets)
    np.testing.assert_allclose(lf.load.coefficient, FL, rtol=0.1)
    # the zero-load Coulomb friction: unbiased with the term, biased by fl x the mean load without it
    err_with = np.abs(_coulomb(lf.beta) - _coulomb(beta))
    err_without = np.abs(_coulomb(b0 if fit0 is None else fit0.beta) - _coulomb(beta))
    assert np.all(err_with < 0.2 * err_without)
    assert (lf.stribeck is not None) == stribeck
    if stribeck:
        np.testing.assert_allclose(lf.stribeck.static_excess_Nm, fs, rtol=0.1)
    assert np.all(lf.load.chi2_gain > 0)


def test_no_load_dependence_fits_no_physical_term():
    """Data without the term: a coefficient at the noise level at most, never a negative one (friction
    does not fall with load) handed on."""
    rng = np.random.default_rng(1)
    W, tau, v, _, offsets = _data(rng, 3000, np.zeros(2))
    y = tau.ravel()
    b0 = np.linalg.lstsq(W, y, rcond=None)[0]
    lf = fit_load_friction(W, y, v, b0, None, SIGMA, WIDTH, offsets)
    assert np.all(lf.load.coefficient >= 0) and np.all(lf.load.coefficient < 0.1 * FL)


def test_load_friction_is_handed_on_and_evaluated_consistently(rx130l: RobotModel, tmp_path) -> None:
    """identified_robot carries fl; save + load keeps it; the inverse dynamics adds fl |tau_0| tanh(v/w)
    with tau_0 the model's torque without it, the forward dynamics inverts that exactly, and the control
    feedforward adds the same term; without it the model is the one without load dependence."""
    act, nq = rx130l.actuation, rx130l.nq
    p = standard_parameters(rx130l.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    fl = np.linspace(0.002, 0.02, nq)
    identified = stage.identified_robot(rx130l, p, None, LoadFriction(fl, act.coulomb_smoothing_rad_s))
    loaded = RobotModel.load(identified.save(tmp_path / "identified"))
    assert robots_equal(load_exact_robot(save_exact_robot(identified, tmp_path / "exact")), identified)
    np.testing.assert_array_equal(loaded.actuation.coulomb_load_coefficient, fl)
    rng = np.random.default_rng(2)
    q = rng.uniform(rx130l.limits.lower_rad, rx130l.limits.upper_rad, (20, nq))
    v, a = rng.normal(size=(20, nq)) * 0.5, rng.normal(size=(20, nq))
    plain = stage.identified_robot(rx130l, p)
    assert plain.actuation.coulomb_load_coefficient is None
    for k in range(len(q)):
        tau0 = plain.inverse_dynamics(q[k], v[k], a[k])
        tau = loaded.inverse_dynamics(q[k], v[k], a[k])
        np.testing.assert_allclose(tau - tau0, fl * np.abs(tau0) * np.tanh(v[k] / WIDTH), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(loaded.forward_dynamics(q[k], v[k], tau), a[k], atol=1e-8)
    ff = feedforward_torque(loaded, q, v, a, "full_friction")
    ff0 = feedforward_torque(plain, q, v, a, "full_friction")
    np.testing.assert_allclose(ff - ff0, fl * np.abs(ff0) * np.tanh(v / WIDTH), atol=1e-9)
    assert np.max(np.abs(ff - ff0)) > 1e-3 * np.max(np.abs(ff0))
