"""The experiments behind the causes docs/PAPERS.md gives, read from their committed outputs in
docs/papers/results/ (fast: JSON only), and rerun on a quick variant where the cause is a property
of the code rather than of one committed run (slow). Each test asserts the property a verdict rests
on, so a rerun that no longer shows it fails here; the printed numbers are checked by
test_papers_evidence.py.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from pipeline.papers import calib_004 as p4
from pipeline.papers.chain_004_rows import CLEAR_REDUCTION
from pipeline.robot.instruments import OpticalMargins

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "papers" / "results"


def result(folder: str) -> dict:
    return json.loads((RESULTS / folder / "results.json").read_text(encoding="utf-8"))["result"]


def test_stiffer_joints_let_the_rigid_feedforward_cut_the_tcp_error():
    """Fig. 2(b): the rigid-body feedforward's cut of the max TCP error grows as the hidden
    RX130L's joints get stiffer; it is not "drastic" with the generic stiffness (S = 33) and is with
    the stiffness fitted into the RX130L's robot.yaml (S = 1) and the stiffest run."""
    points = sorted(result("paper-004-stiffness")["points"], key=lambda p: -p["compliance_scale"])
    cut = [p["tcp_reduction"] for p in points]
    assert points[0]["compliance_scale"] == 33.0 and cut[0] < CLEAR_REDUCTION <= cut[-1]
    assert all(p["tcp_reduction"] >= CLEAR_REDUCTION for p in points if p["compliance_scale"] == 1.0)
    # 10x the rule's stiffness (S = 3.3) is not yet enough: the cut passes 2x between 10x and 33x
    assert all(p["tcp_reduction"] < CLEAR_REDUCTION for p in points if p["compliance_scale"] == 3.3)
    assert any(p["compliance_scale"] == 1.0 for p in points)
    assert all(b >= a for a, b in zip(cut, cut[1:], strict=False))
    # without feedforward the error falls towards the rigid robot's as the deflection shrinks
    none = [p["tcp_error_max_none_m"] for p in points]
    assert none[-1] < 0.25 * none[0]


def table2_after_mm(folder: str) -> np.ndarray:
    after = result(folder)["rows"][0]["designs"]["rr_O3"]["after"]
    return 1e3 * np.array([after[ax]["max_abs"] for ax in ("x", "y", "z")])


def test_table2_positions_hold_with_a_geometric_model_once_the_joints_are_stiff():
    """Table 2's maxima after calibration (0.272 / 0.310 / 0.414 mm) hold with a purely geometric
    model on the hidden RX130L with its stated stiffness (S = 1) and with joints 10x stiffer than the
    generic rule (S = 3.3), not with the rule itself (S = 33) or 3.3x it (S = 10)."""
    paper = np.array([0.272, 0.310, 0.414])
    for folder in ("calib-004-stiffness-33", "calib-004-stiffness-10"):
        assert table2_after_mm(folder)[2] > paper[2], folder          # ez: the gravity deflection's axis
    for folder in ("calib-004-stiffness-3.3", "calib-004-stiffness-1"):
        assert np.all(table2_after_mm(folder) <= paper), folder


def cardan_after_deg(folder: str) -> np.ndarray:
    after = result(folder)["rows"][0]["designs"]["rr_O3"]["after"]
    return np.degrees([after[ax]["max_abs"] for ax in ("alpha", "beta", "gamma")])


def cardan_before_deg(folder: str) -> np.ndarray:
    before = result(folder)["rows"][0]["designs"]["rr_O3"]["before"]
    return np.degrees([before[ax]["max_abs"] for ax in ("alpha", "beta", "gamma")])


def test_the_cardan_errors_are_the_readings_noise_before_and_after_calibration():
    """On the rigid hidden robot the held-out Cardan errors are the orientation readings' noise: with
    the default probe calibration leaves them where they were (after within 10 % of before, on
    average), and a probe twice as large (stated orientation noise halved) lowers both and lets
    calibration cut the maxima on every axis; position is cut far more in both."""
    base, probe = result("calib-004-grid7-ideal"), result("calib-004-probe-2")
    assert math.isclose(probe["rows"][0]["sigma_rad"] / base["rows"][0]["sigma_rad"], 0.5, rel_tol=0.05)
    default_gain = cardan_before_deg("calib-004-grid7-ideal") / cardan_after_deg("calib-004-grid7-ideal")
    probe_gain = cardan_before_deg("calib-004-probe-2") / cardan_after_deg("calib-004-probe-2")
    assert abs(default_gain.mean() - 1) < 0.1
    assert np.all(probe_gain > 1) and probe_gain.mean() > default_gain.mean()
    assert cardan_after_deg("calib-004-probe-2").mean() < 0.7 * cardan_after_deg("calib-004-grid7-ideal").mean()
    assert np.all(table2_after_mm("calib-004-grid7-ideal") < 0.2 * np.array(
        [1e3 * result("calib-004-grid7-ideal")["rows"][0]["designs"]["rr_O3"]["before"][ax]["max_abs"]
         for ax in ("x", "y", "z")]))


