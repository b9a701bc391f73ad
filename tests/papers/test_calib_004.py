"""Quick variant of study calib-004 (paper 004 §3 with its optical 6-D tracker): properties that must hold."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.papers import calib_004 as p4
from pipeline.papers import calib_004_optical as op
from pipeline.robot.instruments import OpticalMargins
from pipeline.robot.model import RobotModel

MARGINS = OpticalMargins(np.radians(1.0), 0.05, 0.01)


@pytest.fixture(scope="module")
def quick() -> tuple[dict, dict]:
    grid = p4.visible_grid("rx130l", 7, MARGINS)
    row = p4._seed(("rx130l", 1, "ideal", grid, 32, 60, ["O3"], MARGINS, "registered", 1.0, None))
    return grid, row


def test_candidates_are_the_visible_grid(quick):
    """Candidates are visible grid configurations (nominal model, with margins): a subset of the
    configurations the cameras see without margins, never one they cannot see."""
    grid, row = quick
    robot = RobotModel.load("rx130l")
    assert 32 <= row["n_candidates"] <= grid["n_visible"] < grid["counts"]["total"]
    assert op.visible_mask(robot, grid["Q"]).all()
    assert np.all(np.diff(grid["flat"]) > 0)          # grid order (the grid-order scan relies on it)


def test_headline_keys_and_the_papers_index(quick):
    _, row = quick
    d = row["designs"]
    for key in ("rr_O3", *p4.BASELINES):
        assert {"B", "O3", "cond", "commanded", "predicted_visible", "lost_on_hidden_robot"} <= d[key].keys()
        assert np.isclose(d[key]["B"], d[key]["O3"] ** 2)      # B = sigma_min(Theta^T Theta) = O3^2
        assert d[key]["predicted_visible"] <= d[key]["commanded"]
        assert 0 <= d[key]["lost_on_hidden_robot"] <= d[key]["predicted_visible"]
    # remove-and-replace on O3 is at least as good as any scan of the same visible candidates
    for key in ("grid_order", "random"):
        assert d["rr_O3"]["B"] >= d[key]["B"]
        assert d[key]["predicted_visible"] == d[key]["commanded"] == 32
    assert d["rr_O3"]["predicted_visible"] == 32


def test_calibration_reduces_the_held_out_errors(quick):
    """On the ideal hidden robot the 6-D calibration from the R&R design reduces the held-out
    position and orientation errors (Table 2 layout keys present)."""
    _, row = quick
    r = row["designs"]["rr_O3"]
    assert r["calibrated"]
    for ax in ("x", "y", "z", "alpha", "beta", "gamma"):
        assert {"max_abs", "half_peak_to_peak"} <= r["after"][ax].keys()
    assert r["after"]["position"]["rms"] < 0.5 * r["before"]["position"]["rms"]
    assert r["after"]["orientation"]["rms"] < r["before"]["orientation"]["rms"]
