"""Paper 000 reproduced: KPI-based optimum experimental design (``python -m pipeline study calib-000``).

Paper: ``papers/000_bd0c20fcd494d4a1.txt`` (Jost, Kudruss, Körkel, Walter, J. Math. Industry 7:9,
2017). 60 measurement configurations of a laser tracker (tracker pose and reflector offset
identified too) are designed to minimise the A-criterion (eq. 24a: "the arithmetic mean of the
diagonal elements of the projected variance-covariance matrix") of either

- ``C_p`` (eq. 25, ``P = (I_1, 0)``): the covariance of the geometric parameters p (the
  "state-of-the-art" criterion), or
- ``C_s`` (``P = (0, I_2)``): the covariance of the KPI, the TCP position at the working
  configuration, ``C_s = J_w C J_w^T`` (eq. 16),

each with and without collision avoidance (Table 8), against the heuristic design. The paper's
kinematic model is DH with Hayati parameters for parallel axes (§1.1, Table 2): here the
``mdh_hayati`` error model (:func:`pipeline.calibration.error_model.mdh_basis`). Every design is
scored by the same figure, the mean TCP variance per coordinate at the working configuration
(Tables 6-8 report "average variances of the TCP").

Readings of the ``C_p`` criterion (each printed as an experiment):

- ``param_literal``: eq. 24a/25 as written: mean diagonal of the marginal covariance (the
  tracker and reflector estimated too) of the identifiable DH/Hayati parameters of the arm, SI
  units (m and rad) and no scaling (P's optional scaling is not specified in the text; Table 2's
  underlined subset is lost, so every identifiable arm parameter counts);
- ``param_scaled``: the same with each angle scaled by the arm's reach (a rad of error becomes the
  metres it moves a point at full reach), so lengths and angles count alike — P "with the
  possibility to scale each parameter independently" (§2.3);
- ``param_legacy``: the earlier study's criterion: the trace over the identifiable coordinates of
  the SE(3) placement-error model (6 per joint, m and rad), arm rows only.

Designs: remove-and-replace (:func:`pipeline.calibration.design.remove_and_replace`) over a pool
of feasible random candidates, then the gradient-based refinement of all joint angles with IPOPT
(:func:`pipeline.calibration.gradient_design.gradient_design`, the paper's SQP analogue) with the
cell's obstacles (CA) or with limits and incidence only (no CA). Cell, baselines and notional arms:
:mod:`pipeline.papers.calib_000_scene`. Tables: :mod:`pipeline.papers.calib_000_report`.

The paper's outlook measured (:mod:`pipeline.papers.calib_000_elastic`): each arm's
``tcp_ca`` design is measured on the default elastic hidden robot (``--elastic-seeds`` seeds, 3;
notional arms ``--notional-elastic-seeds``, 1) and calibrated with the geometric and with the
compliance-aware model; the TCP error at the working configuration of both and the gain of
modelling elasticity are printed (a few seconds per arm and seed).

Experiments beside the defaults (docs/papers/paper_000.md): ``--parameters joint_offsets`` (or a
comma-separated list of DH/Hayati names) identifies fewer arm parameters, ``--tag`` names the
output folder ``data/studies/calib-000-TAG/``.

The arms are independent tasks of :func:`pipeline.core.dispatch.map_tasks` (one dispatch, the named
arms first): ``--jobs N`` local processes or ``--scheduler ADDRESS`` a Dask cluster, as
``python -m pipeline sweep``; the rows do not depend on it (each arm's generator is seeded by the
seed and the arm's name).

Run time: the defaults as one command, ``python -m pipeline study calib-000 --jobs 2`` (three KUKA
arms with IPOPT refinement and the literal SQP reading, 90 notional arms with remove-and-replace on
pools of 400), took 12 min 39 s wall-clock on the shared 2-core machine with other runs beside it
(load average 4-6.4); the arms' own times add up to 1482 s (KUKA 418 s, notional 1064 s, about
12 s each), about what ``--jobs 1`` needs at that load (an earlier ``--jobs 1`` measurement in two
parts at load about 8: 740 s + 1917 s). That measurement predates the elasticity experiment; with it, the
defaults as one command (``--jobs 2``, the test suite running beside) took 6 min 54 s.
``--quick`` (KR 15, pool 300, 15 IPOPT iterations, one elastic seed) 10-30 s.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import error_model as em
from pipeline.calibration import indices as ix
from pipeline.calibration import stage as st
from pipeline.calibration.gradient_design import GradientDesignConfig, feasible_configurations, gradient_design
from pipeline.core.blas import single_thread_blas
from pipeline.core.dispatch import map_tasks
from pipeline.core.progress import Progress
from pipeline.papers import calib_000_elastic as el
from pipeline.papers import calib_000_report as rp
from pipeline.papers import calib_000_scene as sc
from pipeline.robot.model import RobotModel

KUKA_ARMS = ("kuka_kr15", "kuka_kr300", "kuka_kr500")
#: the criteria of Table 8 (C_p readings and C_s); "random" / "spread" are the baselines
CRITERIA = ("param_literal", "param_scaled", "param_legacy", "tcp")
LENGTH_SUFFIXES = ("dx", "dy", "dz", "dd", "da")


@dataclass
class Settings:
    n: int = 60
    pool: int = 1200
    iterations: int = 60
    gradient: bool = True
    criteria: tuple[str, ...] = CRITERIA
    #: also the literal SQP reading: IPOPT from the random (heuristic) design, no discrete search,
    #: no trust region (``*_ca_local``; CA only)
    local: bool = False
    local_iterations: int = 300
    #: ``calibration.parameters`` of the identified arm parameters (tracker and reflector always);
    #: a list of DH/Hayati names leaves out the legacy (SE(3)) criterion
    parameters: str | list[str] = "geometric"
    #: hidden robots (seeds 0..k-1) of the elasticity experiment on the tcp_ca design
    #: (:mod:`pipeline.papers.calib_000_elastic`; 0: off)
    elastic_seeds: int = 3


@dataclass
class ArmSetup:
    """One arm in its cell: models, identifiable bases, candidate pools, working Jacobian."""

    name: str
    robot: RobotModel          # with CA (the cell's tracker, ground and capsules)
    robot_free: RobotModel     # without CA (no capsules)
    scene: sc.Scene
    mm: em.MeasurementModel
    basis: np.ndarray          # mdh_hayati identifiable basis (the paper's parameters)
    names: list[str]
    basis_se3: np.ndarray      # se3 identifiable basis (the legacy criterion)
    names_se3: list[str]
    q_work: np.ndarray
    Jw: np.ndarray
    pools: dict[bool, np.ndarray]


def setup_arm(name: str, robot: RobotModel, pool: int, rng: np.random.Generator,
              parameters: str | list[str] = "geometric") -> ArmSetup:
    scene = sc.fms_scene(robot)
    arm = sc.scene_robot(robot, scene, True)
    mm = em.MeasurementModel(arm)
    rep, basis = st.identify_parameter_set(arm, mm, st.Config(error_model="mdh_hayati", parameters=parameters), rng)
    se3_parameters = "geometric" if isinstance(parameters, list) else parameters
    rep3, basis3 = st.identify_parameter_set(arm, mm, st.Config(error_model="se3", parameters=se3_parameters), rng)
    q_work = sc.working_configuration(robot, scene, rng)
    Jw = st.working_jacobian(arm, mm, q_work[None], basis)
    pools = {ca: sc.candidate_pool(robot, scene, pool, rng, ca) for ca in (True, False)}
    return ArmSetup(name, arm, sc.scene_robot(robot, scene, False), scene, mm, basis, rep.identifiable_names,
                    basis3, rep3.identifiable_names, q_work, Jw, pools)


def _is_arm(name: str) -> bool:
    return not name.startswith(("tracker.", "reflector."))


def parameter_weights(names: list[str], angle_scale_m: float) -> np.ndarray:
    """Diagonal of ``P^T P`` / n_p over the arm's parameters (eq. 24a: the mean of the diagonal);
    angles multiplied by ``angle_scale_m`` (1: the literal SI reading)."""
    w = np.array([0.0 if not _is_arm(n) else (1.0 if n.split(".")[1] in LENGTH_SUFFIXES else angle_scale_m ** 2)
                  for n in names])
    return w / max(int(np.count_nonzero(w)), 1)


def criterion(setup: ArmSetup, key: str) -> tuple[ix.IndexSpec, np.ndarray]:
    """The index and the parameter basis a criterion is optimised in."""
    if key == "tcp":
        return ix.IndexSpec("tcp_A", working_jacobian=setup.Jw, n_working=1), setup.basis
    if key == "param_literal":
        return ix.IndexSpec("A", parameter_weights=parameter_weights(setup.names, 1.0)), setup.basis
    if key == "param_scaled":
        return ix.IndexSpec("A", parameter_weights=parameter_weights(setup.names, setup.scene.reach_m)), setup.basis
    if key == "param_legacy":
        w = np.array([float(_is_arm(n)) for n in setup.names_se3])
        return ix.IndexSpec("A", parameter_weights=w), setup.basis_se3
    raise ValueError(f"unknown criterion {key!r}; choose from {CRITERIA}")


def information(setup: ArmSetup, Q: np.ndarray, basis: np.ndarray) -> np.ndarray:
    cs = cd.build_candidate_set(cd.chain_from_robot(setup.robot), Q, basis, setup.scene.tracker)
    return cs.G


def tcp_variance(setup: ArmSetup, Q: np.ndarray) -> float:
    """Mean variance per TCP coordinate at the working configuration (m^2) with the paper's
    parameters: ``trace(J_w (J^T J)^-1 J_w^T) / 3`` (eq. 16, 24a with ``C_s``)."""
    G = information(setup, Q, setup.basis)
    M = np.einsum("kmi,kmj->ij", G, G)
    return ix.evaluate(ix.IndexSpec("tcp_A", working_jacobian=setup.Jw), M, len(Q)) / 3.0


def collision_share(setup: ArmSetup, Q: np.ndarray) -> float:
    """Share of ``Q`` that is infeasible in the cell with every rule (collision or blocked beam)."""
    ok = feasible_configurations(setup.robot, Q, setup.scene.tracker, setup.scene.obstacles)
    return float(1.0 - ok.mean())


def optimise(setup: ArmSetup, key: str, ca: bool, cfg: Settings, rng: np.random.Generator) -> dict:
    """Remove-and-replace on the pool, then (optionally) the IPOPT refinement; the design's scores."""
    return design(setup, key, ca, cfg, rng)[0]