def test_the_whole_visible_grid_is_no_reading_of_the_factor_18_5():
    """The whole visible 13^6 grid measured: per measured pose R&R is within a factor 2 of it, far from
    the paper's 18.5. (Its B exceeding R&R's holds for any information that adds up: not a finding.)"""
    res = result("calib-004-whole-grid")
    d = res["rows"][0]["designs"]
    assert res["grid"]["n_visible"] > 3000 and d["whole_grid"]["commanded"] > 2000
    assert 0.5 < res["factors_B_per_pose"]["whole_grid"][0] < 2.0


def test_selection_matters_only_at_the_smallest_size():
    """Paper 003's searches on the literal (model-consistent) UR10: the error is the tracker-noise
    floor at every size; at the smallest size the best search lowers it beyond its seed spread, from
    the next size on no search changes it by 5 %; Oc is no better than O1, BSAA no better than DETMAX."""
    res = result("calib-003-sizes")
    table, sizes = res["table_sizes"], res["args"]["sizes"]
    noise_mean_um = 10.0 / math.sqrt(3) * 2 * math.sqrt(2 / math.pi)     # mean |n| of 3-D N(0, σ²): σ·2√(2/π)
    for n in sizes:
        none = table[str(n)]["none"]
        assert noise_mean_um < none["mean_um"][0] < 1.5 * noise_mean_um
        assert none["model_um"][0] < none["mean_um"][0]
    small = table[str(sizes[0])]
    best = min(small[k]["paired_mean_um"][0] for k in small if k != "none")
    assert any(v["paired_mean_um"][0] == best and best < -3 * v["paired_mean_um"][1] for v in small.values())
    for n in sizes[1:]:
        for key, v in table[str(n)].items():
            assert abs(v["paired_mean_um"][0]) < 0.05 * table[str(n)]["none"]["mean_um"][0], (n, key)
    for a, b in (("detmax_Oc", "detmax_O1"), ("bsaa_Oc", "detmax_Oc")):
        da, db = small[a]["paired_mean_um"], small[b]["paired_mean_um"]
        assert da[0] > db[0] - 2 * math.hypot(da[1], db[1]), (a, b)


def test_no_search_beats_random_poses_at_500_of_583():
    """Paper 003 at the real experiment's sizes (full variant): with the unmodelled compliance and
    gear error no search lowers the mean error below random poses beyond two standard errors, and on
    the literal truth every search is within 0.1 µm of them (the noise floor)."""
    res = result("calib-003-full")
    assert res["args"]["select"] == 500 and res["args"]["pool"] == 583 and res["args"]["seeds"] >= 10
    for key, v in res["table_realistic"].items():
        if key != "uncalibrated":
            assert v["paired_diff"][0] >= -2 * v["paired_diff"][1], key
    for key, v in res["table_literal"].items():
        if key != "uncalibrated":
            assert abs(v["paired_diff"][0]) < 0.1, key              # µm


def test_tcp_criterion_beats_random_and_parameter_designs_on_every_arm():
    """Paper 000 at full sizes: on each KUKA arm the C_s (TCP) design has a smaller mean TCP variance
    than the random and every C_p design, and over the 90 notional arms its mean gain over random
    exceeds five standard errors."""
    res = result("calib-000-full")
    assert [a["arm"] for a in res["kuka"]] == ["kuka_kr15", "kuka_kr300", "kuka_kr500"]
    for arm in res["kuka"]:
        cs = arm["tcp_ca"]["tcp_var"]
        assert cs < arm["random"], arm["arm"]
        for p in ("param_literal_ca", "param_scaled_ca", "param_legacy_ca"):
            assert cs < arm[p]["tcp_var"], (arm["arm"], p)
    gain = res["headline"]["notional.tcp_vs_heuristic"]["ours_ca_vs_random_var"]
    assert gain["n"] == 90 and gain["mean"] > 5 * gain["sem"] > 0


def _cardan_gain(probe_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """calib-004 rerun on a quick variant (the 7^6 grid, rigid hidden robot, seed 1, O3, 60 held-out
    poses) with the probe scaled: the Cardan and position maxima's cut by calibration (before / after)."""
    margins = OpticalMargins(np.radians(1.0), 0.05, 0.01)
    grid = p4.visible_grid("rx130l", 7, margins, probe_scale)
    row = p4._seed(("rx130l", 1, "ideal", grid, 32, 60, ["O3"], margins, "registered", 1.0, None, probe_scale,
                    False))
    d = row["designs"]["rr_O3"]
    cut = [d["before"][ax]["max_abs"] / d["after"][ax]["max_abs"] for ax in ("alpha", "beta", "gamma", "x", "y", "z")]
    return np.array(cut[:3]), np.array(cut[3:])


@pytest.mark.slow
def test_rerun_calibration_leaves_the_cardan_errors_at_the_reading_noise():
    """The physics of the Table 2 gain row, rerun: calibration cuts the position maxima severalfold
    with either probe, and leaves the Cardan maxima within 15 % of where they were before, with the
    default probe and with one twice as large (orientation noise halved): the orientation errors the
    geometric model removes are below even the halved reading noise."""
    for scale in (1.0, 2.0):
        cardan, position = _cardan_gain(scale)
        assert np.all(position > 3), scale
        assert np.all(np.abs(cardan - 1) < 0.15), (scale, cardan)
