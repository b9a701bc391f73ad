"""The fit's data on an arm whose dry friction sticks (the MuJoCo arm): the samples in the stiction band
are left out (:func:`pipeline.identification.measure.without_stiction_band`), with the validation's band."""

from __future__ import annotations

import numpy as np

from pipeline.identification import estimate as est_mod
from pipeline.identification.measure import (
    STICTION_BAND_OVER_WIDTH,
    ProcessedData,
    in_stiction_band,
    stiction_band_speed,
    without_stiction_band,
)
from pipeline.identification.validate import outside_stiction_band

WIDTH_RAD_S = 0.01


def _data(v_blocks: np.ndarray, n_params: int = 3) -> ProcessedData:
    """Samples with block velocities ``v_blocks`` (N, k, nr); regressor row ``(k, j)`` holds ``100 k + j``
    in every column and torque ``(k, j)`` the same number, so a kept row can be traced to its sample."""
    n, _, nr = v_blocks.shape
    tag = 100.0 * np.arange(n)[:, None] + np.arange(nr)[None, :]
    Y = np.repeat(tag.reshape(-1, 1), n_params, axis=1)
    return ProcessedData(np.zeros((n, nr)), v_blocks.mean(axis=1), np.zeros((n, nr)), tag.copy(), Y, 0.01,
                         np.ones(nr), v_blocks)


def test_the_fit_and_the_validation_share_one_band() -> None:
    assert stiction_band_speed(WIDTH_RAD_S) == STICTION_BAND_OVER_WIDTH * WIDTH_RAD_S
    v = np.array([-0.03, -0.019, 0.0, 0.019, 0.02, 0.5])
    np.testing.assert_array_equal(in_stiction_band(v, WIDTH_RAD_S), [False, True, True, True, False, False])


def test_a_sample_with_a_joint_in_the_band_or_a_reversal_in_its_block_is_left_out_whole() -> None:
    fast = [0.5, 0.6, 0.7]
    blocks = np.array([
        [fast, fast],                       # 0: kept
        [[0.3, 0.01, 0.3], fast],           # 1: joint 1 below v_s in its block
        [fast, [0.4, -0.4, -0.5]],          # 2: joint 2 reverses inside the block (no reading in the band)
        [[-0.5, -0.6, -0.7], fast],         # 3: kept (one sign, fast)
        [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]],  # 4: both at rest
    ]).transpose(0, 2, 1)                    # (N, k, nr)
    data = _data(blocks)
    kept, ex = without_stiction_band(data, WIDTH_RAD_S)
    assert (ex.n_total, ex.n_left_out) == (5, 3)
    np.testing.assert_array_equal(ex.in_band_per_joint, [2, 2])
    assert ex.band_rad_s == stiction_band_speed(WIDTH_RAD_S)
    # the rows of the kept samples, one per joint, in order, and their torques with them
    np.testing.assert_array_equal(kept.Y[:, 0], [0.0, 1.0, 300.0, 301.0])
    np.testing.assert_array_equal(kept.y, kept.Y[:, 0])
    assert kept.n_samples == 2 and kept.v_blocks.shape == (2, 3, 2)
    np.testing.assert_array_equal(kept.v, data.v[[0, 3]])


def test_held_samples_bias_the_coulomb_level_and_leaving_them_out_removes_it() -> None:
    """One joint, ``tau = fv v + fc tanh(v / w)`` while it slides; in the band the drive's torque is anywhere
    in the breakaway band ``[-1.1 fc, 1.1 fc]`` (held, MuJoCo-like), here at the breakaway level against
    the coming motion. Fitted on every sample the Coulomb level is off by several per cent; without the
    band within 0.5 %, less than a fifth of that error."""
    fv, fc, rng = 2.0, 4.0, np.random.default_rng(3)
    t = np.arange(0.0, 10.0, 0.002)
    v = 0.3 * np.sin(2 * np.pi * 0.5 * t)
    k = 5
    vb = v[: len(v) // k * k].reshape(-1, k, 1)
    tau_full = fv * v + fc * np.tanh(v / WIDTH_RAD_S)
    held = in_stiction_band(v, WIDTH_RAD_S)
    a = np.gradient(v, t)
    tau_full[held] = -1.1 * fc * np.sign(a[held])
    tau_full += 0.01 * rng.standard_normal(len(t))
    tau = tau_full[: len(vb) * k].reshape(-1, k, 1).mean(axis=1)
    Y = np.stack([vb.mean(axis=1)[:, 0], np.tanh(vb / WIDTH_RAD_S).mean(axis=1)[:, 0]], axis=1)
    data = ProcessedData(np.zeros((len(vb), 1)), vb.mean(axis=1), np.zeros((len(vb), 1)), tau, Y, 0.01,
                         np.ones(1), vb)
    all_samples = est_mod.wls(data.Y, data.y, 1).beta
    kept, ex = without_stiction_band(data, WIDTH_RAD_S)
    left_out = est_mod.wls(kept.Y, kept.y, 1).beta
    assert 0 < ex.n_left_out < ex.n_total
    err_all, err_out = abs(all_samples[1] / fc - 1.0), abs(left_out[1] / fc - 1.0)
    assert err_out < 0.005 and err_out < 0.2 * err_all


def test_the_validation_leaves_out_a_joint_held_after_its_commanded_speed_left_the_band() -> None:
    """Joint 1 commanded through a reversal but held by its dry friction for 0.1 s after it (encoder readings
    constant, noise 2 µrad), joint 2 moving throughout: joint 1's held samples are not scored although their
    commanded speed is outside the band; joint 2 is scored everywhere."""
    t = np.arange(0.0, 1.0, 0.004)
    v_cmd = np.stack([0.5 * (t - 0.5), np.full_like(t, 0.3)], axis=1)     # joint 1 reverses at 0.5 s
    q_cmd = np.stack([0.25 * (t - 0.5) ** 2, 0.3 * t], axis=1)
    q_read = q_cmd + 2e-6 * np.random.default_rng(0).standard_normal(q_cmd.shape)
    held = (t > 0.45) & (t < 0.6)
    q_read[held, 0] = q_cmd[np.flatnonzero(held)[0], 0]
    scored = outside_stiction_band(t, v_cmd, q_read, WIDTH_RAD_S)
    inside = held & np.roll(held, 1) & np.roll(held, -1)          # the breakaway reading itself jumps
    past_band = inside & ~in_stiction_band(v_cmd[:, 0], WIDTH_RAD_S)
    assert past_band.sum() >= 10
    assert not scored[past_band, 0].any()
    assert scored[:, 1].all()
    assert scored[t < 0.4, 0].all() and scored[t > 0.65, 0].all()
