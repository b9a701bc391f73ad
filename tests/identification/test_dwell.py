"""A record's joint at rest while others move: the long rests are found and the reversals are not,
their rows carry no equation in the fits (the estimate is the one without them, whatever torque the
drive logged there, and Gautier's sigma counts only the rows that have one), and a held-out tail is
scored as measured."""

from __future__ import annotations

import numpy as np

from pipeline.identification import estimate as est_mod
from pipeline.identification.dwell import DWELL_SPEED_RAD_S, MIN_DWELL_S, Dwells, dwell_rows
from pipeline.identification.measure import ProcessedData

DT = 0.01


def test_a_long_rest_dwells_and_a_reversal_does_not():
    t = np.arange(0.0, 6.0, DT)
    v = np.column_stack([np.cos(2 * np.pi * 0.5 * t),                    # reverses quickly, never rests
                         np.where((t > 2.0) & (t < 3.0), 0.0, 0.5)])     # rests for 1 s
    d = dwell_rows(v, DT)
    assert not d[:, 0].any()
    assert d[:, 1].sum() == np.sum((t > 2.0) & (t < 3.0))
    short = np.where((t > 2.0) & (t < 2.0 + 0.5 * MIN_DWELL_S), 0.0, 0.5)[:, None]
    assert not dwell_rows(short, DT).any()
    creeping = np.where((t > 2.0) & (t < 3.0), 2 * DWELL_SPEED_RAD_S, 0.5)[:, None]
    assert not dwell_rows(creeping, DT).any()


def _record(seed: int = 0) -> tuple[ProcessedData, np.ndarray]:
    """Two joints, a linear model of three columns per row; joint 2 rests for 2 s and its drive logs a
    holding torque there that no state explains."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 10.0, DT)
    v = np.column_stack([np.sin(t), np.where((t > 4.0) & (t < 6.0), 0.0, np.cos(0.7 * t))])
    q = np.cumsum(v, axis=0) * DT
    a = np.gradient(v, DT, axis=0)
    n = len(t)
    Y = np.zeros((n, 2, 6))
    for j in range(2):
        Y[:, j, 3 * j] = a[:, j]
        Y[:, j, 3 * j + 1] = v[:, j]
        Y[:, j, 3 * j + 2] = 1.0
    beta = np.array([0.5, 2.0, 1.0, 0.3, 1.5, -0.5])
    tau = (Y.reshape(-1, 6) @ beta).reshape(n, 2) + rng.normal(size=(n, 2)) * 0.01
    resting = (t > 4.0) & (t < 6.0)
    tau[resting, 1] = rng.uniform(-3.0, 3.0, size=int(resting.sum()))       # held: any torque in the band
    return ProcessedData(q, v, a, tau, Y.reshape(-1, 6), DT), resting


def test_dwell_rows_carry_no_equation():
    data, resting = _record()
    dwells = Dwells.of(data)
    np.testing.assert_array_equal(dwells.rows[:, 1], resting)
    assert not dwells.rows[:, 0].any()
    fit = dwells.without_equations(data)
    est = est_mod.wls(fit.Y, fit.y, 2)
    keep = np.ones((data.n_samples, 2), bool)
    keep[:, 1] = ~resting
    rows = keep.ravel()
    direct = np.linalg.lstsq(data.Y[rows], data.y[rows], rcond=None)[0]
    np.testing.assert_allclose(est.beta, direct, atol=2e-3)
    np.testing.assert_allclose(est.beta, [0.5, 2.0, 1.0, 0.3, 1.5, -0.5], atol=0.01)
    assert est.joint_sigma_Nm[1] < 0.02          # the rows without an equation do not dilute or inflate it
    fitted_as_logged = est_mod.wls(data.Y, data.y, 2)
    assert np.max(np.abs(fitted_as_logged.beta - est.beta)) > 0.05


def test_the_held_out_tail_is_scored_as_measured():
    data, resting = _record()
    dwells = Dwells.of(data)
    first = int(0.5 * data.n_samples)
    part = dwells.without_equations(data, first)
    np.testing.assert_array_equal(part.tau[first:], data.tau[first:])
    np.testing.assert_array_equal(part.Y.reshape(data.n_samples, 2, -1)[first:],
                                  data.Y.reshape(data.n_samples, 2, -1)[first:])
    assert np.all(part.tau[:first][resting[:first], 1] == 0.0)
    assert np.all(part.tau[:first, 0] == data.tau[:first, 0])
