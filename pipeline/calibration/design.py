"""Selection of calibration configurations from a candidate set.

All algorithms work on whitened per-configuration Jacobian blocks ``G`` (N, m, p) and any
:class:`~pipeline.calibration.indices.IndexSpec` through
:class:`~pipeline.calibration.design_state.DesignState` (information matrix updated when a
configuration enters or leaves, paper 004 eqs. 15-17; exact exhaustive candidate searches: low-rank
updates of every candidate at once for the trace and log-det indices, branch and bound for O3/E).

Algorithms: :func:`remove_and_replace` (paper 004 §3.3.1 steps 1-4), :func:`detmax` (Mitchell's
excursion algorithm, as used in paper 003), :func:`bsaa` (paper 003 §3.2: swap one selected for one
unselected, Metropolis acceptance, geometric cooling 0.98, Markov chain length 1).

The stage's design steps before them: the identifiable parameter set (:func:`identify_parameter_set`),
the filtered candidate set (:func:`build_candidates`), the observability index with its working
poses (:func:`index_spec`), and afterwards the index of the configurations actually measured
(:func:`measured_design`).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import error_model as em
from pipeline.calibration import feasibility as fz
from pipeline.calibration import grid_cache, subsets
from pipeline.calibration import indices as ix
from pipeline.calibration import measure as ms
from pipeline.calibration import task_space as ts
from pipeline.calibration.config import Config
from pipeline.calibration.design_state import DesignState
from pipeline.calibration.elastostatic import design_blocks, negligible_compliances
from pipeline.core.blas import single_thread_blas
from pipeline.core.errors import ConfigError, InfeasibleError
from pipeline.core.progress import task
from pipeline.robot.model import RobotModel


def _one_blas_thread(fn):
    """Run a selection algorithm with one OpenBLAS thread (many tiny factorisations)."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with single_thread_blas():
            return fn(*args, **kwargs)
    return wrapper


@dataclass
class SelectionResult:
    """A selected design and how it was found."""

    method: str
    index_name: str
    selected: np.ndarray            # indices into the candidate set
    index_value: float              # natural value of the index
    run_time_s: float
    evaluations: int                # number of index evaluations (candidate designs scored)
    history: list[tuple[int, float]] = field(default_factory=list)  # (iteration, index value)
    #: index value of the rounded optimal approximate design the exchanges started from (None: no
    #: such start, :mod:`pipeline.calibration.design_rounding`)
    start_value: float | None = None
    #: certified lower bound ``V*/n`` of a trace index over every design of the candidate pool with
    #: as many configurations (None: not computed; ``index_value / bound_value >= 1`` is how far the
    #: selection can be from the best exact design at most)
    bound_value: float | None = None

    def as_dict(self) -> dict:
        return {"method": self.method, "index_name": self.index_name,
                "n_configurations": int(len(self.selected)), "index_value": float(self.index_value),
                "run_time_s": float(self.run_time_s), "evaluations": int(self.evaluations)}


def _random_regular_start(G: np.ndarray, n: int, rng: np.random.Generator, tries: int = 200,
                          candidates: np.ndarray | None = None) -> np.ndarray:
    """Paper 004 step 1: random subsets until the information matrix is regular."""
    N, m, p = G.shape
    pool = np.arange(N) if candidates is None else candidates
    if n * m < p:
        raise InfeasibleError(None, "calibration.n_configurations",
                              f"{n} configurations x {m} coordinates < {p} identifiable parameters")
    if pool.size < n:
        raise InfeasibleError(None, "calibration.candidates",
                              f"only {pool.size} feasible candidates for {n} configurations "
                              "(increase n_random_candidates or grid_per_axis)")
    ev_all = np.linalg.eigvalsh(np.einsum("kmi,kmj->ij", G[pool], G[pool]))
    if ev_all[0] <= 1e-10 * max(ev_all[-1], 1e-300):
        raise InfeasibleError(None, "calibration.candidates",
                              "the candidate set cannot make the information matrix regular "
                              f"(rank {int(np.sum(ev_all > 1e-10 * ev_all[-1]))} < {p} parameters)")
    for _ in range(tries):
        S = rng.choice(pool, size=n, replace=False)
        Gs = G[S]
        ev = np.linalg.eigvalsh(np.einsum("kmi,kmj->ij", Gs, Gs))
        if ev[0] > 1e-10 * max(ev[-1], 1e-300):
            return S
    raise InfeasibleError(None, "calibration.candidates",
                          f"no regular random subset of {n} configurations in {tries} tries")


