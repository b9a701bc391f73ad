"""Stribeck friction fit (IPOPT, exact derivatives): recovers the static excess and the Stribeck
velocity and beats the viscous + Coulomb model on held-out data when the data have Stribeck
friction; adds nothing when they have none."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.identification import stage
from pipeline.identification.friction import fit_stribeck, stribeck_torque

from .helpers import quick_context

WIDTH = 0.01
SIGMA = np.array([0.05, 0.03])


def _data(rng, n, fs, vs):
    """Two joints; per joint 3 'rigid-body' columns, a viscous and a Coulomb column."""
    v = rng.uniform(-1.0, 1.0, (n, 2)) * rng.choice([0.05, 1.0], (n, 2))   # many slow samples
    W = np.zeros((n, 2, 10))
    for j in range(2):
        W[:, j, 5 * j : 5 * j + 3] = rng.normal(size=(n, 3))
        W[:, j, 5 * j + 3] = v[:, j]
        W[:, j, 5 * j + 4] = np.tanh(v[:, j] / WIDTH)
    beta = np.array([1.0, -2.0, 0.5, 3.0, 4.0, 0.7, 1.5, -1.0, 2.0, 2.5])
    tau = (W.reshape(-1, 10) @ beta).reshape(n, 2) + stribeck_torque(v, fs, vs, WIDTH)
    return W.reshape(-1, 10), tau + rng.normal(size=tau.shape) * SIGMA, v, beta


@pytest.mark.parametrize("fs", [np.array([2.0, 1.0]), np.zeros(2)])
def test_stribeck_fit(fs):
    rng = np.random.default_rng(0)
    vs = np.array([0.1, 0.2])
    W, tau, v, beta = _data(rng, 1500, fs, vs)
    Wt, taut, vt, _ = _data(np.random.default_rng(1), 1500, fs, vs)
    b_lin = np.linalg.lstsq(W, tau.ravel(), rcond=None)[0]
    fit = fit_stribeck(W, tau.ravel(), v, b_lin, SIGMA, WIDTH)
    rms_lin = np.sqrt(np.mean(((Wt @ b_lin).reshape(-1, 2) - taut) ** 2, axis=0))
    rms_str = np.sqrt(np.mean((fit.predict(Wt, vt) - taut) ** 2, axis=0))
    assert np.all(rms_str <= 1.1 * SIGMA)                      # at the noise level on held-out data
    if fs.any():
        np.testing.assert_allclose(fit.static_excess_Nm, fs, rtol=0.05)
        np.testing.assert_allclose(fit.stribeck_velocity_rad_s, vs, rtol=0.1)
        assert np.all(rms_lin > 2 * rms_str)                  # the linear model is measurably worse
    else:
        assert np.all(fit.static_excess_Nm < 0.05)
        assert np.all(rms_str <= 1.01 * rms_lin)


@pytest.mark.slow
def test_stage_reports_both_friction_models(tmp_path):
    """friction_model: stribeck in the stage: both models scored on the validation path; the
    choice is the one with the smaller held-out error (the hidden robot here has no Stribeck term,
    so the Stribeck model must not be much better or worse)."""
    ctx, _ = quick_context(tmp_path, overrides={"run_tx40": False, "friction_model": "stribeck",
                                                "excitation": {"n_random": 4, "max_iter": 30}})
    s = stage.run(ctx).summary
    rms = {k: np.asarray(v) for k, v in s["friction_heldout_rms_Nm"].items()}
    assert set(rms) == {"viscous_coulomb", "stribeck"} and s["friction_model"] == "stribeck"
    sigma = np.asarray(s["torque_noise_sigma_Nm"])
    best = min(rms, key=lambda k: np.mean(rms[k] / sigma))
    assert s["friction_model_best"] == best
    assert s["stribeck_status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    np.testing.assert_allclose(rms["stribeck"], rms["viscous_coulomb"], rtol=0.1)
