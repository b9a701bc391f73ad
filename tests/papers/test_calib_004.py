"""Quick variant of study calib-004 (paper 004 §3 with its optical 6-D tracker): properties that must hold."""

from __future__ import annotations

import numpy as np

from pipeline.papers import calib_004 as p4
from pipeline.papers import calib_004_optical as op
from pipeline.robot.instruments import OpticalMargins, optical_spec, stated_sigmas
from pipeline.robot.model import RobotModel

MARGINS = OpticalMargins(np.radians(1.0), 0.05, 0.01)


def test_quick_seed_row():
    """One seed of the quick variant and the properties its row must have (the checks below). One
    test, not one per property: a fixture shared by several tests is built again by every pytest-xdist
    worker that runs one of them, and this row is the costliest step of the file."""
    grid = p4.visible_grid("rx130l", 7, MARGINS)
    row = p4._seed(("rx130l", 1, "ideal", grid, 32, 60, ["O3"], MARGINS, "registered", 1.0, None, 1.0, True))
    _candidates_are_the_visible_grid(grid, row)
    _headline_keys_and_the_papers_index(row)
    _calibration_reduces_the_held_out_errors(row)
    _whole_grid_has_the_largest_index_but_not_per_pose(row)


def _candidates_are_the_visible_grid(grid: dict, row: dict) -> None:
    """Candidates are visible grid configurations (nominal model, with margins): a subset of the
    configurations the cameras see without margins, never one they cannot see."""
    robot = RobotModel.load("rx130l")
    assert 32 <= row["n_candidates"] <= grid["n_visible"] < grid["counts"]["total"]
    assert op.visible_mask(robot, grid["Q"]).all()
    assert np.all(np.diff(grid["flat"]) > 0)          # grid order (the grid-order scan relies on it)


def _headline_keys_and_the_papers_index(row: dict) -> None:
    d = row["designs"]
    for key in ("rr_O3", *p4.BASELINES):
        assert {"B", "O3", "cond", "commanded", "predicted_visible", "lost_on_hidden_robot"} <= d[key].keys()
        assert d[key]["predicted_visible"] <= d[key]["commanded"]
        assert 0 <= d[key]["lost_on_hidden_robot"] <= d[key]["predicted_visible"]
    # remove-and-replace on O3 is at least as good as any scan of the same visible candidates
    for key in ("grid_order", "random"):
        assert d["rr_O3"]["B"] >= d[key]["B"]
        assert d[key]["predicted_visible"] == d[key]["commanded"] == 32
    assert d["rr_O3"]["predicted_visible"] == 32


def _calibration_reduces_the_held_out_errors(row: dict) -> None:
    """On the ideal hidden robot the 6-D calibration from the R&R design reduces the held-out
    position and orientation errors (Table 2 layout keys present)."""
    r = row["designs"]["rr_O3"]
    assert r["calibrated"]
    for ax in ("x", "y", "z", "alpha", "beta", "gamma"):
        assert {"max_abs", "half_peak_to_peak"} <= r["after"][ax].keys()
    assert r["after"]["position"]["rms"] < 0.5 * r["before"]["position"]["rms"]
    assert r["after"]["orientation"]["rms"] < r["before"]["orientation"]["rms"]


def _whole_grid_has_the_largest_index_but_not_per_pose(row: dict) -> None:
    """The whole candidate set is measured (every candidate commanded); per measured pose the R&R
    optimum is the better design. (That the whole set's B is at least any subset's holds for any
    Lambda that adds up over poses: not checked here, see test_index_figures_of_a_known_jacobian.)"""
    d = row["designs"]
    whole = d[p4.WHOLE_GRID]
    assert whole["commanded"] == row["n_candidates"]
    assert d["rr_O3"]["B_per_pose"] > whole["B_per_pose"]


def test_index_figures_of_a_known_jacobian():
    """The code path of the paper's index: ``information`` sums G^T G over poses, ``index_figures``
    returns B = the smallest singular value of the stacked Jacobian squared (compared with an SVD of
    the stacked rows, not with the function's own O3), the rank and cond; a rank-deficient Jacobian
    gets B = 0."""
    rng = np.random.default_rng(4)
    G = rng.normal(size=(12, 6, 5)) * np.array([1.0, 3.0, 0.5, 2.0, 0.1])
    fig = p4.index_figures(p4.information(G))
    s = np.linalg.svd(G.reshape(-1, 5), compute_uv=False)
    assert np.isclose(fig["B"], s[-1] ** 2) and fig["rank"] == 5 and np.isclose(fig["cond"], (s[0] / s[-1]) ** 2)
    G[:, :, 4] = G[:, :, 3]                          # two parameters the poses cannot tell apart
    low = p4.index_figures(p4.information(G))
    assert low["B"] == 0.0 and low["rank"] == 4


def test_larger_probe_halves_the_orientation_noise_only():
    """A probe twice as large (diodes about the marker origin x 2): the Kabsch fit's stated
    orientation sigma halves, the position sigma (mean of the diodes' noise) stays."""
    sig = np.array([1e-4])
    out = {}
    for scale in (1.0, 2.0):
        spec = optical_spec(p4.load_robot("rx130l", scale))
        out[scale] = stated_sigmas(spec, np.ones((1, len(spec.probe_diodes_m)), bool), sig)
    assert np.isclose(out[2.0][0][0], out[1.0][0][0], rtol=1e-9)
    assert np.isclose(out[2.0][1][0], 0.5 * out[1.0][1][0], rtol=1e-9)
    scaled, fresh = optical_spec(p4.load_robot("rx130l", 2.0)), optical_spec(RobotModel.load("rx130l"))
    assert np.allclose(scaled.probe_diodes_m, 2.0 * fresh.probe_diodes_m)    # a later load is unchanged