def _check(G: np.ndarray) -> np.ndarray:
    G = np.asarray(G, float)
    if G.ndim != 3:
        raise ValueError("G must be (N, m, p)")
    if not np.all(np.isfinite(G)):
        raise InfeasibleError(None, "calibration.candidates", "non-finite Jacobian entries")
    return G


@_one_blas_thread
def remove_and_replace(G: np.ndarray, spec: ix.IndexSpec, n_max: int, rng: np.random.Generator,
                       n_initial: int | None = None, positions: np.ndarray | None = None,
                       max_iterations: int = 500, rel_tol: float = 1e-6,
                       initial: np.ndarray | None = None) -> SelectionResult:
    """Paper 004 §3.3.1, steps 1-4.

    1. random regular start of ``n_initial`` configurations;
    2. remove the configuration whose removal decreases the index least, add the candidate that
       increases it most; repeat while the index improves;
    3. add the best single candidate while the index improves and ``n < n_max``;
    4. final remove-and-replace: try every selected configuration; execute any exchange that
       improves the index; stop when a full pass makes none.
    """
    t0 = time.perf_counter()
    G = _check(G)
    N, m, p = G.shape
    if n_initial is None:
        n_initial = max(min(n_max, math.ceil(p / m) + 2), (n_max * 2) // 3)
    n_initial = min(n_initial, n_max)
    start = initial if initial is not None else _random_regular_start(G, n_initial, rng)
    st = DesignState(G, spec, positions, start)
    cur = st.score()
    hist = [(0, st.value())]
    it = 0

    def step_exchange(remove_k: int) -> bool:
        nonlocal cur, it
        j, s_new = st.best_exchange(remove_k)
        if j >= 0 and s_new > cur + rel_tol * max(abs(cur), 1e-300) and j != remove_k:
            st.remove(remove_k)
            st.add(j)
            cur = st.score()
            it += 1
            hist.append((it, st.value()))
            return True
        return False

    # step 2
    while it < max_iterations:
        rs = st.remove_scores()
        k = st.selected[int(np.argmax(rs))]
        if not step_exchange(k):
            break
    # step 3
    while st.n < n_max:
        j, s_new = st.best_add()
        if j < 0 or not s_new > cur + rel_tol * max(abs(cur), 1e-300):
            break
        st.add(j)
        cur = st.score()
        it += 1
        hist.append((it, st.value()))
    # step 4
    improved = True
    while improved and it < max_iterations:
        improved = False
        rs = st.remove_scores()
        for k in [st.selected[i] for i in np.argsort(-rs)]:
            if step_exchange(k):
                improved = True
                break
    st.refresh()
    return SelectionResult("remove_and_replace", spec.name, np.array(st.selected), st.value(),
                           time.perf_counter() - t0, st.evaluations, hist)


@_one_blas_thread
def detmax(G: np.ndarray, spec: ix.IndexSpec, n: int, rng: np.random.Generator,
           positions: np.ndarray | None = None, max_depth: int = 3, max_iterations: int = 500,
           rel_tol: float = 1e-9) -> SelectionResult:
    """DETMAX (Mitchell 1974): excursions that add ``d`` best points then remove ``d`` worst ones;
    an improving excursion is kept and the depth reset to 1, otherwise the depth grows up to
    ``max_depth``."""
    t0 = time.perf_counter()
    G = _check(G)
    st = DesignState(G, spec, positions, _random_regular_start(G, n, rng))
    cur = st.score()
    hist = [(0, st.value())]
    depth, it = 1, 0
    while depth <= max_depth and it < max_iterations:
        before = list(st.selected)
        for _ in range(depth):
            j, _s = st.best_add()
            if j < 0:
                break
            st.add(j)
        while st.n > n:
            rs = st.remove_scores()
            st.remove(st.selected[int(np.argmax(rs))])
        new = st.score()
        if new > cur + rel_tol * max(abs(cur), 1e-300):
            cur = new
            depth = 1
            it += 1
            hist.append((it, st.value()))
        else:
            st.selected = before
            st.in_set[:] = False
            st.in_set[before] = True
            st.refresh()
            depth += 1
    return SelectionResult("detmax", spec.name, np.array(st.selected), st.value(),
                           time.perf_counter() - t0, st.evaluations, hist)


@_one_blas_thread
def bsaa(G: np.ndarray, spec: ix.IndexSpec, n: int, rng: np.random.Generator,
         positions: np.ndarray | None = None, t_initial: float = 1e20, t_final: float = 1e-50,
         cooling: float = 0.98, chain_length: int = 1) -> SelectionResult:
    """Binary simulated annealing (paper 003 §3.2).

    A state is a 0/1 selection vector with ``n`` ones. A move flips one random 1 and one random 0
    (swap), accepted by the Metropolis rule ``u < exp((F_new - F) / T)`` on the score F; the
    temperature is multiplied by ``cooling`` (0.98) after each Markov chain (length 1) until
    ``t_final``. Paper 003 gives T_init = 10^20, T_final = 10^-50 (signs of the exponents read from
    the garbled extraction). The best state visited is returned.
    """
    t0 = time.perf_counter()
    G = _check(G)
    N = G.shape[0]
    st = DesignState(G, spec, positions, _random_regular_start(G, n, rng))
    cur = st.score()
    best, best_sel = cur, list(st.selected)
    hist = [(0, st.value())]
    T = t_initial
    it = 0
    n_steps = int(math.ceil(math.log(t_final / t_initial) / math.log(cooling)))
    for _ in range(n_steps):
        for _c in range(chain_length):
            out_pos = int(rng.integers(st.n))
            k_out = st.selected[out_pos]
            while True:
                j_in = int(rng.integers(N))
                if not st.in_set[j_in]:
                    break
            st.remove(k_out)
            st.add(j_in)
            new = st.score()
            d = new - cur
            if d >= 0 or (np.isfinite(d) and rng.random() < math.exp(max(d / T, -700.0))):
                cur = new
                if cur > best:
                    best, best_sel = cur, list(st.selected)
            else:
                st.remove(j_in)
                st.add(k_out)
        it += 1
        if it % 50 == 0:
            hist.append((it, -best if spec.minimised else best))
        T *= cooling
    st.selected = best_sel
    st.in_set[:] = False
    st.in_set[best_sel] = True
    st.refresh()
    hist.append((it, st.value()))
    return SelectionResult("bsaa", spec.name, np.array(best_sel), st.value(),
                           time.perf_counter() - t0, st.evaluations, hist)


@_one_blas_thread
def random_design(G: np.ndarray, spec: ix.IndexSpec, n: int, rng: np.random.Generator,
                  positions: np.ndarray | None = None) -> SelectionResult:
    """Heuristic baseline: a random regular subset (paper 000's 'heuristic', paper 003's 'none')."""
    t0 = time.perf_counter()
    G = _check(G)
    st = DesignState(G, spec, positions, _random_regular_start(G, n, rng))
    return SelectionResult("random", spec.name, np.array(st.selected), st.value(),
                           time.perf_counter() - t0, 1, [(0, st.value())])


@_one_blas_thread
def linear_scan_design(G: np.ndarray, spec: ix.IndexSpec, n: int,
                       positions: np.ndarray | None = None) -> SelectionResult:
    """Paper 004's comparison: ``n`` candidates equally spaced through the (grid-ordered) set."""
    t0 = time.perf_counter()
    G = _check(G)
    sel = np.unique(np.linspace(0, G.shape[0] - 1, n).round().astype(int))
    st = DesignState(G, spec, positions, sel)
    return SelectionResult("linear_scan", spec.name, sel, st.value(), time.perf_counter() - t0, 1,
                           [(0, st.value())])


METHODS = {"remove_and_replace": remove_and_replace, "detmax": detmax, "bsaa": bsaa,
           "random": random_design}


def select(method: str, G: np.ndarray, spec: ix.IndexSpec, n: int, rng: np.random.Generator,
           positions: np.ndarray | None = None, **kw) -> SelectionResult:
    """Dispatch to a selection algorithm by name."""
    if method == "remove_and_replace":
        return remove_and_replace(G, spec, n, rng, positions=positions, **kw)
    if method not in METHODS:
        raise ValueError(f"unknown selection method {method!r}; choose from {sorted(METHODS)}")
    return METHODS[method](G, spec, n, rng, positions=positions, **kw)


def identify_parameter_set(robot: RobotModel, mm: em.MeasurementModel, cfg: Config, rng: np.random.Generator
                           ) -> tuple[em.IdentifiabilityReport, np.ndarray]:
    """Identifiability analysis on random configurations (paper 002 SVD, paper 003 correlations)
    of the parameters in ``calibration.parameters`` (:mod:`pipeline.calibration.subsets`).

    Returns the report (in the error model's own parameters) and the basis ``P`` (n_full, p) of
    the identifiable parameters, ``x = P theta``.
    """
    Q = em.random_configurations(robot, cfg.identifiability_samples, rng)
    if mm.marker_points:   # 6-D readings: the marker origin and the two virtual axis points
        n = len(Q)
        offsets = np.repeat(ms.MARKER_LEVER_M * np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), n, 0)
        _, J = mm.jacobian(np.concatenate([Q] * 3), np.zeros(mm.n), robot.tracker.transform_tracker_to_base,
                           offsets=offsets)
    elif mm.compliance:   # the elastostatic columns need the gravity torques: the CasADi model
        _, J = mm.jacobian(Q, np.zeros(mm.n), robot.tracker.transform_tracker_to_base)
    else:
        _, J = cd.nominal_jacobian(cd.chain_from_robot(robot), Q, robot.tracker.transform_tracker_to_base)
    J = J.reshape(-1, mm.n)
    if mm.compliance:   # no gravity torque on a joint: its compliance has no effect
        J[:, np.arange(mm.n)[mm.sl_compliance][negligible_compliances(mm, J)]] = 0.0
    if cfg.error_model == "se3":
        B, names = np.eye(mm.n), mm.names
    else:
        try:
            B, names = em.mdh_basis(robot, mm.names)
        except ValueError as exc:
            raise ConfigError(None, "calibration.error_model", f"mdh_hayati: {exc}") from None
    cols = subsets.select(cfg.parameters, names)
    rep = em.identifiability((J @ B)[:, cols], [names[i] for i in cols], cfg.identifiability_rel_tol)
    return rep, em.parameter_basis(rep, mm.n, B[:, cols])


