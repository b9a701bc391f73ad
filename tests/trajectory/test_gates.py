"""Quality gates of the trajectory stage: limits on the fine grid and in the simulation, IPOPT status."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.core.errors import QualityGateError
from pipeline.stage_api import StageResult
from pipeline.trajectory import validate
from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.trajectories import TorqueCheck
from pipeline.trajectory.validate import ServoRun, quality_gates


def _check(violation: float = 0.0, v: float = 0.9, a: float = 0.9) -> TorqueCheck:
    z = np.zeros((2, 6))
    return TorqueCheck(np.zeros(2), z, z, z, 1.0 + violation, violation, v, 0.0, a)


def _run(averaged_ratio: float) -> ServoRun:
    """A servo run whose 4 ms mean command is ``averaged_ratio`` x the torque limits."""
    per_joint = np.full(6, averaged_ratio)
    return ServoRun(duration_s=1.0, max_torque_ratio=averaged_ratio, max_torque_ratio_per_joint=per_joint,
                    max_feedforward_ratio=averaged_ratio, max_averaged_torque_ratio=averaged_ratio,
                    max_averaged_torque_ratio_per_joint=per_joint, average_window_s=4e-3,
                    feedback_std_ratio_per_joint=np.zeros(6), feedback_max_ratio_per_joint=np.zeros(6),
                    lag_error_max_rad=0.0, realtime_factor=1.0)


def _plans(cp_check: TorqueCheck | None = None, ptp_status: str = "Solve_Succeeded"):
    ok = {"solver_status": "Solve_Succeeded"}
    cp = SimpleNamespace(checks={"cp": cp_check or _check()}, smooth=None,
                         optimal=SimpleNamespace(info={"method": "reachability"}))
    ptp = SimpleNamespace(checks={"ptp": _check(), "ptp_energy_at_ruckig_duration": _check()},
                          result=SimpleNamespace(info={"solver_status": ptp_status}),
                          at_ruckig_duration=SimpleNamespace(info=ok),
                          at_ruckig_duration_status=lambda: ok["solver_status"])
    return cp, ptp


def _finish(gates):
    return gates.finish(StageResult(summary={}))


def _gate_names(result) -> set[str]:
    return {c["name"] for c in result.summary["quality_gates"]["checks"]}


def test_good_plans_pass():
    cp, ptp = _plans()
    res = _finish(quality_gates(TrajectoryConfig(), cp, ptp, {"cp": _run(0.95)}))
    assert res.summary["quality_gates"]["passed"]


@pytest.mark.parametrize("case, figure", [
    ({"cp_check": _check(violation=0.02)}, "cp_fine_violation"),
    ({"cp_check": _check(a=1.2)}, "cp_fine_max_acceleration_ratio"),
    ({"cp_check": _check(v=1.1)}, "cp_fine_max_velocity_ratio"),
    ({"ptp_status": "Maximum_Iterations_Exceeded"}, "ptp_solver_status"),
])
def test_a_violated_limit_or_failed_solve_fails_the_stage(case, figure):
    cp, ptp = _plans(**case)
    with pytest.raises(QualityGateError, match=figure):
        _finish(quality_gates(TrajectoryConfig(), cp, ptp, {}))
    # --accept-poor: handed on, recorded
    res = _finish(quality_gates(TrajectoryConfig(), cp, ptp, {}, accept_poor=True))
    assert res.summary["accepted_poor"] and not res.summary["quality_gates"]["passed"]


def test_simulation_over_the_limit_fails():
    cp, ptp = _plans()
    sims = {"cp": _run(1.2), "ptp_ruckig": _run(5.0)}
    with pytest.raises(QualityGateError, match="cp_sim_max_averaged_torque_ratio") as err:
        _finish(quality_gates(TrajectoryConfig(), cp, ptp, sims))
    assert "ptp_ruckig" not in str(err.value)          # the baseline is not gated


def test_acceleration_gate_follows_the_switch():
    cp, ptp = _plans(cp_check=_check(a=1.5))
    res = _finish(quality_gates(TrajectoryConfig(acceleration_limits=False), cp, ptp, {}))
    assert res.summary["quality_gates"]["passed"]


def test_on_an_elastic_plant_the_smooth_ptp_is_gated_not_the_time_optimal_one():
    cp, ptp = _plans()
    sims = {"ptp": _run(17.0), "ptp_smooth": _run(0.9)}
    with pytest.raises(QualityGateError, match="ptp_sim_max_averaged_torque_ratio"):
        _finish(quality_gates(TrajectoryConfig(), cp, ptp, sims))          # rigid plant: the plan must run
    assert _finish(quality_gates(TrajectoryConfig(), cp, ptp, sims, elastic_plant=True)).summary[
        "quality_gates"]["passed"]
    sims["ptp_smooth"] = _run(1.2)
    with pytest.raises(QualityGateError, match="ptp_smooth_sim_max_averaged_torque_ratio"):
        _finish(quality_gates(TrajectoryConfig(), cp, ptp, sims, elastic_plant=True))


def test_torque_limited_cp_on_an_elastic_plant_gates_the_executed_cp():
    cp, ptp = _plans()
    cp.checks["cp_executed"] = _check()
    sims = {"cp": _run(2.1), "cp_smooth": _run(1.3),
            "cp_executed": _run(0.99)}
    torque_limited = TrajectoryConfig(acceleration_limits=False)
    # under acceleration limits too: the time-optimal CP over the gate, the executed remedy is vouched for
    passed = _finish(quality_gates(TrajectoryConfig(), cp, ptp, sims, elastic_plant=True))
    assert "cp_executed_fine_max_acceleration_ratio" in _gate_names(passed)
    assert "cp_sim_max_averaged_torque_ratio" not in _gate_names(passed)
    # ... and the time-optimal CP within it is the one gated (it is the one executed)
    within = {"cp": _run(0.95), "cp_executed": _run(0.95)}
    names = _gate_names(_finish(quality_gates(TrajectoryConfig(), cp, ptp, within, elastic_plant=True)))
    assert "cp_sim_max_averaged_torque_ratio" in names and "cp_executed_fine_violation" not in names
    assert _finish(quality_gates(torque_limited, cp, ptp, sims, elastic_plant=True)).summary[
        "quality_gates"]["passed"]
    sims["cp_executed"] = _run(1.05)
    with pytest.raises(QualityGateError, match="cp_executed_sim_max_averaged_torque_ratio"):
        _finish(quality_gates(torque_limited, cp, ptp, sims, elastic_plant=True))
    sims["cp_executed"] = _run(0.99)
    cp.checks["cp_executed"] = _check(violation=0.02)
    with pytest.raises(QualityGateError, match="cp_executed_fine_violation"):
        _finish(quality_gates(torque_limited, cp, ptp, sims, elastic_plant=True))


def test_a_run_is_diverged_at_its_first_non_finite_or_runaway_sample():
    """Finite but further off the reference than the joint's range (one turn at most) is diverged too."""
    t = np.arange(6) * 4e-4
    q_d = np.zeros((6, 2))
    q, v, tau = q_d.copy(), np.zeros((6, 2)), np.zeros((6, 2))
    span = np.array([0.5, 2 * np.pi])
    assert validate.first_divergence_s(t, q, v, tau, q_d, span) is None
    q[3:, 1] = [3.0, 30.0, 3e30]                  # finite, growing: off by more than a turn from sample 4
    assert validate.first_divergence_s(t, q, v, tau, q_d, span) == pytest.approx(t[4])
    q[2, 0] = 0.6                                 # beyond joint 1's 0.5 rad range at sample 2
    assert validate.first_divergence_s(t, q, v, tau, q_d, span) == pytest.approx(t[2])
    tau[1, 1] = np.nan
    assert validate.first_divergence_s(t, q, v, tau, q_d, span) == pytest.approx(t[1])


