"""Task-space design criterion: predicted TCP variance over the region where the arm works.

Paper 000 (``papers/000_bd0c20fcd494d4a1.txt`` §2.3, eq. 16 and 24a) designs calibration
experiments on the covariance of the TCP at a few given working configurations (its KPI,
``C_s = J_w C J_w^T``). Its continuous form over a whole working region is the V-/I-optimal
design criterion (Atkinson, Donev & Tobias, *Optimum Experimental Designs, with SAS*, Oxford 2007,
§10.6 "V-optimality"; I-optimality is the same integral over a continuous region):

    V(design) = (1 / n_w) sum_w trace(J_w M^-1 J_w^T) = trace(W M^-1),
    W = (1 / n_w) sum_w J_w^T J_w,

``M = sum_k G_k^T G_k`` the whitened information matrix of the measured configurations and
``J_w`` (3 x p) the sensitivity of the TCP position to the identifiable parameters at working
configuration ``w`` (tracker and reflector parameters do not move the TCP: zero columns).
``V`` is the mean predicted TCP position variance (m²) over the working configurations; its root
is the predicted RMS TCP error of the calibrated model there. Being ``trace(W M^-1)``, it has the
rank-one (Sherman-Morrison) updates the selection algorithms use and the smooth form the gradient
design uses (:mod:`pipeline.calibration.design`, :mod:`pipeline.calibration.gradient_design`).

The working region (``calibration.working_region``):

- ``iso_cube`` (default): the run's EN ISO 9283 cube (``control.iso.centre_m``, ``edge_m``);
- ``box``: ``calibration.working_box_m = [[xmin, ymin, zmin], [xmax, ymax, zmax]]`` (base frame, m);
- ``csv``: the user's working poses, ``calibration.working_csv`` with columns ``q1..qn`` (rad).

For a region (cube or box) the working configurations are uniformly random joint configurations
inside the joint limits, free of self/floor collision, whose TCP lies in the region: every
orientation the arm can take there (the tracker need not see them: they are where the arm works,
not where it is measured). The reflector term of ``design_figure`` is what a held-out reading can
verify, so it is taken at working configurations the tracker sees at its nominal pose (the held-out
poses' margins, :func:`verifiable_configurations`): there the flange faces the tracker, and the
predicted reading error differs from the one over every orientation of the region.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import indices as ix
from pipeline.calibration.error_model import MeasurementModel
from pipeline.core.errors import ConfigError, DataFileError, InfeasibleError
from pipeline.core.yaml12 import YAMLError, load_yaml
from pipeline.robot.defaults import iso_or_derived
from pipeline.robot.iso9283 import IsoPathConfig
from pipeline.robot.model import RobotModel

WORKING_REGIONS = ("iso_cube", "box", "csv")
#: what V weights over the working configurations (``calibration.design_figure``): the TCP (the task),
#: the reflector in the tracker frame at the working poses the tracker sees (what held-out tracker
#: readings verify), or both
DESIGN_FIGURES = ("tcp+reflector", "tcp", "reflector")


@dataclass
class WorkingRegion:
    """Where the arm works: an axis-aligned box (base frame) or explicit configurations."""

    kind: str
    lower_m: np.ndarray | None = None
    upper_m: np.ndarray | None = None
    configurations: np.ndarray | None = None

    def describe(self) -> str:
        if self.configurations is not None:
            return f"{len(self.configurations)} working poses from {self.kind}"
        lo, hi = self.lower_m, self.upper_m
        return (f"{self.kind}: x {lo[0]:.3f}..{hi[0]:.3f}, y {lo[1]:.3f}..{hi[1]:.3f}, "
                f"z {lo[2]:.3f}..{hi[2]:.3f} m")


def region_from_config(cfg, iso_centre_m, iso_edge_m, robot: RobotModel) -> WorkingRegion:
    """The working region of a calibration ``Config`` (module docstring); ``iso_*`` from ``control.iso``."""
    if cfg.working_region == "box":
        box = np.asarray(cfg.working_box_m, float)
        return WorkingRegion("box", box[0], box[1])
    if cfg.working_region == "csv":
        return WorkingRegion(cfg.working_csv, configurations=read_working_csv(cfg.working_csv, robot))
    if iso_centre_m is None or iso_edge_m is None:      # not configured: the cube derived from the model
        derived = iso_or_derived(robot, IsoPathConfig(centre_m=iso_centre_m, edge_m=iso_edge_m))
        iso_centre_m, iso_edge_m = derived.centre_m, derived.edge_m
    c = np.asarray(iso_centre_m, float)
    h = 0.5 * float(iso_edge_m)
    return WorkingRegion("ISO 9283 cube", c - h, c + h)


def read_working_csv(path: str, robot: RobotModel) -> np.ndarray:
    """Joint configurations ``q1..qn`` (rad) of the user's working poses, inside the joint limits."""
    cols = [f"q{i + 1}" for i in range(robot.nq)]
    try:
        with open(path, encoding="utf-8-sig") as f:
            header = [h.strip() for h in f.readline().split(",")]
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except OSError as exc:
        raise DataFileError(path, "calibration.working_csv", f"cannot read: {exc.strerror}") from None
    except ValueError as exc:
        raise DataFileError(path, "calibration.working_csv", f"not a numeric CSV: {exc}") from None
    missing = [c for c in cols if c not in header]
    if missing:
        raise DataFileError(path, "columns", f"missing {missing} (need {cols})")
    Q = data[:, [header.index(c) for c in cols]]
    if len(Q) == 0 or not np.all(np.isfinite(Q)):
        raise DataFileError(path, "rows", "need at least one row of finite joint angles")
    bad = np.flatnonzero(np.any((Q < robot.limits.lower_rad - 1e-9) | (Q > robot.limits.upper_rad + 1e-9), axis=1))
    if bad.size:
        raise DataFileError(path, f"row {bad[0] + 2}", "joint angles outside the joint limits")
    return Q


