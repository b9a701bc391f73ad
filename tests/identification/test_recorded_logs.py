"""Recorded torque logs as logged: non-uniform time stamps resampled (largest gap reported, a gap
the position filter cannot bridge refused), torque columns without a signal detected or joints
named, friction terms nested and plausible, base-parameter covariance valid for correlated
residuals (HAC)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from pipeline.core.errors import ConfigError, DataFileError
from pipeline.identification import estimate as est_mod
from pipeline.identification.config import Config
from pipeline.identification.friction import fit_stribeck, stribeck_chi2_gain, stribeck_torque
from pipeline.identification.joints import select_joints, unmeasured_torque_columns
from pipeline.identification.record import load_user_record
from pipeline.identification.signals import resample_uniform
from pipeline.robot.model import RobotModel

from .test_stage import _write_csv


def _jittered_times(rng: np.random.Generator, n: int, dt: float, jitter: float) -> np.ndarray:
    return np.cumsum(np.concatenate([[0.0], dt * (1 + jitter * rng.uniform(-1, 1, n - 1))]))


def test_resampling_keeps_smooth_signals_and_reports_the_gap():
    rng = np.random.default_rng(3)
    t = _jittered_times(rng, 3000, 0.01, 0.25)
    q = np.column_stack([np.sin(0.7 * t), np.cos(1.3 * t)])
    tau = np.column_stack([np.cos(0.5 * t), np.sin(0.9 * t)])
    res = resample_uniform(t, q, tau)
    steps = np.diff(res.t_s)
    assert np.ptp(steps) < 1e-9 and res.sample_time_s == pytest.approx(np.median(np.diff(t)))
    assert res.max_gap_s == pytest.approx(np.max(np.diff(t)))
    assert t[res.max_gap_index] - t[res.max_gap_index - 1] == pytest.approx(res.max_gap_s)
    q_true = np.column_stack([np.sin(0.7 * res.t_s), np.cos(1.3 * res.t_s)])
    tau_true = np.column_stack([np.cos(0.5 * res.t_s), np.sin(0.9 * res.t_s)])
    assert np.max(np.abs(res.q - q_true)) < 1e-7          # cubic spline: O(dt^4)
    assert np.max(np.abs(res.tau - tau_true)) < 1e-4      # linear: O(dt^2)
    assert "spline" in res.method and "linear" in res.method


def _record(tmp_path, t, tau_scale=1.0):
    q = 0.3 * np.sin(np.outer(t, np.arange(1, 7)) * 0.8)
    tau = tau_scale * np.cos(np.outer(t, np.arange(1, 7)))
    path = tmp_path / "record.csv"
    _write_csv(path, t, q, tau)
    return path, tau


def test_a_record_with_non_uniform_time_stamps_is_resampled(tmp_path, rx130l: RobotModel):
    t = _jittered_times(np.random.default_rng(1), 4000, 0.004, 0.4)
    path, _ = _record(tmp_path, t)
    rec = load_user_record(Config(data_file=str(path)), rx130l)
    assert np.ptp(np.diff(rec.t_s)) < 1e-9
    assert rec.max_gap_s == pytest.approx(np.max(np.diff(t))) and rec.max_gap_where.startswith("line ")
    assert rec.resampling and rec.line_numbers is not None and len(rec.line_numbers) == len(rec.t_s)


def test_a_gap_too_long_for_the_filter_is_refused_in_one_line(tmp_path, rx130l: RobotModel):
    t = np.arange(4000) * 0.004
    t[2000:] += 0.2                                    # a 0.204 s hole in the log
    path, _ = _record(tmp_path, t)
    with pytest.raises(DataFileError) as info:
        load_user_record(Config(data_file=str(path), data_cutoff_hz=20.0), rx130l)
    message = info.value.one_line()
    assert message.startswith(f"{path}: t: ") and "\n" not in message
    assert "line 2002" in message and "0.025" in message      # where, and the bound 1 / (2 x 20 Hz)


def test_a_stray_time_stamp_is_refused_before_a_grid_is_built(tmp_path, rx130l: RobotModel):
    """One time stamp of 1e6 s in a 4 ms log would resample onto 2.5e8 steps: refused, naming its line."""
    t = np.arange(4000) * 0.004
    t[-1] = 1e6
    path, _ = _record(tmp_path, t)
    with pytest.raises(DataFileError) as info:
        load_user_record(Config(data_file=str(path)), rx130l)
    message = info.value.one_line()
    assert message.startswith(f"{path}: t: ") and "line 4001" in message and "gap" in message


def test_torque_columns_without_a_signal_are_detected():
    rng = np.random.default_rng(0)
    n = 5000
    good = rng.normal(size=(n, 2)).cumsum(axis=0)
    zeros = np.where(rng.uniform(size=n) < 0.85, 0.0, rng.normal(size=n))
    quantised = np.round(rng.normal(size=n) * 2) * 0.5     # a handful of levels
    constant = np.full(n, 1.5)
    found = unmeasured_torque_columns(np.column_stack([good, zeros, quantised, constant]))
    assert set(found) == {2, 3, 4}
    assert "exactly 0" in found[2] and "quantised" in found[3] and "constant" in found[4]


def test_joints_are_named_by_name_or_index_and_bad_names_refused():
    names = ["a1", "a2", "a3", "a4"]
    auto = select_joints([], names, {3: "85% of its logged torques are exactly 0"})
    assert list(auto.used) == [0, 1, 2] and auto.to_dict()["joints_unmeasured"] == {"a4": auto.left_out[3]}
    named = select_joints(["a2", 1], names, {})
    assert list(named.used) == [0, 1] and set(named.left_out) == {2, 3}
    assert named.per_joint([0.5, 0.7]) == [0.5, 0.7, None, None]
    for bad in (["a9"], [0], [5]):
        with pytest.raises(ConfigError, match="identification.joints"):
            select_joints(bad, names, {})
    with pytest.raises(ConfigError, match="no joint left"):
        select_joints([], names[:1], {0: "constant"})


WIDTH = 0.01


def _friction_data(rng, n, fs, vs, sigma):
    v = rng.uniform(-1.0, 1.0, (n, 2)) * rng.choice([0.05, 1.0], (n, 2))
    W = np.zeros((n, 2, 8))
    for j in range(2):
        W[:, j, 4 * j : 4 * j + 2] = rng.normal(size=(n, 2))
        W[:, j, 4 * j + 2] = v[:, j]
        W[:, j, 4 * j + 3] = np.tanh(v[:, j] / WIDTH)
    beta = np.array([1.0, -2.0, 3.0, 4.0, 0.7, 1.5, 2.0, 2.5])
    tau = (W.reshape(-1, 8) @ beta).reshape(n, 2) + stribeck_torque(v, fs, vs, WIDTH)
    return W.reshape(-1, 8), (tau + rng.normal(size=tau.shape) * sigma).ravel(), v


@pytest.mark.parametrize("seed", range(4))
def test_nested_stribeck_fit_gains_are_never_negative_and_terms_bounded(seed):
    """The Stribeck fit extends the viscous + Coulomb one: each kept term lowers the weighted residual
    (gain >= threshold), a dropped one reports 0; no static excess above its bound."""
    rng = np.random.default_rng(seed)
    sigma = np.array([0.05, 0.05])
    fs = np.array([3.0, 0.0]) if seed % 2 else np.array([0.0, 0.0])
    W, y, v = _friction_data(rng, 1500, fs, np.array([0.1, 0.1]), sigma)
    b0 = est_mod.wls(W, y, 2).beta
    bound = np.array([1.0, 1.0])
    fit = fit_stribeck(W, y, v, b0, sigma, WIDTH, max_excess_Nm=bound)
    assert np.all(fit.chi2_gain >= 0) and np.all(fit.static_excess_Nm <= bound + 1e-9)
    kept = fit.static_excess_Nm > 0
    assert np.all(fit.chi2_gain[~kept] == 0)
    # the reported gains are the likelihood-ratio statistics of the handed-on terms
    gain = stribeck_chi2_gain(W, y, fit.stribeck_torque(v), sigma)
    np.testing.assert_allclose(fit.chi2_gain[kept], gain[kept], rtol=1e-6)
    assert kept[0] == bool(fs[0]) and not kept[1]


def _ar1(rng, n, rho, size):
    """AR(1) series e_k = rho e_(k-1) + w_k (a burn-in of 100 samples dropped)."""
    return scipy.signal.lfilter([1.0], [1.0, -rho], rng.normal(size=(n + 100, size)), axis=0)[100:]


def test_hac_covariance_covers_correlated_residuals():
    """Smooth regressors, AR(1) residuals (rho 0.9): the white-residual covariance is far too
    optimistic, the HAC sandwich puts >= 90 % of the estimates within 3 sigma (Monte Carlo);
    on white residuals the two agree."""
    rng = np.random.default_rng(5)
    n, nv = 400, 2
    t = np.linspace(0, 4 * np.pi, n)
    X = np.zeros((n, nv, 4))
    X[:, 0, 0], X[:, 0, 1] = np.sin(t), np.cos(0.5 * t)
    X[:, 1, 2], X[:, 1, 3] = np.sin(1.5 * t), 1.0
    W = X.reshape(-1, 4)
    beta = np.array([1.0, -1.0, 0.5, 2.0])
    within = {"white": [], "hac": []}
    ratio_white = []
    for _ in range(100):
        e = _ar1(rng, n, 0.9, nv) * np.array([0.1, 0.2])
        y = W @ beta + e.ravel()
        est = est_mod.wls(W, y, nv)
        hac = est_mod.wls_hac_covariance(W, y, est)
        within["white"].append(np.abs(est.beta - beta) <= 3 * est.sigma)
        within["hac"].append(np.abs(est.beta - beta) <= 3 * hac.sigma)
        e_white = rng.normal(size=(n, nv)) * np.array([0.1, 0.2])
        est_w = est_mod.wls(W, W @ beta + e_white.ravel(), nv)
        ratio_white.append(est_mod.wls_hac_covariance(W, W @ beta + e_white.ravel(), est_w).white_ratio)
    assert np.mean(within["white"]) < 0.8
    assert np.mean(within["hac"]) >= 0.9
    assert 0.7 < np.median(ratio_white) < 1.3
