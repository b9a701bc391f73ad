"""The CP the arm executes: a torque-limited plan that keeps the limits in the servo simulation.

Time-optimal under torque limits only (``acceleration_limits: false``, paper 004 §5) the CP switches
its torques between the limits from one grid interval to the next. On the hidden robot's elastic
joints each switch rings the gear spring and the drives' feedback rides on top of the planned
torques: the command averaged over 4 ms exceeds the limits (``cp_sim_max_averaged_torque_ratio``).
Three remedies, each measured in the servo simulation and priced in time against the pure
time-optimal plan (``T / T_opt - 1``):

``reserve``     the time-optimal profile re-solved (reachability, full friction) with the limits of
                the joints whose 4 ms mean ratio ``r_j`` exceeds the gate lowered,
                ``scale_j = 1 / (1 + x (r_j - 1))``; the plan stays time-optimal under them;
``smooth``      the jerk-limited CP (``cp_smooth``: continuous jerk, paper 004 §5) slowed in time,
                ``t' = (1 + x) t`` (inertial torques scale with ``1 / (1 + x)^2``);
``slowed``      the time-optimal CP slowed in time the same way.

Each remedy's strength ``x`` is the smallest that keeps the gate, found by regula falsi on the
measured ratio (:func:`to_gate`, a few servo runs of ~1 s each).

The executed CP is the shortest candidate whose servo simulation keeps the gate (the time-optimal
plan itself when it does; the remedies are then not run, the smooth CP is still measured); the pure
time-optimal plan is reported beside it (``cp_sim_*``), as the time-optimal PtP is on an elastic
plant. A remedy is stored beside the plans (``trajectory_cp_executed``), so ``python -m pipeline
export`` writes the motion the servo simulation vouched for. Every figure here is simulated (the
hidden robot of the run).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.control.config import ControlConfig
from pipeline.core.errors import InfeasibleError, SolverError
from pipeline.robot.model import RobotModel
from pipeline.stage_api import RealRobot
from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.cp import CPProfile
from pipeline.trajectory.design import JointPath
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.reachability import solve_cp_reachability
from pipeline.trajectory.settling import time_scaled
from pipeline.trajectory.solve import CPPlan
from pipeline.trajectory.trajectories import JointTrajectory, TorqueCheck, check_trajectory
from pipeline.trajectory.validate import ServoRun, simulate_on_real

#: servo runs per remedy (slowing or re-solving) before it is given up
SERVO_ROUNDS = 6
#: a remedy is strong enough once its ratio is within [GATE_AIM, 1] x the gate (regula falsi aims here)
GATE_AIM = 0.97
#: the reserve remedy keeps each joint's limit at least this many times the torque that holds the path
#: at rest: at exactly that torque the path can only be crawled, and the re-solve has no motion
RESERVE_HOLDING_MARGIN = 1.1


@dataclass
class ExecutableCP:
    """The executed CP (``name`` among ``candidates``), its servo simulation and every candidate's price."""

    name: str
    trajectory: JointTrajectory
    sim: ServoRun
    candidates: dict[str, dict] = field(default_factory=dict)
    #: remedies that could not be planned, and why (one line each)
    unavailable: dict[str, str] = field(default_factory=dict)

    def summary(self, optimal_duration_s: float) -> dict:
        s: dict[str, Any] = {"cp_executed": self.name, "cp_executed_duration_s": self.trajectory.duration_s,
                             "cp_executed_time_cost": self.trajectory.duration_s / optimal_duration_s - 1.0}
        for name, c in self.candidates.items():
            s[f"cp_executable_{name}_duration_s"] = c["duration_s"]
            s[f"cp_executable_{name}_time_cost"] = c["duration_s"] / optimal_duration_s - 1.0
            s[f"cp_executable_{name}_sim_max_averaged_torque_ratio"] = c["max_averaged_torque_ratio"]
        for name, why in self.unavailable.items():
            s[f"cp_executable_{name}_unavailable"] = why
        return s

    def table(self, optimal_duration_s: float, gate: float) -> str:
        lines = ["Executable CP on the elastic arm (servo simulation of the hidden robot, 4 ms mean command "
                 f"within {gate:g} x the torque limits); price in time against the time-optimal plan "
                 f"({optimal_duration_s:.4f} s):", "",
                 "| remedy | duration [s] | time cost | 4 ms mean torque ratio | servo rounds | executed |",
                 "|---|---|---|---|---|---|"]
        for name, c in self.candidates.items():
            lines.append(f"| {name} ({c['what']}) | {c['duration_s']:.4f} | "
                         f"{100 * (c['duration_s'] / optimal_duration_s - 1):.1f} % | "
                         f"{c['max_averaged_torque_ratio']:.3f} | {c['rounds']} | "
                         f"{'yes' if name == self.name else '-'} |")
        for name, why in self.unavailable.items():
            lines.append(f"| {name} (not available: {why}) | – | – | – | – | - |")
        return "\n".join(lines)