def build_candidates(robot: RobotModel, cfg: Config, basis: np.ndarray, rng: np.random.Generator,
                     static_torques: Callable[[np.ndarray], np.ndarray] | None = None) -> cd.CandidateSet:
    """Filtered candidate set with whitened Jacobians (nominal model, nominal tracker pose;
    ``static_torques`` for a basis with compliances, :func:`cd.build_candidate_set`)."""
    chain = cd.chain_from_robot(robot)
    margins = cd.FilterMargins(cfg.margin_collision_m, math.radians(cfg.margin_incidence_deg), cfg.margin_beam_m)
    grid_index = None
    # a first 1 % of random configurations: none feasible -> stop with the cause, not after minutes
    first = fz.probe(chain, margins, [c.name for c in robot.capsules])
    if first.n_feasible == 0:
        raise fz.infeasible_error(first, robot.spec.path)
    if cfg.candidates == "grid":
        per_axis = cfg.grid_points_per_axis(robot.nq)
        with task(f"calibration: filtering the {per_axis}^{robot.nq} grid") as bar:
            Q, grid_index, counts = grid_cache.filter_grid(chain, per_axis, margins, progress=bar)
    else:
        Q, counts = cd.random_candidates(chain, cfg.n_random_candidates, rng, margins, count_all=True)
    if len(Q) == 0:
        counts_text = ", ".join(f"{k} {v}" for k, v in counts.items() if k != "time_s")
        key = "calibration.grid_per_axis" if cfg.candidates == "grid" else "calibration.candidates"
        raise InfeasibleError(None, key,
                              f"no feasible candidate configuration (joint limits, collisions, floor, tracker "
                              f"visibility with the calibration.margin_* values; {counts_text})")
    return cd.build_candidate_set(chain, Q, basis, robot.tracker.transform_tracker_to_base, counts, grid_index,
                                  static_torques=static_torques)