def tcp_positions(chain: cd.Chain, robot: RobotModel, Q: np.ndarray) -> np.ndarray:
    """TCP positions (N, 3) in the base frame from the batched chain kinematics."""
    kin = cd.kinematics(chain, Q)
    p_tcp_flange = np.asarray(robot.transform_tcp_to_flange.translation, float)
    return kin.o_flange + kin.R_flange @ p_tcp_flange


def sample_region(robot: RobotModel, region: WorkingRegion, n: int, rng: np.random.Generator,
                  chain: cd.Chain | None = None, visibility: bool = False,
                  margins: cd.FilterMargins | None = None, max_batches: int = 60,
                  batch: int = 50_000) -> np.ndarray:
    """``n`` random collision-free configurations with the TCP in the region (module docstring);
    with ``visibility`` also predicted visible to the tracker of ``chain``. Explicit working poses
    are returned as given (visibility-filtered when asked)."""
    chain = chain or cd.chain_from_robot(robot)
    if region.configurations is not None:
        Q = region.configurations
        if visibility:
            ok, _ = cd.filter_configurations(chain, Q, margins, visibility=True)
            Q = Q[ok]
        return Q[:n] if len(Q) > n else Q
    out, have = [], 0
    for _ in range(max_batches):
        Q = _draw_near_region(chain, robot, region, batch, rng)
        p = tcp_positions(chain, robot, Q)
        Q = Q[np.all((p >= region.lower_m) & (p <= region.upper_m), axis=1)]
        if len(Q):
            ok, _ = cd.filter_configurations(chain, Q, margins or cd.FilterMargins(0.0, 0.0, 0.0),
                                             visibility=visibility)
            out.append(Q[ok])
            have += int(ok.sum())
        if have >= n:
            break
    if have == 0:
        what = "visible to the tracker and " if visibility else ""
        raise InfeasibleError(None, "calibration.working_region",
                              f"no collision-free configuration {what}with the TCP in the {region.describe()}")
    return np.concatenate(out)[:n]