def averaged_ratio_per_joint(sim: ServoRun) -> np.ndarray:
    """Per joint: the 4 ms mean command over the full limit (``simulate_on_real``)."""
    return np.asarray(sim.max_averaged_torque_ratio_per_joint, float)


def to_gate(run: Callable[[float], tuple[JointTrajectory, ServoRun]], first: tuple[JointTrajectory, ServoRun],
            step: Callable[[float], float], gate: float) -> tuple[JointTrajectory, ServoRun, int]:
    """Smallest remedy strength ``x`` (``x = 0``: ``first``) whose servo run keeps ``gate``, by regula
    falsi on the 4 ms mean ratio: ``step(ratio)`` proposes the first strength from the measured
    excess, later rounds interpolate between the strongest failing and the weakest passing run,
    aiming ``GATE_AIM`` below the gate. Returns the shortest passing run (else the last) and the
    number of servo runs; a run that diverged ends the search (its ratio measures nothing)."""
    fail_x, fail_r = 0.0, first[1].max_averaged_torque_ratio
    if fail_r <= gate or first[1].diverged:
        return first[0], first[1], 0
    best, rounds = None, 0
    x, last = step(fail_r), first
    pass_x: float | None = None
    pass_r = 0.0                              # the last passing run's ratio, read once pass_x is set
    while rounds < SERVO_ROUNDS:
        last = run(x)
        rounds += 1
        r = last[1].max_averaged_torque_ratio
        if last[1].diverged:
            break
        if r <= gate:
            if best is None or last[0].duration_s < best[0].duration_s:
                best = last
            pass_x, pass_r = x, r
            if r >= GATE_AIM * gate:
                break
        else:
            fail_x, fail_r = x, r
        if pass_x is None:
            x = x + max(step(r), 0.5 * (x - fail_x) + 1e-3) if r > gate else x
            continue
        target = GATE_AIM * gate
        x = fail_x + (pass_x - fail_x) * (fail_r - target) / max(fail_r - pass_r, 1e-9)
    tr, sim = best if best is not None else last
    return tr, sim, rounds


def servo_slowed(real: RealRobot, robot: RobotModel, traj: JointTrajectory, ccfg: ControlConfig, seed: int,
                 gate: float, first_sim: ServoRun | None = None) -> tuple[JointTrajectory, ServoRun, int]:
    """``traj`` slowed in time (``t' = (1 + x) t``) until its 4 ms mean command keeps ``gate``."""
    def run(x: float) -> tuple[JointTrajectory, ServoRun]:
        tr = time_scaled(traj, 1.0 + x, traj.name)
        tr.info["servo_time_scale"] = 1.0 + x
        return tr, simulate_on_real(real, robot, tr, ccfg, np.random.default_rng(seed))

    first = (traj, first_sim if first_sim is not None else
             simulate_on_real(real, robot, traj, ccfg, np.random.default_rng(seed)))
    return to_gate(run, first, lambda r: float(np.sqrt(r / gate)) - 1.0, gate)


def reserve_floor(pm: PlanningModel, path: JointPath, n_grid: int) -> np.ndarray:
    """Per joint, the smallest torque-limit scale the reserve remedy may use on ``path``:
    ``RESERVE_HOLDING_MARGIN x max_s (|g_j(q(s))| + F_c,j) / tau_max,j`` on the ``n_grid`` grid (at
    most 1): below it the arm cannot hold the path at rest, let alone move along it."""
    q = path(np.linspace(0.0, 1.0, n_grid + 1))
    holding_Nm = np.max(np.abs(pm.rigid_torques(q, np.zeros_like(q), np.zeros_like(q))), axis=0) + pm.coulomb_Nm
    return np.minimum(RESERVE_HOLDING_MARGIN * holding_Nm / pm.effort_Nm, 1.0)


