"""Study calib-003 (papers/003): incremental indices, searches, and the quick study."""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest

from pipeline.calibration import indices as ix
from pipeline.papers import calib_003 as p3
from pipeline.papers import calib_003_search as ps
from pipeline.papers import calib_003_sizes as p3s
from pipeline.papers import registry as studies

#: BSAA's cooling factor in the quick study test (the paper's: 0.98, the default of ps.bsaa)
FAST_COOLING = 0.9


def _pool(seed: int = 0, N: int = 120, p: int = 12) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(N, 3, p)) * np.linspace(0.2, 3.0, p)
    P = rng.uniform(0.0, 1000.0, (N, 3))
    return J, P


def _direct(J: np.ndarray, P: np.ndarray, S: np.ndarray, scale: ps.OcScale) -> dict[str, float]:
    M = np.einsum("kmi,kmj->ij", J[S], J[S])
    s = np.sqrt(np.linalg.eigvalsh(M))
    o1 = float(np.exp(np.mean(np.log(s))) / np.sqrt(len(S)))
    od = ix.od_index(P[S], 3)
    oc = float(ps.oc_terms(o1, s[0], od, scale).sum())
    return {"O1": o1, "O2": float(s[0] / s[-1]), "O3": float(s[0]), "Od": od, "Oc": oc}


def test_incremental_state_matches_a_recomputation_after_swaps_and_undo():
    J, P = _pool()
    rng = np.random.default_rng(1)
    scale = ps.OcScale(1.0, 1.0, 1e-4)
    state = ps.SubsetState(J, P, ps.random_subset(J, 40, rng), "Oc", 3, scale)
    for _ in range(60):
        out = int(rng.choice(state.selected))
        inn = int(rng.choice(np.flatnonzero(~state.sel)))
        token = state.swap(out, inn)
        if rng.random() < 0.5:
            state.undo(token)
    got, want = state.all_values(), _direct(J, P, state.selected, scale)
    for k in want:
        assert got[k] == pytest.approx(want[k], rel=1e-9)


@pytest.mark.parametrize("name", ["O1", "O2", "O3", "Od", "Oc"])
def test_best_add_and_remove_equal_the_exhaustive_search(name):
    J, P = _pool(2)
    rng = np.random.default_rng(3)
    scale = ps.OcScale(1.0, 1.0, 1e-4)
    state = ps.SubsetState(J, P, ps.random_subset(J, 40, rng), name, 3, scale)
    cand = np.flatnonzero(~state.sel)
    add = [_direct(J, P, np.append(state.selected, c), scale)[name] for c in cand]
    j, v = state.best_add(cand)
    assert j == cand[int(np.argmax(add))] and v == pytest.approx(max(add), rel=1e-9)
    rem = [_direct(J, P, state.selected[state.selected != s], scale)[name] for s in state.selected]
    k, v = state.best_remove()
    assert k == state.selected[int(np.argmax(rem))] and v == pytest.approx(max(rem), rel=1e-9)


@pytest.mark.parametrize("search", [ps.detmax, ps.bsaa])
@pytest.mark.parametrize("name", ["O1", "O3", "Oc"])
def test_searches_reach_a_better_index_than_random_designs(search, name):
    J, P = _pool(4)
    rng = np.random.default_rng(5)
    scale = ps.reference_scale(J, P, 30, rng)
    res = search(J, P, name, 30, rng, scale)
    assert len(np.unique(res.selected)) == 30
    reached = ps.index_values(J, P, res.selected, scale=scale)[name]
    assert reached == pytest.approx(res.index_value, rel=1e-9)
    randoms = [ps.index_values(J, P, ps.random_subset(J, 30, rng), scale=scale)[name] for _ in range(10)]
    assert reached > max(randoms)


def test_normalised_oc_terms_sit_mid_range():
    J, P = _pool(6)
    rng = np.random.default_rng(7)
    scale = ps.reference_scale(J, P, 30, rng)
    vals = ps.index_values(J, P, ps.random_subset(J, 30, rng), scale=scale)
    terms = ps.oc_terms(vals["O1"], vals["O3"], vals["Od"], scale)
    assert np.all((terms > 0.2) & (terms < 0.8))


def test_quick_study_prints_every_row_and_calibrates(tmp_path, monkeypatch, capsys):
    """The quick study with every section (the sweep and the small designs on one seed), its eight BSAA
    searches cooled five times faster (0.9 per step instead of the paper's 0.98: 1530 steps from 1e20
    to 1e-50 instead of 7978); BSAA on the paper's schedule: the search tests above."""
    monkeypatch.setattr(studies, "study_dir", lambda name, root=None: tmp_path)
    monkeypatch.setattr(ps, "bsaa", functools.partial(ps.bsaa, cooling=FAST_COOLING))
    assert p3.study_003(["--quick", "--seeds", "1", "--sweep-seeds", "1", "--small", "20"]) == 0
    res = json.loads((tmp_path / "result.json").read_text())
    out = capsys.readouterr().out
    assert {"none", "bsaa_Oc", "gain", "ours_gain"} <= set(res["paper_table4"])
    for table in ("table_literal", "table_realistic"):
        for key in p3.KEYS:
            assert key in res[table]
    for key in p3.KEYS:
        assert key.replace("_", " x ", 1) in out
        # every design calibrates: far below the uncalibrated error under both truths
        for truth in ("literal", "realistic"):
            row = res["rows"][0]["truths"][truth]
            assert row[key]["mean"] < row["uncalibrated"]["mean"] / 3
    # the designs' overlap with the random one is reported (the cause of equal errors at the paper's sizes)
    assert 0 < res["indices"]["bsaa_Oc"]["shared"][0] <= 60
    # each search reaches at least the random design's value of its own index
    d = res["rows"][0]["designs"]
    for alg in ("detmax", "bsaa"):
        for name in ("O1", "O2", "O3", "Oc"):
            assert d[f"{alg}_{name}"]["indices"][name] >= d["none"]["indices"][name]
    # without unmodelled effects the calibrated error is at the tracker-noise level (micrometres)
    assert res["rows"][0]["truths"]["literal"]["none"]["mean"] < 50e-6


@pytest.mark.slow
def test_quick_sizes_study_calibrates_every_design_to_the_noise_floor(tmp_path, monkeypatch):
    """The literal (model-consistent) truth at small subset sizes: every design calibrates, its model
    error is micrometres, and each search raises its index."""
    monkeypatch.setattr(studies, "study_dir", lambda name, root=None: tmp_path)
    assert p3s.study(["--quick", "--seeds", "1"]) == 0
    res = json.loads((tmp_path / "result.json").read_text())
    assert res["args"]["sizes"] == [20, 40] and set(res["table_sizes"]) == {"20", "40"}
    for n, per in res["rows"][0]["sizes"].items():
        err = per["errors"]
        for key in p3s.design_keys():
            assert err[key]["measured"] == int(n)
            assert err[key]["mean"] < err["uncalibrated"]["mean"] / 20
            assert err[key]["model"] < 50e-6
        assert per["indices"]["detmax_O1"]["O1"] >= per["indices"]["none"]["O1"]
        assert per["indices"]["detmax_O3"]["O3"] >= per["indices"]["none"]["O3"]