def too_few_candidates(cfg: Config, robot: RobotModel, n_feasible: int) -> str:
    """Message for a candidate set smaller than ``n_configurations``, in the user's fields."""
    rules = "joint limits, collisions, floor, tracker visibility with the calibration.margin_* values"
    if cfg.candidates == "random":
        return (f"only {n_feasible} feasible random configurations were found ({rules}; n_random_candidates = "
                f"{cfg.n_random_candidates}), fewer than the {cfg.n_configurations} configurations asked for: "
                "lower n_configurations or the margins, or check the robot's limits, capsules and tracker pose")
    per_axis = cfg.grid_points_per_axis(robot.nq)
    return (f"only {n_feasible} of the {per_axis}^{robot.nq} grid configurations (grid_per_axis = "
            f"{per_axis}) are feasible ({rules}), fewer than the {cfg.n_configurations} configurations "
            "asked for: raise grid_per_axis or lower n_configurations")


def working_jacobian(robot: RobotModel, mm: em.MeasurementModel, Qw: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """TCP-position Jacobian rows (3 n_w, p) at working configurations wrt ``theta`` (base frame;
    tracker and reflector parameters do not move the TCP; compliances by the gravity deflection,
    :func:`pipeline.calibration.task_space.tcp_jacobian`)."""
    return ts.tcp_jacobian(mm, Qw, basis, robot.frame_tcp)


def index_spec(cfg: Config, robot: RobotModel, mm: em.MeasurementModel, basis: np.ndarray, rng: np.random.Generator,
               region: ts.WorkingRegion | None = None) -> tuple[ix.IndexSpec, np.ndarray | None]:
    """The observability index; for the TCP criteria random collision-free working poses (``V``: in
    the working region, :mod:`pipeline.calibration.task_space`; its reflector term at the working
    poses the tracker sees, where held-out readings verify it)."""
    if cfg.index_name == "V":
        region = region or ts.default_region(robot)
        Qw = ts.sample_region(robot, region, cfg.n_region_configurations, rng)
        Qv = (ts.verifiable_configurations(robot, region, cfg.n_region_configurations, rng, cfg.margin_collision_m)
              if "reflector" in cfg.design_figure.split("+") else None)
        return ts.task_space_spec(mm, Qw, basis, cfg.design_figure, Qv), Qw
    if not cfg.index_name.startswith("tcp_A"):
        return ix.IndexSpec(cfg.index_name), None
    chain = cd.chain_from_robot(robot)
    Qw, _ = cd.random_candidates(chain, cfg.n_working_configurations, rng, visibility=False)
    Jw = working_jacobian(robot, mm, Qw, basis)
    return ix.IndexSpec(cfg.index_name, working_jacobian=Jw, n_working=len(Qw)), Qw


def measured_design(robot: RobotModel, mm: em.MeasurementModel, basis: np.ndarray, Q: np.ndarray, spec: ix.IndexSpec,
                    T_tb, method: str, mounted: np.ndarray | None = None) -> dict:
    """Observability index of the configurations ``Q`` actually measured (nominal model, whitened
    by the tracker noise model, tracker pose ``T_tb``, the payload's torque where ``mounted``);
    same conventions as the selection."""
    G = design_blocks(mm, Q, basis, T_tb, mounted).reshape(-1, basis.shape[1])
    Y = cd.nominal_jacobian(cd.chain_from_robot(robot), Q, T_tb)[0] if spec.needs_positions else None
    value = ix.evaluate(spec, G.T @ G, len(Q), Y)
    return {"method": method, "index_name": spec.name, "n_configurations": int(len(Q)), "index_value": float(value)}