def design(setup: ArmSetup, key: str, ca: bool, cfg: Settings, rng: np.random.Generator) -> tuple[dict, np.ndarray]:
    """:func:`optimise`'s scores and the designed configurations."""
    spec, basis = criterion(setup, key)
    pool = setup.pools[ca]
    t0 = time.perf_counter()
    G = information(setup, pool, basis)
    sel = ds.remove_and_replace(G, spec, cfg.n, rng, n_initial=cfg.n)
    Q = pool[sel.selected]
    out = {"tcp_var_discrete": tcp_variance(setup, Q)}
    if cfg.gradient:
        arm = setup.robot if ca else setup.robot_free
        gcfg = GradientDesignConfig(max_iterations=cfg.iterations, obstacles=sc.obstacles_of(setup.scene, ca))
        g = gradient_design(arm, setup.mm, basis, Q, spec, gcfg, transform_tracker_to_base=setup.scene.tracker)
        Q = g.Q
        out |= {"ipopt_status": g.status, "reverted": g.reverted, "fallback": g.fallback}
    out |= {"tcp_var": tcp_variance(setup, Q), "collision_share": collision_share(setup, Q),
            "time_s": time.perf_counter() - t0}
    return out, Q


def optimise_local(setup: ArmSetup, key: str, Q_start: np.ndarray, cfg: Settings) -> dict:
    """The SQP of paper 000 §3.1 read literally: all joint angles optimised by IPOPT from the
    heuristic (random) design, with the cell's constraints, no discrete preselection and no trust
    region. A non-success status keeps the start (never stored as a result)."""
    spec, basis = criterion(setup, key)
    t0 = time.perf_counter()
    gcfg = GradientDesignConfig(max_iterations=cfg.local_iterations, max_step_rad=2 * np.pi,
                                obstacles=setup.scene.obstacles)
    g = gradient_design(setup.robot, setup.mm, basis, Q_start, spec, gcfg,
                        transform_tracker_to_base=setup.scene.tracker)
    return {"tcp_var_start": tcp_variance(setup, Q_start), "tcp_var": tcp_variance(setup, g.Q),
            "ipopt_status": g.status, "fallback": g.fallback, "reverted": g.reverted,
            "collision_share": collision_share(setup, g.Q), "time_s": time.perf_counter() - t0}