def servo_reserved(real: RealRobot, robot: RobotModel, pm: PlanningModel, path: JointPath, profile: CPProfile,
                   ccfg: ControlConfig,
                   seed: int, gate: float, n_grid: int, fine_dt_s: float,
                   first_sim: ServoRun) -> tuple[JointTrajectory, ServoRun, int]:
    """The time-optimal profile re-solved with the torque limits of the joints over the gate lowered,
    ``scale_j = 1 / (1 + x (r_j - 1))`` with ``r_j`` their 4 ms mean ratio on the time-optimal plan
    (``x = 1``: each by its whole excess), ``x`` by :func:`to_gate`; never below
    ``RESERVE_HOLDING_MARGIN`` times the share of the limit that holds the path at rest (gravity and
    Coulomb friction, on the grid), below which no motion along the path exists."""
    r0 = np.maximum(averaged_ratio_per_joint(first_sim) / gate, 1.0)
    floor = reserve_floor(pm, path, n_grid)

    def run(x: float) -> tuple[JointTrajectory, ServoRun]:
        scale = np.maximum(1.0 / (1.0 + x * (r0 - 1.0)), floor)
        prof = solve_cp_reachability(pm, path, n_grid, name="cp_reserve", torque_scale=scale,
                                     acceleration_limits=False)
        tr = prof.sample(path, fine_dt_s)
        tr.info["torque_scale"] = scale.tolist()
        return tr, simulate_on_real(real, robot, tr, ccfg, np.random.default_rng(seed))

    return to_gate(run, (profile.sample(path, fine_dt_s), first_sim), lambda r: 0.5, gate)


def executable_cp(real: RealRobot, robot: RobotModel, pm: PlanningModel, cp: CPPlan, ccfg: ControlConfig, seed: int,
                  cfg: TrajectoryConfig,
                  cp_sim: ServoRun) -> ExecutableCP:
    """Measure the remedies (module docstring) and pick the shortest that keeps the servo gate.

    ``cp`` is the stage's :class:`~pipeline.trajectory.solve.CPPlan`, ``cp_sim`` the servo simulation
    of its time-optimal plan. A remedy that still exceeds the gate after its rounds is reported and
    not chosen; when none keeps it, the one with the lowest ratio is executed (and the stage's gate
    reports it)."""
    gate = cfg.max_sim_averaged_torque_ratio
    cands: dict[str, tuple[JointTrajectory, ServoRun, int, str]] = {
        "time_optimal": (cp.trajectories["cp"], cp_sim, 0, "as planned")}
    over = cp_sim.max_averaged_torque_ratio > gate
    unavailable: dict[str, str] = {}
    if over:
        try:
            tr, sim, rounds = servo_reserved(real, robot, pm, cp.path, cp.optimal, ccfg, seed, gate,
                                             cfg.cp_n_grid, cfg.fine_dt_s, cp_sim)
            scale = tr.info.get("torque_scale", [1.0] * pm.nq)
            cands["reserve"] = (tr, sim, rounds, "torque limits x " + ", ".join(f"{s:.2f}" for s in scale))
        except (InfeasibleError, SolverError) as exc:    # lowered limits no profile meets: the other remedies
            unavailable["reserve"] = str(exc)
    if "cp_smooth" in cp.trajectories:
        tr, sim, rounds = servo_slowed(real, robot, cp.trajectories["cp_smooth"], ccfg, seed, gate)
        cands["smooth"] = (tr, sim, rounds, f"jerk-limited, slowed x {tr.info.get('servo_time_scale', 1.0):.3f}")
    if over:
        tr, sim, rounds = servo_slowed(real, robot, cp.trajectories["cp"], ccfg, seed, gate, cp_sim)
        cands["slowed"] = (tr, sim, rounds, f"time-optimal slowed x {tr.info.get('servo_time_scale', 1.0):.3f}")
    table = {name: {"duration_s": c[0].duration_s, "max_averaged_torque_ratio": c[1].max_averaged_torque_ratio,
                    "rounds": c[2], "what": c[3]} for name, c in cands.items()}
    best = choose(table, gate)
    tr, sim = cands[best][0], cands[best][1]
    executed = JointTrajectory("cp_executed", tr.t_s, tr.q, tr.v, tr.a, {**tr.info, "remedy": best})
    return ExecutableCP(best, executed, sim, table, unavailable)


def choose(candidates: dict[str, dict], gate: float) -> str:
    """The shortest candidate (``duration_s``) whose ``max_averaged_torque_ratio`` keeps ``gate``;
    when none does, the one with the lowest ratio."""
    passing = [n for n, c in candidates.items() if c["max_averaged_torque_ratio"] <= gate]
    if passing:
        return min(passing, key=lambda n: candidates[n]["duration_s"])
    return min(candidates, key=lambda n: candidates[n]["max_averaged_torque_ratio"])


def executed_check(pm: PlanningModel, ex: ExecutableCP) -> TorqueCheck:
    """Fine-grid check of the executed CP against the planning limits."""
    return check_trajectory(pm, ex.trajectory)