def _diverged(at_s: float) -> ServoRun:
    """A servo run that left the finite numbers at ``at_s``: its ratios are NaN."""
    return replace(_run(float("nan")), diverged_at_s=at_s)


def test_a_diverged_servo_simulation_fails_naming_the_plan_not_a_nan_ratio():
    cp, ptp = _plans()
    sims = {"ptp": _run(0.9), "ptp_smooth": _diverged(0.0032)}
    with pytest.raises(QualityGateError) as err:
        _finish(quality_gates(TrajectoryConfig(), cp, ptp, sims, elastic_plant=True))
    text = str(err.value)
    assert "ptp_smooth_sim_diverged" in text and "plan ptp_smooth diverged at t = 0.0032 s" in text
    assert "nan" not in text.lower()
    # a reported (not vouched for) plan that diverged fails too: its figures are no measurement
    sims = {"ptp": _run(0.9), "ptp_smooth": _run(0.9), "ptp_ruckig": _diverged(0.5)}
    res = _finish(quality_gates(TrajectoryConfig(), cp, ptp, sims, elastic_plant=True, accept_poor=True))
    failed = [c["name"] for c in res.summary["quality_gates"]["checks"] if not c["passed"]]
    assert failed == ["ptp_ruckig_sim_diverged"]


def test_simulate_on_real_names_the_first_non_finite_sample(monkeypatch):
    n, dt = 50, 4e-4
    t = dt * np.arange(n)
    q = np.zeros((n, 6))
    tau = np.ones((n, 6))
    tau[20:, 3] = np.nan                            # the command turns NaN first, then the state
    q[21:] = np.nan
    res = SimpleNamespace(t_s=t, q=q, q_d=np.zeros((n, 6)), v=np.zeros((n, 6)), tau_cmd=tau,
                          tau_ff=np.ones((n, 6)), max_torque_ratio=np.full(6, np.inf), lag_error_rad=q,
                          realtime_factor=1.0, tcp_position_m=None)
    monkeypatch.setattr(validate, "simulate_joint_trajectory", lambda *args, **kwargs: res)
    robot = SimpleNamespace(limits=SimpleNamespace(effort_Nm=np.full(6, 10.0), lower_rad=np.full(6, -3.0),
                                                   upper_rad=np.full(6, 3.0)))
    traj = SimpleNamespace(t_s=t, q=q, v=q, a=q)
    run = validate.simulate_on_real(None, robot, traj)
    assert run.diverged and run.diverged_at_s == pytest.approx(20 * dt)
    res.tau_cmd = np.ones((n, 6))
    res.q = np.zeros((n, 6))
    res.lag_error_rad = res.q
    assert not validate.simulate_on_real(None, robot, traj).diverged
    res.q[30:, 2] = 7.0                             # finite, but more than a turn off its reference
    assert validate.simulate_on_real(None, robot, traj).diverged_at_s == pytest.approx(30 * dt)