def run_arm(name: str, robot: RobotModel, cfg: Settings, seed: int) -> dict:
    """Every design of Table 8 for one arm (a result row)."""
    with single_thread_blas():
        rng = np.random.default_rng([seed, sum(map(ord, name))])
        t0 = time.perf_counter()
        setup = setup_arm(name, robot, cfg.pool, rng, cfg.parameters)
        pool = setup.pools[True]
        starts = [sc.random_design(pool, cfg.n, rng) for _ in range(5)]
        rnd = [tcp_variance(setup, Q) for Q in starts]
        spread = sc.spread_design(setup.robot, setup.scene, pool, cfg.n)
        row: dict = {"arm": name, "n": cfg.n, "pool": {str(k): len(v) for k, v in setup.pools.items()},
                     "q_work_deg": np.rad2deg(setup.q_work).round(1).tolist(),
                     "tcp_work_m": setup.robot.fk(setup.q_work, setup.robot.frame_tcp).translation.round(3).tolist(),
                     "n_parameters": len(setup.names), "n_arm_parameters": sum(map(_is_arm, setup.names)),
                     "random": float(np.mean(rnd)), "random_sem": float(np.std(rnd, ddof=1) / np.sqrt(len(rnd))),
                     "spread": tcp_variance(setup, spread), "spread_collision_share": collision_share(setup, spread)}
        designs = {}
        for key in [c for c in cfg.criteria if not (c == "param_legacy" and isinstance(cfg.parameters, list))]:
            for ca in (True, False):
                row[f"{key}_{'ca' if ca else 'free'}"], designs[key, ca] = design(setup, key, ca, cfg, rng)
            if cfg.local:
                row[f"{key}_ca_local"] = optimise_local(setup, key, starts[0], cfg)
        if cfg.elastic_seeds and ("tcp", True) in designs:   # own generator: the rows above do not change
            t1 = time.perf_counter()
            row["elastic"] = el.elastic_gain(setup.robot, setup.mm, designs["tcp", True], setup.q_work,
                                             list(range(cfg.elastic_seeds)),
                                             np.random.default_rng([seed, sum(map(ord, name)), 1]))
            row["elastic"]["time_s"] = time.perf_counter() - t1
        row["time_s"] = time.perf_counter() - t0
    return row