def _draw_near_region(chain: cd.Chain, robot: RobotModel, region: WorkingRegion, batch: int, rng: np.random.Generator,
                      per_prefix: int = 16) -> np.ndarray:
    """Uniform joint configurations, drawn so that most have the TCP near the region: prefixes
    ``q_1..q_k`` (k = min(3, nq - 1)) are kept when the origin of joint k+1 is within the reach of the
    rest of the chain (sum of the remaining placement offsets, flange and TCP) of the box, then
    ``per_prefix`` uniform suffixes are drawn for each kept prefix. The kept prefixes are a superset
    of those that can reach the box, so the result is still uniform over the configurations whose
    TCP lies in it (rejection sampling with a necessary condition first)."""
    k = min(3, chain.nq - 1)
    reach = (sum(np.linalg.norm(chain.p_place[i]) for i in range(k + 1, chain.nq)) + np.linalg.norm(chain.flange_p)
             + np.linalg.norm(np.asarray(robot.transform_tcp_to_flange.translation, float)))
    pre = rng.uniform(chain.lower, chain.upper, size=(batch // per_prefix, chain.nq))
    o = cd.kinematics(chain, pre).opre[:, k]
    gap = np.maximum(np.maximum(region.lower_m - o, o - region.upper_m), 0.0)
    pre = pre[np.linalg.norm(gap, axis=1) <= reach + 1e-9]
    Q = np.repeat(pre, per_prefix, axis=0)
    Q[:, k:] = rng.uniform(chain.lower[k:], chain.upper[k:], size=(len(Q), chain.nq - k))
    return Q


def tcp_jacobian(mm: MeasurementModel, Q: np.ndarray, basis: np.ndarray, frame: str | None = None) -> np.ndarray:
    """Stacked TCP-position Jacobian rows ``(3 n_w, p)`` wrt the identifiable parameters ``theta``
    (exact CasADi AD at the nominal parameters, one mapped call).

    Tracker and reflector parameters do not move the TCP. A basis with compliance rows
    (elastostatic ``mm``) gets the TCP's gravity deflection: ``q_link = q - c g(q)`` gives
    ``dp/dc_j = -g_j(q) dp/dq_j`` (the ``j{j}.dq`` column) with ``g`` the gravity torques of ``mm``'s
    dynamic model without payload (the arm in its working region)."""
    Q = np.atleast_2d(np.asarray(Q, float))
    f = mm.sym.fk_position_jacobian(frame or mm.robot.frame_tcp).map(len(Q))
    J_kin = np.asarray(f(Q.T, np.zeros(mm.n_kin))[0]).reshape(3, len(Q), mm.n_kin).transpose(1, 0, 2)
    P = np.asarray(basis, float)
    out = J_kin @ P[mm.sl_kin]
    if mm.compliance and P.shape[0] == mm.n:
        dq = [mm.names.index(f"j{i}.dq") for i in range(1, mm.nq + 1)]
        J_c = -mm.static_torques(Q)[:, None, :] * J_kin[:, :, dq]
        out = out + J_c @ P[mm.sl_compliance]
    return out.reshape(-1, P.shape[1])


def reflector_jacobian(mm: MeasurementModel, Q: np.ndarray, basis: np.ndarray, T_tb=None) -> np.ndarray:
    """Stacked Jacobian rows ``(3 n_w, p)`` of the reflector position in the tracker frame (the
    reading a held-out measurement compares) at the configurations ``Q``, nominal parameters, tracker
    pose ``T_tb`` (None: robot.yaml's nominal one), wrt ``theta`` (compliances: the gravity
    deflection of the arm without payload)."""
    T = mm.robot.tracker.transform_tracker_to_base if T_tb is None else T_tb
    _, J = mm.jacobian(np.atleast_2d(np.asarray(Q, float)), np.zeros(mm.n), T, basis)
    return J.reshape(-1, J.shape[2])


def task_space_spec(mm: MeasurementModel, Qw: np.ndarray, basis: np.ndarray, figure: str = "tcp",
                    Qv: np.ndarray | None = None) -> ix.IndexSpec:
    """The ``V`` index over the working configurations ``Qw`` on ``figure`` (:data:`DESIGN_FIGURES`):
    the TCP, the reflector in the tracker frame, or both (``W = (W_tcp + W_reflector) / 2``, the
    mean of the two points' predicted variances).

    ``Qv``: the working configurations the tracker sees (:func:`verifiable_configurations`), where
    the reflector term is taken (None: ``Qw``). A held-out reading verifies the reflector only
    where the beam reaches it, and there the arm's orientations are those facing the tracker, a
    different part of the region's orientations than ``Qw``'s; the reflector rows are scaled by
    ``sqrt(n_w / n_v)`` so that ``W_reflector = sum_v J_v^T J_v / n_v`` whatever the two counts."""
    if figure not in DESIGN_FIGURES:
        raise ValueError(f"design figure must be one of {DESIGN_FIGURES}, got {figure!r}")
    Qv = Qw if Qv is None or len(Qv) == 0 else Qv
    rows = []
    if "tcp" in figure.split("+"):
        rows.append(tcp_jacobian(mm, Qw, basis))
    if "reflector" in figure.split("+"):
        rows.append(math.sqrt(len(Qw) / len(Qv)) * reflector_jacobian(mm, Qv, basis))
    return ix.IndexSpec("V", working_jacobian=np.vstack(rows), n_working=len(rows) * len(Qw))


#: margins of a verifiable working pose: those of the held-out poses (collision margin of the run,
#: 1 degree of incidence, 5 mm of beam clearance; :func:`pipeline.calibration.measure.heldout_measurements`)
VERIFIABLE_INCIDENCE_MARGIN_RAD = math.radians(1.0)
VERIFIABLE_BEAM_MARGIN_M = 0.005


def verifiable_configurations(robot: RobotModel, region: WorkingRegion, n: int, rng: np.random.Generator,
                              collision_margin_m: float) -> np.ndarray | None:
    """Up to ``n`` working configurations of ``region`` that the tracker at its nominal pose sees
    (the held-out poses' margins), where held-out readings can verify the reflector; None when the
    tracker sees no pose of the region."""
    margins = cd.FilterMargins(collision_margin_m, VERIFIABLE_INCIDENCE_MARGIN_RAD, VERIFIABLE_BEAM_MARGIN_M)
    try:
        Qv = sample_region(robot, region, n, rng, visibility=True, margins=margins)
    except InfeasibleError:
        return None
    return Qv if len(Qv) else None


def tcp_part(spec: ix.IndexSpec, figure: str) -> ix.IndexSpec | None:
    """The TCP-only ``V`` index contained in a :func:`task_space_spec` of ``figure`` (its first
    ``3 n_w`` rows); None when the figure has no TCP rows."""
    if figure == "tcp":
        return spec
    if figure != "tcp+reflector":
        return None
    n_w = spec.n_working // 2
    return ix.IndexSpec("V", working_jacobian=np.asarray(spec.working_jacobian)[: 3 * n_w], n_working=n_w)


def predicted_tcp_rms_m(spec: ix.IndexSpec, M: np.ndarray) -> float:
    """Predicted RMS TCP position error over the working configurations, ``sqrt(trace(W M^-1))``
    (inf for a singular ``M``)."""
    ev = np.linalg.eigvalsh(M)
    if ev[0] <= 1e-12 * max(ev[-1], 1e-300):
        return math.inf
    return math.sqrt(max(float(np.trace(np.linalg.solve(M, spec.weight_matrix(M.shape[0])))), 0.0))


def check_task_fields(cfg, source: str = "config") -> None:
    """Robot-independent checks of the working-region fields of a calibration ``Config``."""
    def bad(key: str, problem: str) -> ConfigError:
        return ConfigError(source, f"calibration.{key}", problem)

    if cfg.design_figure not in DESIGN_FIGURES:
        raise bad("design_figure", f"must be one of {DESIGN_FIGURES}, got {cfg.design_figure!r}")
    if cfg.working_region not in WORKING_REGIONS:
        raise bad("working_region", f"must be one of {WORKING_REGIONS}, got {cfg.working_region!r}")
    if cfg.working_region == "box":
        box = cfg.working_box_m
        ok = (isinstance(box, list) and len(box) == 2
              and all(isinstance(r, list) and len(r) == 3 for r in box))
        arr = np.asarray(box, float) if ok else None
        if not ok or not np.all(np.isfinite(arr)) or not np.all(arr[1] > arr[0]):
            raise bad("working_box_m", f"working_region box needs [[xmin, ymin, zmin], [xmax, ymax, zmax]] "
                      f"(m, max > min), got {box!r}")
    if cfg.working_region == "csv" and not cfg.working_csv:
        raise bad("working_csv", "working_region csv needs a file of working poses (columns q1..qn, rad)")
    for key in ("n_region_configurations", "design_table_heldout"):
        if getattr(cfg, key) < 1:
            raise bad(key, f"must be >= 1, got {getattr(cfg, key)}")
    repeats = getattr(cfg, "design_table_repeats", 0)
    if isinstance(repeats, bool) or not isinstance(repeats, int) or not 0 <= repeats <= 100:
        raise bad("design_table_repeats", f"must be an integer in [0, 100], got {repeats!r}")


def default_region(robot: RobotModel) -> WorkingRegion:
    """The ISO 9283 cube the run uses by default for ``robot``: ``control.iso`` of the robot's
    ``run_defaults`` (robot.yaml), else the control stage's defaults (for callers without a run
    configuration: studies, notebooks), else the cube derived from the model
    (:func:`pipeline.robot.defaults.iso_or_derived`)."""
    iso = IsoPathConfig()
    centre, edge = iso.centre_m, iso.edge_m
    try:
        data = load_yaml(Path(robot.spec.path).read_text(encoding="utf-8")) or {}
        section = ((data.get("run_defaults") or {}).get("control") or {}).get("iso") or {}
        centre, edge = section.get("centre_m", centre), section.get("edge_m", edge)
    except (OSError, AttributeError, YAMLError):
        pass
    if centre is None or edge is None:
        iso = iso_or_derived(robot, IsoPathConfig(centre_m=centre, edge_m=edge))
        centre, edge = iso.centre_m, iso.edge_m
    c = np.asarray(centre, float)
    return WorkingRegion("ISO 9283 cube", c - 0.5 * float(edge), c + 0.5 * float(edge))


def region_of_run(run, cfg, robot: RobotModel) -> WorkingRegion:
    """The working region of a run: ``control.iso`` of the run configuration for ``iso_cube``."""
    iso = getattr(getattr(run, "control", None), "iso", None)
    if cfg.working_region == "iso_cube" and iso is None:
        return default_region(robot)
    if cfg.working_region == "iso_cube":
        iso = iso_or_derived(robot, iso)     # the cube the control stage derives for this robot
    return region_from_config(cfg, getattr(iso, "centre_m", None), getattr(iso, "edge_m", None), robot)
