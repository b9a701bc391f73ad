"""Signal processing and estimators on synthetic data with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.errors import DataFileError
from pipeline.identification import estimate as E
from pipeline.identification import signals
from pipeline.identification.measure import JointRecord, process_periodic
from pipeline.identification.regressor import RegressorModel, base_parameters, standard_parameters


def test_zero_phase_lowpass_and_derivatives():
    dt = 1e-3
    t = np.arange(0, 4, dt)
    x = np.sin(2 * np.pi * 0.5 * t)[:, None] + 1e-3 * np.sin(2 * np.pi * 200 * t)[:, None]
    st = signals.states_from_positions(x, dt, cutoff_hz=5.0)
    core = slice(1000, -1000)  # away from the filter start-up at both ends
    w = 2 * np.pi * 0.5
    np.testing.assert_allclose(st.q[core, 0], np.sin(w * t[core]), atol=2e-5)  # no lag, no ripple
    np.testing.assert_allclose(st.v[core, 0], w * np.cos(w * t[core]), atol=5e-4)
    np.testing.assert_allclose(st.a[core, 0], -(w**2) * np.sin(w * t[core]), atol=5e-3)
    with pytest.raises(DataFileError):
        signals.lowpass(x, 600.0, 1000.0)  # above Nyquist


def test_average_periods_divides_the_noise():
    rng = np.random.default_rng(0)
    base = np.sin(np.linspace(0, 2 * np.pi, 200, endpoint=False))[:, None]
    x = np.tile(base, (16, 1)) + rng.normal(scale=0.1, size=(3200, 1))
    mean, std = signals.average_periods(x, 200)
    assert np.std(mean - base) == pytest.approx(0.1 / 4, rel=0.2)
    assert np.mean(std) == pytest.approx(0.1, rel=0.1)


def test_least_squares_recover_exact_parameters_and_sigmas_are_calibrated(rx130l):
    act = rx130l.actuation
    reg = RegressorModel(rx130l.model, act.gear_matrix, act.coulomb_smoothing_rad_s)
    base = base_parameters(reg, np.random.default_rng(0))
    rng = np.random.default_rng(1)
    Q, V, A = rng.normal(size=(3, 400, 6))
    Wb = base.base_regressor(reg.stacked(Q, V, A))
    beta = rng.normal(size=base.n_base)
    y0 = Wb @ beta
    np.testing.assert_allclose(E.ols(Wb, y0, 6).beta, beta, rtol=1e-6, atol=1e-8)
    sig = np.array([2.0, 2.0, 1.0, 0.2, 0.2, 0.1])
    z = []
    for k in range(20):
        y = y0 + (sig * np.random.default_rng(10 + k).normal(size=(400, 6))).ravel()
        est = E.wls(Wb, y, 6)
        z.append((est.beta - beta) / est.sigma)
    z = np.array(z)
    assert 0.85 < np.sqrt(np.mean(z**2)) < 1.15  # the covariance matches the actual scatter
    np.testing.assert_allclose(est.joint_sigma_Nm, sig, rtol=0.15)


def test_physical_fit_is_consistent_and_fits_consistent_data(rx130l):
    act = rx130l.actuation
    reg = RegressorModel(rx130l.model, act.gear_matrix, act.coulomb_smoothing_rad_s)
    p_nom = standard_parameters(rx130l.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    rng = np.random.default_rng(2)
    p_true = p_nom.copy()
    p_true[-24:-6] *= rng.uniform(0.8, 1.2, 18)  # other rotor inertia and friction
    Q, V, A = rng.normal(size=(3, 300, 6))
    Y = reg.stacked(Q, V, A)
    y = Y @ p_true + 0.01 * rng.normal(size=Y.shape[0])
    fit = E.physical_fit(Y, y, 6, p_nom, regularization=1e-6)
    assert fit.consistent
    assert fit.rms_Nm < 0.02
    assert np.all(fit.p[60:78] > 0)
    # an inconsistent data set (negative rotor inertia of axis 6) cannot be followed: the data press that
    # rotor inertia against its positive bound, the parameters stay consistent at every iterate (60 of them
    # bring it from 0.1 kg m² below 1e-4; the fit never converges: the optimum is on the bound)
    p_bad = p_true.copy()
    p_bad[65] = -0.5
    fit_bad = E.physical_fit(Y, Y @ p_bad, 6, p_nom, regularization=1e-6, max_iter=60)
    assert fit_bad.consistent and 0 < fit_bad.p[65] < 1e-3 * p_nom[65]


def test_physical_fit_does_not_pull_a_rotor_inertia_the_nominal_model_leaves_out(rx130l):
    """An assumed (or link-side) rotor inertia is 0 in the nominal prediction: no prior, so the data
    decide it, at the default regularisation (a pull towards 0 put a UR3's joint-2 value at a third)."""
    act = rx130l.actuation
    reg = RegressorModel(rx130l.model, act.gear_matrix, act.coulomb_smoothing_rad_s)
    p_true = standard_parameters(rx130l.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    p_nom = p_true.copy()
    p_nom[60:66] = 0.0                                  # rotor inertia left out of the nominal model
    rng = np.random.default_rng(5)
    Q, V, A = rng.normal(size=(3, 300, 6))
    Y = reg.stacked(Q, V, A)
    fit = E.physical_fit(Y, Y @ p_true + 0.01 * rng.normal(size=Y.shape[0]), 6, p_nom, regularization=1e-3)
    np.testing.assert_allclose(fit.p[60:66], p_true[60:66], rtol=0.05)


def test_bad_inputs_raise_data_file_errors(rx130l):
    act = rx130l.actuation
    reg = RegressorModel(rx130l.model, act.gear_matrix, act.coulomb_smoothing_rad_s)
    q = np.zeros((100, 6))
    with pytest.raises(DataFileError, match="mismatched"):
        reg.stacked(q, q[:99], q)
    bad = q.copy()
    bad[5, 2] = np.nan
    with pytest.raises(DataFileError, match="NaN"):
        reg.stacked(bad, q, q)
    W = np.ones((348, 58))
    with pytest.raises(DataFileError, match="more samples than parameters"):
        E.ols(W, np.ones(348), 6)  # 58 samples for 58 parameters
    t = np.arange(100) * 1e-3
    with pytest.raises(DataFileError, match="mismatched"):
        JointRecord(t, q, q[:90]).validate(6)
    with pytest.raises(DataFileError, match="NaN"):
        JointRecord(t, bad, q).validate(6)
    with pytest.raises(DataFileError, match="too few"):
        process_periodic(JointRecord(t, q, q), reg, 100, 5.0, 10)