@dataclass(frozen=True)
class ArmTask:
    """One arm of the study (a task of :func:`pipeline.core.dispatch.map_tasks`): a robot folder, or a
    notional arm (segment lengths ``lambda_m``, ``mu_m`` on the ``robot`` folder's kinematics)."""

    name: str
    robot: str
    cfg: Settings
    seed: int
    lambda_m: float | None = None
    mu_m: float | None = None


def run_task(task: ArmTask) -> dict:
    """The result row of one arm (a pure function of ``task``: the arm's generator is seeded by
    the study seed and the arm's name, so the row does not depend on where or when it runs)."""
    robot = RobotModel.load(task.robot)
    if task.lambda_m is None or task.mu_m is None:
        return run_arm(task.name, robot, task.cfg, task.seed)
    row = run_arm(task.name, sc.notional_arm(robot, task.lambda_m, task.mu_m), task.cfg, task.seed)
    return row | {"lambda_m": task.lambda_m, "mu_m": task.mu_m}


def kuka_tasks(cfg: Settings, seed: int, arms: tuple[str, ...] = KUKA_ARMS) -> list[ArmTask]:
    return [ArmTask(a, a, cfg, seed) for a in arms]


def notional_tasks(cfg: Settings, seed: int, count: int, base: str = "kuka_kr15") -> list[ArmTask]:
    """The paper's 90 notional arms (or ``count`` of them spread over the lambda x mu grid)."""
    grid = [(lam, mu) for lam in sc.LAMBDA_M for mu in sc.MU_M]
    if count < len(grid):
        grid = [grid[i] for i in np.unique(np.linspace(0, len(grid) - 1, count).round().astype(int))]
    return [ArmTask(f"lambda {lam:.2f} mu {mu:.2f}", base, cfg, seed, lam, mu) for lam, mu in grid]


