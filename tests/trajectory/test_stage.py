"""Stage ``trajectory`` on the quick profile (nominal dynamics, no upstream stages)."""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.progress import Progress
from pipeline.robot.truth import RealRobot, TruthConfig
from pipeline.runner import StageContext, stage_rng
from pipeline.trajectory import stage

REQUIRED = ("cp_duration_s", "cp_toppra_duration_s", "cp_fine_violation", "cp_toppra_fine_violation_full_friction",
            "cp_smooth_duration_s", "ptp_duration_s", "ptp_ruckig_duration_s", "ptp_fine_violation",
            "ptp_energy_at_ruckig_duration_ratio", "ptp_solve_time_s", "cp_sim_max_torque_ratio",
            "cp_smooth_sim_max_torque_ratio", "ptp_sim_max_torque_ratio")


def test_stage_quick(quick_config, rx130l, ptp_problem, tmp_path):
    cfg = dataclasses.replace(quick_config.trajectory, ptp_pareto_k2=[0.1])
    real = RealRobot.create(rx130l, quick_config.seed, TruthConfig())
    ctx = StageContext(run=quick_config, config=cfg, robot=rx130l.copy(), real=real, upstream={},
                       out_dir=tmp_path, rng=stage_rng(quick_config.seed, "trajectory"),
                       progress=Progress(enabled=False))
    res = stage.run(ctx)
    s = res.summary
    for key in REQUIRED:
        assert key in s and s[key] is not None, key
    tol = cfg.violation_tolerance
    assert s["cp_fine_violation"] <= tol and s["ptp_fine_violation"] <= tol
    assert s["cp_toppra_fine_violation_full_friction"] > s["cp_fine_violation"]
    assert s["ptp_duration_s"] < s["ptp_ruckig_duration_s"]
    assert s["cp_smooth_duration_s"] >= s["cp_duration_s"] * (1 - 1e-6)
    # the simulation executed each trajectory for its planned duration
    assert abs(s["cp_sim_duration_s"] - s["cp_duration_s"]) < 2e-3
    assert abs(s["ptp_sim_duration_s"] - s["ptp_duration_s"]) < 2e-3
    for name in ("cp", "ptp"):
        t, q = res.arrays[f"trajectory_{name}_t"], res.arrays[f"trajectory_{name}_q"]
        assert q.shape == (len(t), 6) and np.all(np.diff(t) > 0)
    assert {"cp_normalised", "ptp_normalised", "ptp_pareto"} <= set(res.figures)
    assert "toppra" in res.report_md


def test_check_names_bad_fields(quick_config, rx130l):
    import pytest

    from pipeline.errors import ConfigError

    base = quick_config.trajectory
    for field, value, match in (("cp_segment", "rectangle", "cp_segment"), ("ptp_energy", "joules", "ptp_energy"),
                                ("ptp_goal_deg", [0, 170, 0, 0, 0, 0], "joint 2"),
                                ("ruckig_check_dt_s", 1e-3, "0.5 ms"), ("ptp_start_deg", [0.0] * 5, "6 numbers")):
        with pytest.raises(ConfigError, match=match):
            stage.check(dataclasses.replace(base, **{field: value}), rx130l)
    stage.check(base, rx130l)
