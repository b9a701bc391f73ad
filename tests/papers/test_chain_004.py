"""Study paper-004 (paper 004 §2.3.3, §4, §5 through the whole pipeline).

Fast: the paper's settings in configs/paper004.yaml and the study's experiment configs. Slow
(``pytest -m slow``, about 5 min on the shared box): the ``--quick`` study and the properties
the paper states (feedforward reduces the lag and, on the rigid robot, the TCP error; torque
match within the noise; a limit active along the CP; a monotone time/energy front).
"""

from __future__ import annotations

import math

import pytest

from pipeline.core.config import load_config
from pipeline.papers import chain_004 as study
from pipeline.papers import chain_004_rows as rows_mod
from pipeline.papers import chain_004_stiffness as stiff
from pipeline.papers.registry import resolve
from pipeline.sim.truth import TruthConfig

HEADLINES = {"iso_settings", "excitation_tcp", "fig2a_lag", "fig2b_tcp", "fig5_torques", "fig8_cp_active",
             "ptp_tradeoff", "executed"}


def _get(cfg, dotted: str):
    node = cfg
    for part in dotted.split("."):
        node = getattr(node, part)
    return node


def test_config_file_holds_the_paper_settings():
    cfg = load_config(study.FULL_CONFIG)
    for key, value in study.PAPER_SETTINGS.items():
        assert _get(cfg, key) == value, key
    assert resolve("paper-004") is study.study_paper_004


def test_experiment_configs():
    main = study.chain_config(1, quick=True)
    rigid = study.chain_config(1, quick=True, variant="rigid")
    acc = study.chain_config(1, quick=True, variant="acceleration_limits", accept_poor=True)
    full = study.chain_config(1, quick=True, variant="full_torque")
    assert len({main.name, rigid.name, acc.name, full.name}) == 4
    assert full.identification.excitation.torque_margin == 1.0 > main.identification.excitation.torque_margin
    assert full.stages == list(study.EXCITATION_STAGES)
    assert rigid.stages == list(study.RIGID_STAGES) and "trajectory" in main.stages
    assert rigid.truth == TruthConfig.ideal() and main.truth == TruthConfig()
    assert acc.trajectory.acceleration_limits and not main.trajectory.acceleration_limits
    assert acc.accept_poor and not main.accept_poor
    # the quick study keeps the paper's settings
    for key, value in study.PAPER_SETTINGS.items():
        assert _get(main, key) == value, key
    with pytest.raises(ValueError):
        study.chain_config(1, quick=True, variant="other")


def test_stiffness_configs_scale_only_the_joint_compliance():
    """The Fig. 2(b) stiffness runs: the quick chain up to control with the paper's settings, the
    default hidden robot except its joint compliance, one run name per (scale, seed)."""
    settings = {**study.PAPER_SETTINGS, **study.QUICK_SETTINGS}
    a = stiff.stiffness_config(1, 0.1, study.QUICK_CONFIG, settings)
    b = stiff.stiffness_config(1, 1.0, study.QUICK_CONFIG, settings)
    assert a.truth.joint_compliance_scale == 0.1 and b.truth == TruthConfig()
    assert a.name != b.name and a.stages == list(stiff.STIFFNESS_STAGES)
    for key, value in study.PAPER_SETTINGS.items():
        assert _get(a, key) == value, key


def test_largest_drastic_scale_needs_every_seed():
    pts = [{"compliance_scale": s, "seed": k, "tcp_reduction": r}
           for s, k, r in ((1.0, 1, 1.0), (0.1, 1, 3.0), (0.1, 2, 1.5), (0.01, 1, 9.0), (0.01, 2, 8.0))]
    assert stiff.largest_drastic_scale(pts) == 0.01
    assert stiff.largest_drastic_scale(pts[:1]) is None


def test_stat_formats_one_and_many_seeds():
    assert rows_mod.stat([2.0]) == "2"
    assert "±" in rows_mod.stat([1.0, 2.0, 3.0]) and "n=3" in rows_mod.stat([1.0, 2.0, 3.0])


@pytest.mark.slow
def test_quick_study_properties(tmp_path):
    rows, timings = study.run_study([1], quick=True, out=tmp_path, say=lambda m: None)
    by = {r.key: r for r in rows}
    assert HEADLINES <= set(by)
    for r in rows:
        assert r.paper and r.ours and r.verdict
    # §4.3: the excitation stays within the paper's TCP speed and acceleration
    v = by["excitation_tcp"].values
    assert max(v["tcp_speed_max_m_s"]) <= rows_mod.PAPER_TCP_SPEED_M_S * 1.001
    assert max(v["tcp_acceleration_max_m_s2"]) <= rows_mod.PAPER_TCP_ACCELERATION_M_S2 * 1.001
    # Fig. 2: feedforward reduces the lag of axes 1-3 and, on the rigid robot, the TCP error
    for j in (1, 2, 3):
        assert min(by["fig2a_lag"].values[f"lag_reduction_axis{j}"]) > 1.0
    assert min(by["fig2b_tcp"].values["tcp_reduction_rigid"]) > 1.0
    assert min(by["fig2b_tcp"].values["tcp_tracking_reduction_elastic_static"]) > 1.0
    # Fig. 5: measured vs predicted torques within the identification gate
    assert max(by["fig5_torques"].values["rms_over_noise_worst"]) <= rows_mod.TORQUE_MATCH_OVER_NOISE
    # Fig. 8: a torque or speed limit active at >= 99 % of the CP grid points
    assert min(by["fig8_cp_active"].values["grid_active_fraction"]) >= rows_mod.ACTIVE_GRID_FRACTION
    # PtP: raising k2 costs time and saves energy
    assert min(by["ptp_tradeoff"].values["energy_decrease"]) > 0
    assert min(by["ptp_tradeoff"].values["time_increase"]) >= 0
    # the jerk-limited plans need less torque in the servo than the unsmoothed optimum
    ex = by["executed"].values
    assert max(ex["cp_smooth_torque_ratio"]) < max(ex["cp_torque_ratio"])
    assert max(ex["ptp_smooth_torque_ratio"]) < max(ex["ptp_torque_ratio"])
    assert all(math.isfinite(t) for t in timings.values())
    assert set(timings) >= {"main_s", "rigid_s", "acceleration_limits_s", "full_torque_s"}
    # --report: the same table from the stored runs
    again = study.stored_rows([1], quick=True, out=tmp_path)
    assert [(r.key, r.ours, r.verdict) for r in again] == [(r.key, r.ours, r.verdict) for r in rows]