def run_tasks(tasks: list[ArmTask], jobs: int = 1, scheduler: object = None) -> list[dict]:
    """The rows of ``tasks`` in order, on ``jobs`` local processes or a Dask ``scheduler``."""
    return map_tasks(run_task, tasks, jobs=jobs, scheduler=scheduler, progress=Progress(), description="calib-000 arms")


def study(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="study calib-000", description=__doc__.split("\n\n")[0])
    ap.add_argument("--arms", nargs="*", default=list(KUKA_ARMS), help="robot folders (default: the three KUKA arms)")
    ap.add_argument("--notional", type=int, default=90, help="notional arms (paper: 90; 0: none)")
    ap.add_argument("--n", type=int, default=60)
    ap.add_argument("--pool", type=int, default=1200, help="feasible random candidates per arm and CA setting")
    ap.add_argument("--iterations", type=int, default=60, help="IPOPT iterations of the refinement")
    ap.add_argument("--no-gradient", action="store_true", help="remove-and-replace designs only")
    ap.add_argument("--notional-gradient", action="store_true", help="refine the notional arms' designs too")
    ap.add_argument("--notional-pool", type=int, default=400, help="candidates per notional arm and CA setting")
    ap.add_argument("--no-local", action="store_true",
                    help="skip the literal SQP reading (IPOPT from the heuristic design) on the named arms")
    ap.add_argument("--quick", action="store_true",
                    help="one arm (KR 15), pool 300, 15 iterations, no notional arms, one elastic seed")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--elastic-seeds", type=int, default=3,
                    help="hidden robots of the elasticity experiment (paper's outlook) per arm; 0: off")
    ap.add_argument("--notional-elastic-seeds", type=int, default=1,
                    help="the same for each notional arm (0: off)")
    ap.add_argument("--jobs", type=int, default=1, help="local worker processes (joblib; default 1)")
    ap.add_argument("--scheduler", metavar="ADDRESS",
                    help="Dask scheduler address (tcp://host:8786): the arms run on its workers")
    ap.add_argument("--tag", default="", help="write data/studies/calib-000[-TAG]/result.json")
    ap.add_argument("--parameters", default="geometric",
                    help="identified arm parameters (calibration.parameters: geometric, joint_offsets, or "
                         "comma-separated DH/Hayati names such as j2.da,j3.dq)")
    a = ap.parse_args(argv)
    if "," in a.parameters:
        a.parameters = a.parameters.split(",")
    if a.quick:
        a.arms, a.notional, a.pool, a.iterations, a.no_local, a.elastic_seeds = ["kuka_kr15"], 0, 300, 15, True, 1
    cfg = Settings(n=a.n, pool=a.pool, iterations=a.iterations, gradient=not a.no_gradient, local=not a.no_local,
                   parameters=a.parameters, elastic_seeds=a.elastic_seeds)
    ncfg = Settings(n=a.n, pool=a.notional_pool, iterations=a.iterations, gradient=cfg.gradient and a.notional_gradient,
                    parameters=a.parameters, elastic_seeds=a.notional_elastic_seeds)
    kuka = kuka_tasks(cfg, a.seed, tuple(a.arms))
    t0 = time.perf_counter()
    # one dispatch for all arms (the named arms, the slowest, first): workers stay busy to the end
    rows = run_tasks(kuka + (notional_tasks(ncfg, a.seed, a.notional) if a.notional else []), a.jobs, a.scheduler)
    kuka_rows, notional = rows[:len(kuka)], rows[len(kuka):]
    result = rp.report(kuka_rows, notional, vars(a), time.perf_counter() - t0)
    rp.save("calib-000" + (f"-{a.tag}" if a.tag else ""), result)
    return 0
