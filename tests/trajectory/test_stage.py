"""Stage ``trajectory`` on the quick profile (nominal dynamics, no upstream stages)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.core.errors import ConfigError
from pipeline.core.progress import Progress
from pipeline.sim.truth import RealRobot, TruthConfig
from pipeline.stage_api import StageContext, stage_rng
from pipeline.trajectory import report, stage

REQUIRED = ("cp_duration_s", "cp_toppra_duration_s", "cp_fine_violation", "cp_toppra_fine_violation_full_friction",
            "cp_smooth_duration_s", "ptp_duration_s", "ptp_ruckig_duration_s", "ptp_fine_violation",
            "ptp_energy_at_ruckig_duration_ratio", "ptp_solve_time_s", "cp_sim_max_torque_ratio",
            "cp_smooth_sim_max_torque_ratio", "ptp_sim_max_torque_ratio")


def test_stage_quick(quick_config, rx130l, ptp_problem, tmp_path):
    # 0.01 = the main solution's k2: reused as the Pareto point (no extra solve); the warm-started sweep
    # over k2 is plan_ptp's, checked on the big move by test_ptp.py (k2 = 0.01, 0.1, 1.0). Coarser CP grids
    # (IK samples, path grid, smooth intervals) than the quick profile's, whose CP plans test_cp.py checks
    cfg = dataclasses.replace(quick_config.trajectory, ptp_pareto_k2=[0.01], cp_ik_points=40, cp_n_grid=60,
                              cp_smooth_intervals=25)
    real = RealRobot.create(rx130l, quick_config.seed, TruthConfig())
    # planned on the NOMINAL model (no identification upstream), run on the hidden robot: the servo
    # simulation may exceed the limits; accept_poor records the gates instead of stopping
    run_cfg = dataclasses.replace(quick_config, accept_poor=True)
    ctx = StageContext(run=run_cfg, config=cfg, robot=rx130l.copy(), real=real, upstream={},
                       out_dir=tmp_path, rng=stage_rng(quick_config.seed, "trajectory"),
                       progress=Progress(enabled=False))
    res = stage.run(ctx)
    s = res.summary
    gates = {c["name"]: c for c in s["quality_gates"]["checks"]}
    # the plans themselves vouch for their limits on the fine grid and their solver statuses
    assert all(c["passed"] for n, c in gates.items() if "_sim_" not in n), gates
    assert {"cp_fine_violation", "ptp_fine_violation", "ptp_solver_status", "cp_smooth_solver_status",
            "cp_fine_max_acceleration_ratio"} <= set(gates)
    assert s["accepted_poor"] == (not s["quality_gates"]["passed"])
    assert res.data["solver_status"]["ptp"] == "Solve_Succeeded"
    for key in REQUIRED:
        assert key in s and s[key] is not None, key
    tol = cfg.violation_tolerance
    assert s["cp_fine_violation"] <= tol and s["ptp_fine_violation"] <= tol
    assert s["cp_toppra_fine_violation_full_friction"] >= s["cp_fine_violation"]
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
    # the PtP plans on the elastic truth: duration, settling time and move + settle of each, the
    # smooth variant one filter length longer
    for name in ("ptp", "ptp_smooth", "ptp_ruckig"):
        assert s[f"{name}_move_and_settle_s"] is None or np.isclose(
            s[f"{name}_move_and_settle_s"], s[f"{name}_settle_duration_s"] + s[f"{name}_settling_time_s"])
        assert f"| {name} |" in res.report_md
    # (slowed by ptp_smooth_time_scale >= 1 when needed to keep the limits on the fine grid and in the servo)
    scale = s["ptp_smooth_time_scale"]
    assert scale >= 1.0 and s["ptp_smooth_sim_max_averaged_torque_ratio"] <= 1.0
    assert abs(s["ptp_smooth_settle_duration_s"] - scale * (s["ptp_duration_s"] + s["ptp_smooth_filter_time_s"])) \
        < 2e-3 * scale
    assert "ptp_settling" in res.figures and "move + settle [s]" in res.report_md
    # the CP the elastic arm executes: a measured remedy, never shorter than the time-optimal plan
    assert s["cp_executed"] in ("time_optimal", "reserve", "smooth", "slowed")
    assert s["cp_executed_duration_s"] >= s["cp_duration_s"] * (1 - 1e-6)
    assert "Executable CP on the elastic arm" in res.report_md
    # a remedy is stored as a plan of its own (export writes it); the time-optimal plan is not stored twice
    executed = res.arrays.get("trajectory_cp_executed_t")
    assert (executed is None) == (s["cp_executed"] == "time_optimal")
    if executed is not None:
        assert executed[-1] - executed[0] == pytest.approx(s["cp_executed_duration_s"], rel=1e-9)
    assert s["ptp_smooth_sim_tcp_error_max_m"] is not None
    assert s["ptp_smooth_fine_violation"] <= tol and "ptp_smooth_fine_violation" in gates
    assert s["ptp_smooth_duration_s"] == s["ptp_smooth_settle_duration_s"]
    # one energy per motion: the fine-grid value in the summary and in the Pareto entry alike
    main = next(e for e in s["ptp_pareto"] if e["k2"] == cfg.ptp_k2)
    assert main["duration_s"] == s["ptp_nlp_duration_s"] and s["ptp_time_scale"] >= 1.0
    assert s["ptp_duration_s"] == pytest.approx(s["ptp_time_scale"] * s["ptp_nlp_duration_s"], rel=1e-6)
    if s["ptp_time_scale"] == 1.0:   # the plan handed on is the NLP's own
        assert main["energy"] == s["ptp_energy"]
    assert all(set(e) >= {"k2", "duration_s", "energy", "dominated"} for e in s["ptp_pareto"])
    # the report: violations in %, the Pareto sweep as a table, torques in N·m
    row = _report_row(res.report_md, "PtP fine-grid torque violation")
    assert row.rstrip(" |").endswith("%") and "fraction" in row
    assert f"{100 * s['ptp_fine_violation']:.3f} %" in row
    cp_row = _report_row(res.report_md, "CP fine-grid torque violation")
    assert cp_row.count("%") >= 3 and "fractions" in cp_row
    assert "| k2 | duration [s] | energy (normalised) [s] | dominated |" in res.report_md
    assert "N·m" in res.report_md


def _report_row(report: str, label_start: str) -> str:
    return next(line for line in report.splitlines() if line.startswith(f"| {label_start}"))


def test_report_units_and_pareto_table():
    """Violations as percentages (summary.json keeps fractions), the Pareto sweep as a small
    rounded table with the dominated flag, N·m for torques (from a summary, no solver run)."""
    summary = {"ptp_pareto": [
        {"k2": 0.003, "duration_s": 0.6291234567891234, "energy": 1.7601234567891234, "dominated": True,
         "cold_restart": "discarded"},
        {"k2": 0.01, "duration_s": 0.6281234567891234, "energy": 1.4161234567891234, "dominated": False,
         "cold_restart": None}]}
    table = report.pareto_table(summary["ptp_pareto"], "energy (normalised) [s]")
    lines = table.splitlines()
    assert "| k2 | duration [s] | energy (normalised) [s] | dominated |" in lines
    assert "| 0.003 | 0.6291 | 1.76 | yes (local optimum; cold re-solve: discarded) |" in lines
    assert "| 0.01 | 0.6281 | 1.416 | no |" in lines
    assert "1234567" not in table
    assert report.percent(0.002758) == "0.276 %" and report.percent(0.0) == "0.000 %"
    assert report.ENERGY_UNITS["torque"] == "N²·m²·s"


def test_check_names_bad_fields(quick_config, rx130l):
    base = quick_config.trajectory
    for field, value, match in (("cp_segment", "rectangle", "cp_segment"), ("ptp_energy", "joules", "ptp_energy"),
                                ("ptp_goal_deg", [0, 170, 0, 0, 0, 0], "joint 2"),
                                ("ruckig_check_dt_s", 1e-3, "0.5 ms"), ("ptp_start_deg", [0.0] * 5, "6 numbers")):
        with pytest.raises(ConfigError, match=match):
            stage.check(dataclasses.replace(base, **{field: value}), rx130l)
    stage.check(base, rx130l)
