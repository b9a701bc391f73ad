"""Friction and actuation terms beyond viscous + Coulomb, chosen per joint by forward-chaining
cross-validation on a record's training part: the class behind the data is found on the joint that
has it and nowhere else, beats the viscous + Coulomb model on the held-out tail, and implausible
fits are refused; the model-class check flags a joint whose residual keeps structure and passes one
whose residual is noise."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.identification.friction_terms import (
    MAX_EFFORT_GAIN,
    JointTerm,
    add_back,
    not_handed_on_note,
    report_lines,
    select_terms,
    take_off,
)
from pipeline.identification.gates import MAX_RESIDUAL_AUTOCORRELATION, model_class_structure
from pipeline.identification.measure import ProcessedData

WIDTH = 0.01
DT = 0.01
LIMIT = np.array([100.0, 100.0])
NOISE_NM = 0.05


def _trajectory(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n) * DT
    f = np.array([[0.11, 0.23, 0.37], [0.13, 0.29, 0.41]])
    q = np.column_stack([np.sum(np.sin(2 * np.pi * f[j] * t[:, None] + j), axis=1) * 0.6 for j in range(2)])
    v = np.gradient(q, DT, axis=0)
    return q, v, np.gradient(v, DT, axis=0)


def _record(extra, seed: int = 0, n: int = 6000, sigma: float = NOISE_NM, gain: float = 0.0) -> ProcessedData:
    """Two joints whose rows share a 'gravity' column (as a chain's do), each with its own inertia,
    viscous, Coulomb and offset columns; ``extra(q, v)`` (N, 2) added friction; joint 2's effort
    scaled by ``1 + gain``."""
    q, v, a = _trajectory(n)
    Y = np.zeros((n, 2, 9))
    Y[:, 0, 0] = Y[:, 1, 0] = np.cos(q[:, 0] + q[:, 1])        # shared by both rows
    Y[:, 0, 1] = np.cos(q[:, 0])
    for j in range(2):
        Y[:, j, 2 + j] = a[:, j]
        Y[:, j, 4 + j] = v[:, j]
        Y[:, j, 6 + j] = np.tanh(v[:, j] / WIDTH)
    Y[:, 0, 8] = 1.0
    beta = np.array([20.0, 15.0, 0.5, 0.3, 1.0, 0.6, 2.0, 1.5, 0.4])
    tau = (Y.reshape(-1, 9) @ beta).reshape(n, 2) + extra(q, v)
    tau[:, 1] *= 1.0 + gain
    tau += np.random.default_rng(seed).normal(size=tau.shape) * sigma
    return ProcessedData(q, v, a, tau, Y.reshape(-1, 9), DT)


def _heldout_rms(data: ProcessedData, train: int) -> np.ndarray:
    """Per joint RMS on the tail of the rigid model fitted on the first ``train`` samples (for a record
    with terms taken off, the error of the rigid model plus the terms against the measured torques)."""
    W, nr = data.Y, 2
    beta = np.linalg.lstsq(W[: train * nr], data.y[: train * nr], rcond=None)[0]
    return np.sqrt(np.mean((data.tau[train:] - (W[train * nr:] @ beta).reshape(-1, nr)) ** 2, axis=0))


def _selected(data: ProcessedData, train: int):
    return select_terms(data, lambda Y: Y, train, WIDTH, LIMIT)


def _sigmoid(q, v):
    """Gaz et al.'s sigmoid friction on joint 1 (a level of 3 N·m, steep, shifted by 0.05 rad/s)."""
    out = np.zeros_like(v)
    out[:, 0] = 3.0 / (1.0 + np.exp(-40.0 * (v[:, 0] + 0.05))) - 3.0 / (1.0 + np.exp(-40.0 * 0.05))
    return out


def _asymmetric(q, v):
    out = np.zeros_like(v)
    out[:, 1] = 0.8 * np.abs(np.tanh(v[:, 1] / WIDTH))     # Coulomb 0.8 N·m higher one way than the other
    return out


def _position(q, v):
    out = np.zeros_like(v)
    out[:, 1] = 0.6 * np.sin(q[:, 1]) + 0.3 * np.cos(2 * q[:, 1])
    return out


@pytest.mark.parametrize(("extra", "joint", "kind"), [(_sigmoid, 0, "sigmoid"), (_asymmetric, 1, "coulomb_asymmetry"),
                                                      (_position, 1, "position")])
def test_the_class_behind_the_data_is_chosen_on_its_joint_and_wins_on_the_tail(extra, joint, kind):
    data = _record(extra)
    train = int(0.7 * data.n_samples)
    terms = _selected(data, train)
    chosen = terms.by_joint(2)
    assert kind in chosen[joint] and chosen[1 - joint] == [], chosen
    less = take_off(data, terms, lambda Y: Y)
    before, after = _heldout_rms(data, train), _heldout_rms(less, train)
    assert after[joint] < 0.5 * before[joint]
    assert after[1 - joint] <= 1.01 * before[1 - joint]
    assert np.all(terms.cv_rms_after_Nm <= terms.cv_rms_before_Nm * 1.02 + 1e-12)


def test_an_effort_to_torque_constant_off_on_one_joint_is_found_there():
    """Joint 2's effort 15 % high: its rows share the 'gravity' parameter with joint 1, so the ratio of
    the two joints' constants is identifiable (not their common scale): one gain is chosen, on joint 2
    (+15 %) or on joint 1 (1 / 1.15 - 1 = -13 %), within a few per cent; nothing else."""
    data = _record(lambda q, v: np.zeros_like(v), gain=0.15)
    terms = _selected(data, int(0.7 * data.n_samples))
    assert len(terms.terms) == 1 and terms.terms[0].kind == "effort_gain"
    g, joint = terms.terms[0].coefficients[0], terms.terms[0].joint
    assert g == pytest.approx(0.15 if joint == 1 else 1 / 1.15 - 1, abs=0.03)
    assert np.all(terms.cv_rms_after_Nm < 1.1 * NOISE_NM) and np.all(terms.cv_rms_before_Nm > 3 * NOISE_NM)


def test_viscous_coulomb_data_take_no_term():
    data = _record(lambda q, v: np.zeros_like(v), seed=3)
    terms = _selected(data, int(0.7 * data.n_samples))
    assert terms.terms == [] and take_off(data, terms, lambda Y: Y) is data
    summary = terms.summary(lambda a: list(a), np.array([1, 2]))
    assert not_handed_on_note(summary) is None and not any("Not handed on" in line for line in report_lines(summary))


def test_chosen_terms_are_stated_as_not_handed_on():
    """The robot handed on has robot.yaml's friction law only: the summary's warning and the report
    name the joint and the class that stay in the identification."""
    terms = _selected(_record(_sigmoid), int(0.7 * _record(_sigmoid).n_samples))
    summary = terms.summary(lambda a: list(a), np.array([1, 2]))
    note = not_handed_on_note(summary)
    assert note is not None and "joint 1 (sigmoid)" in note and "joint 2" not in note
    assert any(line.startswith("**Not handed on:**") and "joint 1 (sigmoid)" in line for line in report_lines(summary))


def test_implausible_terms_are_refused():
    """Friction that feeds energy in (a sigmoid falling with velocity), terms above a tenth of the
    torque limit and an effort constant off by more than its bound are not physical."""
    assert not JointTerm("sigmoid", 0, 0.1, 0.0, np.array([-1.0])).plausible(100.0)
    assert JointTerm("sigmoid", 0, 0.1, 0.0, np.array([1.0])).plausible(100.0)
    assert not JointTerm("sigmoid", 0, 0.1, 0.0, np.array([6.0])).plausible(100.0)     # phi1 = 12 > 10
    assert not JointTerm("position", 0, coefficients=np.array([8.0, 8.0, 0.0, 0.0])).plausible(100.0)
    assert not JointTerm("effort_gain", 0, coefficients=np.array([MAX_EFFORT_GAIN * 1.1])).plausible(100.0)
    # on data: a strong negative sigmoid on joint 1 is not handed on as friction
    data = _record(lambda q, v: -_sigmoid(q, v))
    terms = _selected(data, int(0.7 * data.n_samples))
    assert all(t.plausible(100.0) for t in terms.terms)
    assert "sigmoid" not in terms.by_joint(2)[0]


def test_held_out_torques_get_the_terms_back():
    class Val:
        tau_Nm = np.ones((3, 2))
        pred_phys = np.zeros((3, 2))
        pred_load = None

    val = Val()
    add_back(val, np.full((3, 2), 2.0))
    assert np.all(val.tau_Nm == 3.0) and np.all(val.pred_phys == 2.0) and val.pred_load is None


def test_model_class_check_flags_structure_and_passes_noise():
    """White noise through a zero-phase low-pass has decorrelated at one cut-off period; a slow
    periodic error left by the model class has not. A held-out error well above the fit's is
    flagged too, and every flag is a warning naming the joint."""
    rng = np.random.default_rng(1)
    n, lag = 4000, 5
    t = np.arange(n) * DT
    noise = rng.normal(size=(n, 2))
    kernel = np.ones(lag) / lag                     # decorrelated beyond lag samples
    noise = np.column_stack([np.convolve(noise[:, j], kernel, mode="same") for j in range(2)])
    residual = noise.copy()
    residual[:, 1] += 2.0 * np.std(noise[:, 1]) * np.sign(np.sin(2 * np.pi * 0.2 * t))
    fit = np.sqrt(np.mean(residual**2, axis=0))
    out = model_class_structure(residual, fit, lag, np.array([3, 4]))
    acf = out["model_class_residual_autocorrelation"]
    assert acf[0] < MAX_RESIDUAL_AUTOCORRELATION < acf[1]
    assert out["model_class_structure_joints"] == [4] and "joint 4" in out["warnings"][0]
    passes = model_class_structure(noise, np.sqrt(np.mean(noise**2, axis=0)), lag, np.array([3, 4]))
    assert passes["model_class_structure_joints"] == [] and "warnings" not in passes
    far = model_class_structure(noise, 2.0 * np.sqrt(np.mean(noise**2, axis=0)), lag, np.array([3, 4]))
    assert far["model_class_structure_joints"] == [3, 4]
