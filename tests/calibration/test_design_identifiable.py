"""The design's identifiable set shrinks to what the feasible configurations can identify."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration.design import _random_regular_start
from pipeline.calibration.design_identifiable import POOL_REL_TOL, pool_identifiable_columns, restrict_to_pool
from pipeline.calibration.error_model import IdentifiabilityReport
from pipeline.calibration.outcome import ModelSetUp


def _pool(rng: np.random.Generator, dependent: bool) -> np.ndarray:
    """(N, 3, 5) blocks; with ``dependent`` column 3 is 2 x column 1 (up to 1e-9): the pool cannot
    tell parameters 1 and 3 apart."""
    G = rng.normal(size=(60, 3, 5))
    if dependent:
        G[:, :, 3] = 2.0 * G[:, :, 1] + 1e-9 * rng.normal(size=(60, 3))
    return G


def _model_and_candidates(G: np.ndarray) -> tuple[ModelSetUp, cd.CandidateSet]:
    p = G.shape[-1]
    names = [f"x{k}" for k in range(p)]
    report = IdentifiabilityReport(names, list(range(p)), np.ones(p), p, [], {}, [], [])
    mm = SimpleNamespace(compliance=False)
    basis = np.eye(p)
    model = ModelSetUp(None, mm, report, basis, basis.copy(), None)
    cs = cd.CandidateSet(np.zeros((len(G), 6)), np.zeros((len(G), 3)), np.ones(len(G)), G, basis)
    return model, cs


def test_a_dependent_parameter_is_dropped_and_the_design_proceeds_on_the_rest():
    rng = np.random.default_rng(0)
    G = _pool(rng, dependent=True)
    assert np.linalg.eigvalsh(np.einsum("kmi,kmj->ij", G, G))[0] < 1e-10 * 60     # every selector refuses it
    model, cs = _model_and_candidates(G)
    cs, dropped = restrict_to_pool(model, cs)
    assert len(dropped) == 1 and dropped[0].name in ("x1", "x3") and dropped[0].relative_r <= POOL_REL_TOL
    assert "held at its nominal value" in dropped[0].why
    assert cs.G.shape == (60, 3, 4) and model.basis.shape == (5, 4) and model.design_basis.shape == (5, 4)
    assert model.report.identifiable_names == [n for n in ("x0", "x1", "x2", "x3", "x4") if n != dropped[0].name]
    assert len(_random_regular_start(cs.G, 10, rng)) == 10                         # regular now


def test_a_regular_pool_keeps_every_parameter():
    G = _pool(np.random.default_rng(1), dependent=False)
    keep, relative = pool_identifiable_columns(G)
    assert list(keep) == list(range(5)) and relative.max() == 1.0
    model, cs = _model_and_candidates(G)
    cs2, dropped = restrict_to_pool(model, cs)
    assert not dropped and cs2.G.shape == G.shape and model.basis.shape == (5, 5)
