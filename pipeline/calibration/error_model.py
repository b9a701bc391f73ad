"""Error model of the tracker calibration and its identifiable parameter set.

Parameters ``x`` (all zero = nominal):

- the robot's kinematic errors of :class:`pipeline.robot.symbolic.SymbolicRobot`
  (``j{i}.dx..rz`` SE(3) offsets of each joint placement, ``j{i}.dq`` zero offsets, ``base.*``,
  ``tool.*``); optionally restricted to modified-DH directions with Hayati's parameter for parallel
  axes (``error_model="mdh_hayati"``, a linear basis ``p_kin = B x_mdh``, see :func:`mdh_basis`);
- ``tracker.dx..rz``: the tracker pose ``T_tb = T_tb0 exp6(xi)`` (``p_base = T_tb p_tracker``), with
  ``T_tb0`` the current estimate (nominal, then the registration result);
- ``reflector.dx dy dz``: reflector offset error in the reflector (= flange-aligned) frame;
- with ``compliance=True`` (elastostatic model, paper 000 Outlook): ``j{i}.c`` the torsional
  compliance of joint i (rad/(N m)); the link-side angles of a static pose are
  ``q_link = q - c * g(q)`` with ``g`` the gravity torques of the current dynamic model (the
  RobotModel's inertias: nominal, or identified) with the known payload when it is mounted.
  ``g`` is evaluated at the commanded angles (first order in ``c``; the second order is
  ``|c g'| ~ 1e-3`` of the deflection).

Measurement (tracker frame): ``y(q, x) = T_tb^-1 (p_refl(q_link, p_kin) + R_refl(q_link, p_kin) dr)``.
The identification Jacobian ``dy/dx`` is exact (CasADi AD of the SX model; paper 002 eq. 10-12,
paper 003 eq. 15).

Identifiability (paper 002 §3: SVD of the identification Jacobian; paper 003: correlations): on
many random configurations the column-normalised Jacobian is decomposed by SVD (rank = number of
singular values above ``rel_tol * s_max``; the right singular vectors of the null space show the
dependent combinations); the base set is chosen by a QR/Gram-Schmidt pass over the columns in a
stated priority order (sensor set-up first: tracker, reflector; then joint zero offsets, joint
placements, base, tool), keeping a column only if it is not in the span of the kept ones. Each
dropped parameter is reported as unidentifiable (no effect) or as combined with kept ones
(``J_j = J_B beta``), and column correlations ``|rho| > 0.999`` are listed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import pinocchio as pin

from pipeline.core.casadi_buffers import BufferedFunction
from pipeline.core.compiled_on_demand import CompiledOnDemand
from pipeline.robot import spatial_sx as sx
from pipeline.robot.model import RobotModel
from pipeline.robot.parameters import KINEMATIC_COMPONENTS
from pipeline.robot.payload import Payload, gravity_torques_Nm, with_payload
from pipeline.robot.symbolic import SymbolicRobot

TRACKER_NAMES = [f"tracker.{c}" for c in KINEMATIC_COMPONENTS]
REFLECTOR_NAMES = ["reflector.dx", "reflector.dy", "reflector.dz"]
#: suffix of the joint compliance parameters ``j{i}.c`` (rad/(N m))
COMPLIANCE_SUFFIX = ".c"
#: the modified-DH + Hayati errors of a joint placement (:func:`mdh_basis`) that turn it: the
#: twist about the previous x axis, the zero offset and Hayati's rotation about y
MDH_ROTATIONS = ("dalpha", "dtheta", "beta")
#: configuration sets whose static torques a measurement model remembers (a cross-validation fold's
#: training and held-out readings, the chunks of a larger record)
TORQUE_MEMO_SETS = 8


def is_compliance(name: str) -> bool:
    return name.startswith("j") and name.endswith(COMPLIANCE_SUFFIX)


#: the unit of each parameter component (the part of a name after its last dot)
_COMPONENT_UNITS = {"dx": "m", "dy": "m", "dz": "m", "da": "m", "dd": "m", "rx": "rad", "ry": "rad", "rz": "rad",
                    "dq": "rad", MDH_ROTATIONS[0]: "rad", MDH_ROTATIONS[1]: "rad", MDH_ROTATIONS[2]: "rad",
                    COMPLIANCE_SUFFIX[1:]: "rad/(N m)"}


def parameter_unit(name: str) -> str:
    """The unit of error parameter ``name`` (module docstring): m for offsets, rad for rotations and
    zero offsets, rad/(N m) for compliances."""
    component = name.rsplit(".", 1)[-1]
    if component not in _COMPONENT_UNITS:
        raise ValueError(f"parameter {name!r}: unknown component {component!r}")
    return _COMPONENT_UNITS[component]


def se3_to_vector(T: pin.SE3) -> np.ndarray:
    """12-vector ``[R (row-major 9), p (3)]`` fed to the CasADi measurement functions."""
    return np.concatenate([np.asarray(T.rotation).reshape(-1), np.asarray(T.translation).reshape(-1)])


class MeasurementModel:
    """CasADi measurement model of the reflector seen by the tracker, all parameters.

    ``h(q, x, T0) -> y`` and ``hj(q, x, T0) -> (y, dy/dx)``; numeric batched helpers
    :meth:`predict` and :meth:`jacobian` evaluate them on ``(N, nq)`` configurations with
    ``Function.map`` in chunks, compiled by gcc once their use pays for it
    (:class:`pipeline.core.compiled_on_demand.CompiledOnDemand`; same numbers).
    """

    def __init__(self, robot: RobotModel, sym: SymbolicRobot | None = None, chunk: int = 4096, compliance: bool = False,
                 payload: Payload | None = None, marker_points: bool = False) -> None:
        self.robot = robot
        self.sym = sym if sym is not None else SymbolicRobot(robot)
        self.nq = self.sym.nq
        self.n_kin = self.sym.n_kin
        self.compliance = bool(compliance)
        #: rows may be points at an offset ``o`` in the reflector frame (6-D readings, measure.py)
        self.marker_points = bool(marker_points)
        self.payload = payload
        self.names: list[str] = list(self.sym.kinematic_parameter_names) + TRACKER_NAMES + REFLECTOR_NAMES
        if self.compliance:
            self.names += [f"j{i}{COMPLIANCE_SUFFIX}" for i in range(1, self.nq + 1)]
        self.n = len(self.names)
        self.sl_kin = slice(0, self.n_kin)
        self.sl_tracker = slice(self.n_kin, self.n_kin + 6)
        self.sl_reflector = slice(self.n_kin + 6, self.n_kin + 9)
        self.sl_compliance = slice(self.n_kin + 9, self.n)
        self.chunk = chunk
        self.set_gravity_model(robot.model)
        q = ca.SX.sym("q", self.nq)
        x = ca.SX.sym("x", self.n)
        t0 = ca.SX.sym("T0", 12)
        tau = ca.SX.sym("tau", self.nq)
        offset = ca.SX.sym("o", 3)
        extra = ([tau] if self.compliance else []) + ([offset] if self.marker_points else [])
        q_link = q - x[self.sl_compliance] * tau if self.compliance else q
        pos, rot = self.sym.fk_expression(self.robot.frame_reflector, q_link, x[self.sl_kin])
        marker = x[self.sl_reflector] + offset if self.marker_points else x[self.sl_reflector]
        p_base = pos + ca.mtimes(rot, marker)
        R0 = ca.reshape(t0[:9], 3, 3).T  # row-major
        Rx, px = sx.exp6(x[self.sl_tracker])
        R = ca.mtimes(R0, Rx)
        p = ca.mtimes(R0, px) + t0[9:12]
        y = ca.mtimes(R.T, p_base - p)
        self.h = ca.Function("h", [q, x, t0, *extra], [y])
        self.hj = ca.Function("hj", [q, x, t0, *extra], [y, ca.jacobian(y, x)])
        # base-frame reflector position and its configuration Jacobian (for predictions)
        self.base_pos = ca.Function("pb", [q, x, *extra], [p_base, rot])
        # sensitivity of the reading to the gravity torques (gravity-model uncertainty)
        if self.compliance:
            self.ht = ca.Function("ht", [q, x, t0, *extra], [ca.jacobian(y, tau)])
        self._functions: dict[str, CompiledOnDemand] = {}

    @property
    def gravity_model(self) -> pin.Model:
        """The model whose inertias give the gravity torques (the robot's own, or an upstream one)."""
        return self._gravity_model

    def set_gravity_model(self, model: pin.Model) -> None:
        """Take the gravity torques from ``model``'s inertias (e.g. an identified model)."""
        self._gravity_model = model
        self._payload_model = with_payload(model, self.robot.frame_flange, self.payload)
        #: torques of the last few configuration sets (an iterative fit evaluates the same readings
        #: again at every step); emptied with a new gravity model
        self._torque_memo: dict[tuple[tuple[int, ...], bytes, bytes | None], np.ndarray] = {}

    def static_torques(self, Q: np.ndarray, mounted: np.ndarray | None = None) -> np.ndarray:
        """``(N, nq)`` gravity torques of the current dynamic model, with the payload where ``mounted``
        (remembered for the last :data:`TORQUE_MEMO_SETS` sets of up to ``chunk`` configurations)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        m = None if mounted is None else np.asarray(mounted, bool)
        key = (Q.shape, Q.tobytes(), None if m is None else m.tobytes()) if len(Q) <= self.chunk else None
        if key is not None and key in self._torque_memo:
            return self._torque_memo[key].copy()
        tau = gravity_torques_Nm(self._gravity_model, Q)
        if m is not None and np.any(m):
            if self.payload is None:
                raise ValueError("payload readings but the measurement model has no payload")
            tau[m] = gravity_torques_Nm(self._payload_model, Q[m])
        if key is not None:
            if len(self._torque_memo) >= TORQUE_MEMO_SETS:
                del self._torque_memo[next(iter(self._torque_memo))]
            self._torque_memo[key] = tau.copy()
        return tau

    def _extra(self, Q: np.ndarray, mounted: np.ndarray | None, offsets: np.ndarray | None) -> list[np.ndarray]:
        out = [self.static_torques(Q, mounted).T] if self.compliance else []
        if self.marker_points:
            out.append(np.zeros((3, len(Q))) if offsets is None else np.asarray(offsets, float).T)
        return out

    def _on_demand(self, name: str) -> CompiledOnDemand:
        if name not in self._functions:
            f = {"h": self.h, "hj": self.hj, "pb": self.base_pos, "ht": getattr(self, "ht", None)}[name]
            self._functions[name] = CompiledOnDemand(f, subdir="measurement_model")
        return self._functions[name]

    def _mapped(self, name: str, n: int) -> BufferedFunction:
        return self._on_demand(name).mapped(n)

    def expect_readings(self, readings: int) -> None:
        """Announce at least ``readings`` evaluations of both :meth:`predict` and :meth:`jacobian`
        (readings times evaluations) to come: their compiled code is built as soon as the use known
        so far pays for it (:meth:`pipeline.core.compiled_on_demand.CompiledOnDemand.expect`)."""
        for name in ("h", "hj"):
            self._on_demand(name).expect(readings)

    def predict(self, Q: np.ndarray, x: np.ndarray, T0: pin.SE3, mounted: np.ndarray | None = None,
                offsets: np.ndarray | None = None) -> np.ndarray:
        """Predicted tracker-frame positions ``(N, 3)`` (``mounted``: rows measured with the payload)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        t0 = se3_to_vector(T0)
        out = np.empty((len(Q), 3))
        for s in range(0, len(Q), self.chunk):
            Qc = Q[s : s + self.chunk]
            f = self._mapped("h", len(Qc))
            mc = None if mounted is None else mounted[s : s + self.chunk]
            oc = None if offsets is None else offsets[s : s + self.chunk]
            out[s : s + len(Qc)] = f(Qc.T, x, t0, *self._extra(Qc, mc, oc))[0].T
        return out

    def jacobian(self, Q: np.ndarray, x: np.ndarray, T0: pin.SE3,
                 basis: np.ndarray | None = None, mounted: np.ndarray | None = None,
                 offsets: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Predictions ``(N, 3)`` and Jacobian blocks ``(N, 3, p)`` wrt ``theta`` where
        ``x = x_current + basis @ theta`` (``basis`` (n, p); None: all parameters)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        t0 = se3_to_vector(T0)
        P = np.eye(self.n) if basis is None else np.asarray(basis, float)
        Y = np.empty((len(Q), 3))
        J = np.empty((len(Q), 3, P.shape[1]))
        for s in range(0, len(Q), self.chunk):
            Qc = Q[s : s + self.chunk]
            n = len(Qc)
            mc = None if mounted is None else mounted[s : s + self.chunk]
            oc = None if offsets is None else offsets[s : s + self.chunk]
            y, jac = self._mapped("hj", n)(Qc.T, x, t0, *self._extra(Qc, mc, oc))
            Y[s : s + n] = y.T
            jac = jac.reshape(3, n, self.n).transpose(1, 0, 2)  # hcat of (3 x n_x) blocks
            J[s : s + n] = jac @ P
        return Y, J

    def torque_jacobian(self, Q: np.ndarray, x: np.ndarray, T0: pin.SE3, mounted: np.ndarray | None = None,
                        offsets: np.ndarray | None = None) -> np.ndarray:
        """``(N, 3, nq)`` sensitivity ``dy/dtau = -(dy/dq_link) diag(c)`` of the reading to the static
        joint torques (elastostatic model only; zero compliances give zero)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        if not self.compliance:
            return np.zeros((len(Q), 3, self.nq))
        t0 = se3_to_vector(T0)
        out = np.empty((len(Q), 3, self.nq))
        for s in range(0, len(Q), self.chunk):
            Qc = Q[s : s + self.chunk]
            n = len(Qc)
            mc = None if mounted is None else mounted[s : s + self.chunk]
            oc = None if offsets is None else offsets[s : s + self.chunk]
            jac = self._mapped("ht", n)(Qc.T, x, t0, *self._extra(Qc, mc, oc))[0]
            out[s : s + n] = jac.reshape(3, n, self.nq).transpose(1, 0, 2)
        return out

    def base_positions(self, Q: np.ndarray, x: np.ndarray, mounted: np.ndarray | None = None,
                       offsets: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Reflector positions ``(N, 3)`` and rotations ``(N, 3, 3)`` in the robot base frame."""
        Q = np.atleast_2d(np.asarray(Q, float))
        P = np.empty((len(Q), 3))
        R = np.empty((len(Q), 3, 3))
        for s in range(0, len(Q), self.chunk):
            Qc = Q[s : s + self.chunk]
            n = len(Qc)
            mc = None if mounted is None else mounted[s : s + self.chunk]
            oc = None if offsets is None else offsets[s : s + self.chunk]
            p, r = self._mapped("pb", n)(Qc.T, x, *self._extra(Qc, mc, oc))
            P[s : s + n] = p.T
            R[s : s + n] = r.reshape(3, n, 3).transpose(1, 0, 2)
        return P, R


def priority_order(names: list[str]) -> list[int]:
    """Columns in the order the base set is built: tracker, reflector, joint zero offsets,
    joint compliances, joint placements, base, tool (sensor set-up first; robot base frame and
    tool kept nominal when they cannot be told apart from the set-up)."""
    groups = [
        [i for i, n in enumerate(names) if n.startswith("tracker.")],
        [i for i, n in enumerate(names) if n.startswith("reflector.")],
        [i for i, n in enumerate(names) if n.startswith("j") and n.endswith(".dq")],
        [i for i, n in enumerate(names) if is_compliance(n)],
        [i for i, n in enumerate(names) if n.startswith("j") and not n.endswith(".dq") and not is_compliance(n)],
        [i for i, n in enumerate(names) if n.startswith("base.")],
        [i for i, n in enumerate(names) if n.startswith("tool.")],
    ]
    order = [i for g in groups for i in g]
    rest = [i for i in range(len(names)) if i not in order]
    return order + rest


@dataclass
class IdentifiabilityReport:
    """Result of :func:`identifiability`."""

    names: list[str]
    identifiable: list[int]              # base-set column indices into ``names`` (model space)
    singular_values: np.ndarray          # of the column-normalised Jacobian
    rank: int
    unidentifiable: list[str]            # no effect on the measurements
    combined: dict[str, list[tuple[str, float]]]  # dropped -> [(kept name, coefficient)]
    null_space: list[list[tuple[str, float]]]     # SVD null-space vectors (largest components)
    correlated_pairs: list[tuple[str, str, float]]   # |column correlation| > threshold
    high_covariance_correlations: list[tuple[str, str, float]] = field(default_factory=list)

    @property
    def identifiable_names(self) -> list[str]:
        return [self.names[i] for i in self.identifiable]

    def as_dict(self) -> dict:
        return {
            "n_parameters": len(self.names),
            "rank": int(self.rank),
            "identifiable": self.identifiable_names,
            "unidentifiable": self.unidentifiable,
            "combined": {k: [[n, float(c)] for n, c in v] for k, v in self.combined.items()},
            "correlated_pairs": [[a, b, float(r)] for a, b, r in self.correlated_pairs],
            "high_covariance_correlations": [[a, b, float(r)] for a, b, r in
                                             self.high_covariance_correlations],
            "singular_values_min_max": [float(self.singular_values[-1]), float(self.singular_values[0])],
        }

    def markdown(self, max_rows: int = 60) -> str:
        lines = [f"Identifiability: {self.rank} of {len(self.names)} parameters identifiable "
                 f"(SVD rank of the column-normalised identification Jacobian).", "",
                 f"- identifiable: {', '.join(self.identifiable_names)}",
                 f"- unidentifiable (no effect on the tracker readings): "
                 f"{', '.join(self.unidentifiable) or 'none'}", "",
                 "| dropped parameter | combined with (coefficient) |", "|---|---|"]
        for k, v in list(self.combined.items())[:max_rows]:
            lines.append(f"| {k} | " + ", ".join(f"{n} ({c:+.3g})" for n, c in v) + " |")
        if self.correlated_pairs:
            lines += ["", "| column correlation (paper 003) | rho |", "|---|---|"]
            for a, b, r in self.correlated_pairs[:max_rows]:
                lines.append(f"| {a} / {b} | {r:+.4f} |")
        return "\n".join(lines)


def identifiability(J: np.ndarray, names: list[str], rel_tol: float = 1e-7,
                    corr_threshold: float = 0.999, order: list[int] | None = None) -> IdentifiabilityReport:
    """Identifiable base set from a stacked identification Jacobian ``J`` (rows, n).

    See the module docstring. ``rel_tol`` is relative to the largest singular value of the
    column-normalised Jacobian (exact dependencies give ~1e-14).
    """
    J = np.asarray(J, float)
    n = J.shape[1]
    norms = np.linalg.norm(J, axis=0)
    scale = np.where(norms > 1e-12 * max(norms.max(), 1e-300), norms, np.inf)
    Jn = J / scale
    s = np.linalg.svd(Jn, compute_uv=False)
    _, _, Vt = np.linalg.svd(Jn, full_matrices=Jn.shape[0] < n)
    tol = rel_tol * s[0]
    rank = int(np.sum(s > tol))
    zero_cols = [i for i in range(n) if not np.isfinite(scale[i])]
    # ordered Gram-Schmidt pass (QR without pivoting on the priority order)
    order = priority_order(names) if order is None else order
    basis: list[np.ndarray] = []
    kept: list[int] = []
    for i in order:
        if i in zero_cols:
            continue
        c = Jn[:, i].copy()
        for _ in range(2):  # re-orthogonalise for stability
            for b in basis:
                c -= (b @ c) * b
        r = np.linalg.norm(c)
        if r > np.sqrt(tol):   # residual of a unit column; dependent columns give ~1e-13
            basis.append(c / r)
            kept.append(i)
    if len(kept) != rank:
        # fall back to the SVD rank by trimming the weakest kept columns (near-dependencies)
        while len(kept) > rank:
            Jb = Jn[:, kept]
            sub = [np.linalg.svd(np.delete(Jb, k, axis=1), compute_uv=False)[-1] for k in range(len(kept))]
            kept.pop(int(np.argmax(sub)))
    kept_sorted = sorted(kept)
    Jb = Jn[:, kept_sorted]
    combined: dict[str, list[tuple[str, float]]] = {}
    for i in range(n):
        if i in kept_sorted or i in zero_cols:
            continue
        beta, *_ = np.linalg.lstsq(Jb, Jn[:, i], rcond=None)
        # coefficients in parameter units: x_i moves the readings like sum beta_k * (s_i / s_k) x_k
        coef = beta * norms[i] / norms[kept_sorted]
        big = np.argsort(-np.abs(beta))
        combined[names[i]] = [(names[kept_sorted[k]], float(coef[k])) for k in big if abs(beta[k]) > 1e-6][:6]
    null_space = []
    for v in Vt[rank:]:
        big = np.argsort(-np.abs(v))[:6]
        null_space.append([(names[k], float(v[k])) for k in big if abs(v[k]) > 1e-3])
    # paper 003 style correlations between columns (cosine of the angle)
    nz = [i for i in range(n) if i not in zero_cols]
    C = Jn[:, nz].T @ Jn[:, nz]
    pairs = []
    for a in range(len(nz)):
        for b in range(a + 1, len(nz)):
            if abs(C[a, b]) > corr_threshold:
                pairs.append((names[nz[a]], names[nz[b]], float(C[a, b])))
    # correlations of the base-set covariance (identifiable but poorly separated)
    cov = np.linalg.inv(Jb.T @ Jb)
    d = np.sqrt(np.diag(cov))
    rho = cov / np.outer(d, d)
    high = [(names[kept_sorted[a]], names[kept_sorted[b]], float(rho[a, b]))
            for a in range(len(kept_sorted)) for b in range(a + 1, len(kept_sorted)) if abs(rho[a, b]) > 0.95]
    return IdentifiabilityReport(list(names), kept_sorted, s, rank, [names[i] for i in zero_cols],
                                 combined, null_space, pairs, high)


def parameter_basis(report: IdentifiabilityReport, n_full: int, model_basis: np.ndarray | None = None
                    ) -> np.ndarray:
    """``P`` (n_full, p) with ``x = P theta`` for the identifiable parameters ``theta``."""
    B = np.eye(n_full) if model_basis is None else np.asarray(model_basis, float)
    return B[:, report.identifiable]


def random_configurations(robot: RobotModel, n: int, rng: np.random.Generator) -> np.ndarray:
    """Uniform random joint vectors inside the limits."""
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    return rng.uniform(lo, hi, size=(n, robot.nq))


def mdh_basis(robot: RobotModel, names: list[str], parallel_tol_rad: float = 1e-6) -> tuple[np.ndarray, list[str]]:
    """Basis ``B`` (n_full x n_mdh) mapping modified-DH errors to the SE(3) placement errors.

    For a placement ``M_i = Rx(alpha) Tx(a) Rz(theta) Tz(d)`` the right-multiplied twist of each
    MDH error is ``Ad_{(rest)^-1}`` of the elementary twist (exact: ``M_i exp(B dx)`` moves along
    the MDH parameter). For axes parallel to the previous one (|alpha| ~ 0) Hayati's rotation
    ``beta`` about the y axis replaces ``d`` (Hayati 1983; paper 003 §1). Tracker, reflector, joint
    offsets, base and tool parameters are kept as they are. Raises ValueError if a placement is
    not of MDH form.
    """
    n_full = len(names)
    cols: list[np.ndarray] = []
    out_names: list[str] = []
    model = robot.model
    for i in range(1, model.njoints):
        M = model.jointPlacements[i]
        R, p = M.rotation, M.translation
        alpha = np.arctan2(-R[1, 2], R[2, 2])
        theta = np.arctan2(-R[0, 1], R[0, 0])
        a = p[0]
        d = float(-np.sin(alpha) * p[1] + np.cos(alpha) * p[2])
        Mr = pin.SE3(pin.utils.rotate("x", alpha), np.zeros(3)) * pin.SE3(np.eye(3), np.array([a, 0, 0])) * \
            pin.SE3(pin.utils.rotate("z", theta), np.zeros(3)) * pin.SE3(np.eye(3), np.array([0, 0, d]))
        if not np.allclose(Mr.homogeneous, M.homogeneous, atol=1e-9):
            raise ValueError(f"joint {i} placement is not of modified-DH form")
        Tz = pin.SE3(np.eye(3), np.array([0, 0, d]))
        RzTz = pin.SE3(pin.utils.rotate("z", theta), np.zeros(3)) * Tz
        TxRzTz = pin.SE3(np.eye(3), np.array([a, 0, 0])) * RzTz
        e = np.eye(6)
        twists = {
            "dd": e[2],
            MDH_ROTATIONS[1]: e[5],
            "da": RzTz.inverse().toActionMatrix() @ e[0],
            MDH_ROTATIONS[0]: TxRzTz.inverse().toActionMatrix() @ e[3],
        }
        if abs(np.sin(alpha)) < parallel_tol_rad:  # parallel to the previous axis: Hayati
            twists.pop("dd")
            twists[MDH_ROTATIONS[2]] = RzTz.inverse().toActionMatrix() @ e[4]
        base = names.index(f"j{i}.dx")
        for k, tw in twists.items():
            col = np.zeros(n_full)
            col[base : base + 6] = tw
            cols.append(col)
            out_names.append(f"j{i}.{k}")
    for j, nm in enumerate(names):
        if nm.startswith("j") and nm.split(".")[1] in KINEMATIC_COMPONENTS:
            continue
        col = np.zeros(n_full)
        col[j] = 1.0
        cols.append(col)
        out_names.append(nm)
    return np.stack(cols, axis=1), out_names
