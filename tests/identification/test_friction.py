"""Stribeck friction fit (IPOPT, exact derivatives): recovers the static excess and the Stribeck
velocity and beats the viscous + Coulomb model on held-out data when the data have Stribeck
friction; adds nothing when they have none. The fit is handed on in the identified model (saved,
loaded back, used by the model's friction and the control feedforward)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.control.simulate import feedforward_torque
from pipeline.identification import estimate as est_mod
from pipeline.identification import fourier, stage
from pipeline.identification import measure as meas_mod
from pipeline.identification.friction import MIN_CHI2_GAIN, StribeckFit, fit_stribeck, stribeck_torque
from pipeline.identification.regressor import RegressorModel, base_parameters, standard_parameters
from pipeline.robot.exact import load_exact_robot, robots_equal, save_exact_robot
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot, TruthConfig

from .helpers import calibrated_robot, quick_context

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
        assert np.all(fit.chi2_gain > MIN_CHI2_GAIN)
    else:   # no Stribeck term in the data: none kept (likelihood-ratio test), nothing fitted to noise
        assert np.all(fit.chi2_gain < MIN_CHI2_GAIN) and np.all(fit.static_excess_Nm == 0.0)
        assert np.all(rms_str <= 1.01 * rms_lin)


@pytest.mark.slow
def test_stage_reports_both_friction_models(tmp_path):
    """friction_model: stribeck in the stage on the default (Stribeck, load-dependent) hidden robot: the
    three models scored on the validation path, the best of them handed on, a Stribeck one (with or
    without the load-dependent term) within 1.3 sigma, viscous + Coulomb measurably worse."""
    ctx, real = quick_context(tmp_path, overrides={"run_tx40": False, "friction_model": "stribeck",
                                                   "excitation": {"n_random": 4, "max_iter": 30}})
    res = stage.run(ctx)
    s = res.summary
    ratio = {k: np.asarray(v) for k, v in s["friction_heldout_rms_over_noise"].items()}
    assert set(ratio) == {"viscous_coulomb", "stribeck", "stribeck_load"} and s["friction_model"] == "stribeck"
    best = s["friction_model_best"]
    assert best in ("stribeck", "stribeck_load") and s["friction_model_handed_on"] == best
    assert best == min(ratio, key=lambda k: float(np.mean(ratio[k])))
    assert s["stribeck_status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    np.testing.assert_allclose(ratio[best], s["validation_rms_over_noise"])   # the handed-on model
    assert np.all(ratio[best] <= 1.3) and np.max(ratio["viscous_coulomb"] - ratio[best]) > 0.1
    np.testing.assert_allclose(res.robot.actuation.static_friction_excess_Nm, s["stribeck_static_excess_Nm"])
    assert (res.robot.actuation.coulomb_load_coefficient is not None) == (best == "stribeck_load")


def test_stribeck_fit_is_handed_on_in_the_saved_model(rx130l: RobotModel, tmp_path) -> None:
    """identified_robot carries fs, vs; save + load keeps them; friction_torque and the control
    feedforward include the Stribeck term; without a fit the model is viscous + Coulomb again."""
    act, nq = rx130l.actuation, rx130l.nq
    p = standard_parameters(rx130l.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    fs, vs = np.linspace(1.0, 3.0, nq), np.linspace(0.03, 0.08, nq)
    fit = StribeckFit(np.zeros(1), fs, vs, act.coulomb_smoothing_rad_s, "Solve_Succeeded", 1)
    identified = stage.identified_robot(rx130l, p, fit)
    loaded = RobotModel.load(identified.save(tmp_path / "identified"))
    assert robots_equal(load_exact_robot(save_exact_robot(identified, tmp_path / "exact")), identified)
    v = np.linspace(-0.3, 0.3, 61)[:, None] * np.ones(nq)
    linear = rx130l.friction_torque(v)
    np.testing.assert_allclose(loaded.friction_torque(v), linear + stribeck_torque(v, fs, vs, WIDTH), atol=1e-9)
    assert np.max(np.abs(loaded.friction_torque(v) - linear)) > 0.5 * fs.max()
    q = np.zeros((len(v), nq))
    ff = feedforward_torque(loaded, q, v, q, "full_friction") - feedforward_torque(rx130l, q, v, q, "full_friction")
    np.testing.assert_allclose(ff, stribeck_torque(v, fs, vs, WIDTH), atol=1e-6)
    again = stage.identified_robot(loaded, p)        # viscous_coulomb: no Stribeck term handed on
    assert again.actuation.static_friction_excess_Nm is None
    np.testing.assert_array_equal(again.friction_torque(v), linear)


def test_stribeck_model_validates_better_on_a_stribeck_truth(rx130l: RobotModel) -> None:
    """A short simulated excitation of a hidden robot with Stribeck and load-dependent friction,
    processed like the stage (period averaging, block-mean decimation), scored on a slower held-out
    trajectory: the Stribeck model within 1.3 sigma on every joint, viscous + Coulomb measurably worse."""
    real = RealRobot.create(rx130l, 2, TruthConfig())
    robot = calibrated_robot(rx130l, real)
    nq, rng = robot.nq, np.random.default_rng(0)
    reg = RegressorModel(robot.model, np.eye(nq), robot.actuation.coulomb_smoothing_rad_s)
    base = base_parameters(reg, rng, 200, lower=robot.limits.lower_rad, upper=robot.limits.upper_rad)
    limits = fourier.ExcitationLimits.from_robot(robot, 0.9, 0.9, 0.9, 0.8, 0.0, 0.0)
    traj = fourier.random_trajectory(robot, limits, 5, 0.1, rng)
    sim = meas_mod.simulate_excitation(real, traj, 2, 0.002, rng)
    data = meas_mod.process_periodic(sim, reg, int(round(traj.period_s / 0.002)), 2.0, 5)
    Wb = base.base_regressor(data.Y)
    wls = est_mod.wls(Wb, data.y, nq)
    fit = fit_stribeck(Wb, data.y, data.v_blocks, wls.beta, wls.joint_sigma_Nm, reg.coulomb_width_rad_s)
    val = fourier.random_trajectory(robot, limits, 2, 0.05, rng)
    t = np.arange(0.0, val.period_s, 0.004)
    q, v, a = val.evaluate(t)
    measured = real.execute_joint_trajectory(t, q, v, a, rng)
    Wv, sigma = base.base_regressor(reg.stacked(q, v, a)), measured.tau_sigma_Nm
    ratio_vc = np.sqrt(np.mean(((Wv @ wls.beta).reshape(-1, nq) - measured.tau_Nm) ** 2, axis=0)) / sigma
    ratio_st = np.sqrt(np.mean((fit.predict(Wv, v) - measured.tau_Nm) ** 2, axis=0)) / sigma
    assert np.all(ratio_st <= 1.3)
    assert np.all(ratio_st <= ratio_vc + 0.02) and np.max(ratio_vc - ratio_st) > 0.2
    np.testing.assert_allclose(fit.static_excess_Nm, real.transmission.static_excess_Nm, rtol=0.3, atol=0.1)
