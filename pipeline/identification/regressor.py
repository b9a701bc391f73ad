"""Numeric dynamic regressor and base parameters.

The joint torque of a rigid arm with actuators is linear in the dynamic parameters
(paper ``004_abbe750b8bbcc3aa.txt`` §2.2/§4.1, eq. of motion (4) and the linear system (28)):

    tau = Y(q, v, a) p,   p = [p_link (10 per link), Ia (nq), fv (nq), fc (nq), tau0 (nq)]

* ``p_link`` are the standard parameters of each link in Pinocchio's
  ``Inertia.toDynamicParameters`` order (m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz about
  the joint frame origin); their columns are ``pin.computeJointTorqueRegressor``.
* Actuator ``j`` (rotor inertia, viscous and Coulomb friction) acts on the motor side. With the
  gear matrix ``K`` (``q_motor = K q``, ``tau_joint = K^T tau_motor``) its joint-side columns are

      Ia_j:  K_j^T (K_j a) / K_jj^2
      fv_j:  K_j^T (K_j v) / K_jj^2
      fc_j:  K_j^T tanh(K_j v / (|K_jj| w)) / |K_jj|

  where ``K_j`` is row ``j`` of ``K`` and ``w`` the Coulomb smoothing width (rad/s, joint side;
  ``w = 0`` gives ``sign``). The parameters are therefore *joint-side equivalents*
  (``Ia_j = K_jj^2 J_motor``): for a diagonal ``K`` the columns reduce to ``a_j``, ``v_j``,
  ``tanh(v_j / w)`` on joint ``j``, the layout of ``SymbolicRobot.dynamic_parameter_names``.
  For the Stäubli TX40 (motor 6 drives axes 5 and 6, ``K[5, 4] = N6``) motor 6 loads both
  joints with ``a5 + a6``.
* ``tau0`` are constant torque offsets per joint.

Base parameters (Gautier 1990; Khalil & Dombre) are found by a column-pivoted QR of the regressor
stacked over random states: ``Y P = Q R``; columns whose ``|R_kk| <= tol * |R_00|`` are dependent.
With ``R = [[R1, R2], [0, ~0]]`` the base parameters are ``beta = p_1 + R1^-1 R2 p_2``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.linalg

from pipeline.core.blas import single_thread_blas
from pipeline.core.errors import DataFileError
from pipeline.robot.friction import smooth_sign

LINK_PARAMETER_NAMES: tuple[str, ...] = (
    "m",
    "mx",
    "my",
    "mz",
    "Ixx",
    "Ixy",
    "Iyy",
    "Ixz",
    "Iyz",
    "Izz",
)
ACTUATOR_PARAMETER_NAMES: tuple[str, ...] = ("Ia", "fv", "fc", "off")

#: relative tolerance on |R_kk| / |R_00| of the pivoted QR below which a column is dependent
BASE_QR_TOLERANCE = 1e-8
#: columns whose norm is below this fraction of the largest are zero (round-off of a structurally
#: zero column must not become a unit column in the normalised QR)
ZERO_COLUMN_TOLERANCE = 1e-10


def parameter_names(model: pin.Model) -> list[str]:
    """Names of the standard parameters, e.g. ``"link3.Izz"``, ``"j2.fv"``."""
    names = []
    for i in range(1, model.njoints):
        link = model.names[i]
        names += [f"{link}.{p}" for p in LINK_PARAMETER_NAMES]
    for kind in ACTUATOR_PARAMETER_NAMES:
        names += [f"j{j + 1}.{kind}" for j in range(model.nv)]
    return names


def standard_parameters(
    model: pin.Model,
    rotor_inertia_kgm2: Sequence[float] | np.ndarray,
    viscous_Nms_rad: Sequence[float] | np.ndarray,
    coulomb_Nm: Sequence[float] | np.ndarray,
    offset_Nm: Sequence[float] | np.ndarray | None = None,
) -> np.ndarray:
    """Standard parameter vector of a Pinocchio model and its actuator values."""
    links = [model.inertias[i].toDynamicParameters() for i in range(1, model.njoints)]
    nv = model.nv
    off = np.zeros(nv) if offset_Nm is None else np.asarray(offset_Nm, float)
    return np.concatenate(
        [
            *links,
            np.asarray(rotor_inertia_kgm2, float),
            np.asarray(viscous_Nms_rad, float),
            np.asarray(coulomb_Nm, float),
            off,
        ]
    )


@dataclass
class RegressorModel:
    """Everything the numeric regressor needs: Pinocchio model, gear matrix, Coulomb width.

    ``model.armature`` is ignored here: rotor inertia is a column of the regressor.
    ``coulomb_width_rad_s``: the smoothing width ``w`` of the Coulomb columns ``tanh(v_m / (k w))``,
    one for all joints or one per joint (motor ``j``'s velocity ``v_m``, gear ratio ``k``).
    """

    model: pin.Model
    gear_matrix: np.ndarray
    coulomb_width_rad_s: float | np.ndarray = 0.0
    #: joints whose torque rows :meth:`stacked` keeps (measured torques); None: every joint
    rows: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.gear_matrix = np.asarray(self.gear_matrix, float)
        nv = self.model.nv
        if self.gear_matrix.shape != (nv, nv):
            raise DataFileError(
                None, "gear_matrix", f"shape {self.gear_matrix.shape}, expected ({nv}, {nv})"
            )
        if np.any(np.abs(np.diag(self.gear_matrix)) < 1e-12):
            raise DataFileError(None, "gear_matrix", "zero on the diagonal")
        self.data = self.model.createData()

    @property
    def nv(self) -> int:
        return self.model.nv

    @property
    def joint_coulomb_width_rad_s(self) -> np.ndarray:
        """(nv,) the Coulomb smoothing width of every joint."""
        return np.broadcast_to(np.asarray(self.coulomb_width_rad_s, float), (self.nv,)).copy()

    @property
    def row_coulomb_width_rad_s(self) -> np.ndarray:
        """(n_rows,) the Coulomb smoothing width of the joints of the torque rows (:attr:`rows`)."""
        w = self.joint_coulomb_width_rad_s
        return w if self.rows is None else w[self.rows]

    @property
    def n_rows(self) -> int:
        """Rows per sample of :meth:`stacked`."""
        return self.nv if self.rows is None else len(self.rows)

    @property
    def n_parameters(self) -> int:
        return 10 * (self.model.njoints - 1) + 4 * self.model.nv

    @property
    def names(self) -> list[str]:
        return parameter_names(self.model)

    def actuator_columns(self, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """(nv, 4 nv) columns of rotor inertia, viscous, Coulomb friction and offsets."""
        K = self.gear_matrix
        nv = self.nv
        kd = np.abs(np.diag(K))
        out = np.zeros((nv, 4 * nv))
        vm = K @ v
        am = K @ a
        s = smooth_sign(vm, kd * self.joint_coulomb_width_rad_s)
        for j in range(nv):
            kj = K[j]
            out[:, j] = kj * am[j] / kd[j] ** 2
            out[:, nv + j] = kj * vm[j] / kd[j] ** 2
            out[:, 2 * nv + j] = kj * s[j] / kd[j]
        out[:, 3 * nv :] = np.eye(nv)
        return out

    def regressor(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """(nv, n_parameters) regressor at one state."""
        y_links = pin.computeJointTorqueRegressor(self.model, self.data, q, v, a)
        return np.hstack([y_links, self.actuator_columns(v, a)])

    def stacked(self, Q: np.ndarray, V: np.ndarray, A: np.ndarray) -> np.ndarray:
        """Regressor stacked sample-major: rows ``k*nv + j`` (sample k, joint j; only the joints of
        :attr:`rows` when set)."""
        Q, V, A = (np.atleast_2d(np.asarray(x, float)) for x in (Q, V, A))
        check_state_arrays(Q, V, A, self.nv)
        n, nv = Q.shape[0], self.nv
        n_link = self.n_parameters - 4 * nv
        out = np.empty((n, nv, self.n_parameters))
        model, data = self.model, self.data
        for k in range(n):
            out[k, :, :n_link] = pin.computeJointTorqueRegressor(model, data, Q[k], V[k], A[k])
        # actuator columns for all samples at once (same formulas as actuator_columns)
        K = self.gear_matrix
        kd = np.abs(np.diag(K))
        vm, am = V @ K.T, A @ K.T  # (n, nv) motor side
        # column j of group g on joint i: K[j, i] * f_g(sample, j)
        out[:, :, n_link : n_link + nv] = (am / kd**2)[:, None, :] * K.T[None]
        out[:, :, n_link + nv : n_link + 2 * nv] = (vm / kd**2)[:, None, :] * K.T[None]
        out[:, :, n_link + 2 * nv : n_link + 3 * nv] = self.coulomb_block(V, self.joint_coulomb_width_rad_s)
        out[:, :, n_link + 3 * nv :] = np.eye(nv)[None]
        if self.rows is not None:
            out = out[:, self.rows]
        return out.reshape(n * self.n_rows, self.n_parameters)

    @property
    def coulomb_columns(self) -> slice:
        """The Coulomb columns of the standard regressor (one per joint, :meth:`coulomb_block`)."""
        n_link = self.n_parameters - 4 * self.nv
        return slice(n_link + 2 * self.nv, n_link + 3 * self.nv)

    def coulomb_block(self, V: np.ndarray, width_rad_s: np.ndarray) -> np.ndarray:
        """(n, nv, nv) the Coulomb columns at joint velocities ``V`` (n, nv) with the per-joint smoothing
        widths ``width_rad_s`` (nv,): on joint ``i``, column ``j`` is ``K[j, i] tanh(v_m,j / (k_j w_j)) / k_j``
        (all rows, before :attr:`rows`)."""
        K = self.gear_matrix
        kd = np.abs(np.diag(K))
        s = smooth_sign(np.atleast_2d(V) @ K.T, kd * np.asarray(width_rad_s, float))
        return (s / kd)[:, None, :] * K.T[None]

    def torques(self, Q: np.ndarray, V: np.ndarray, A: np.ndarray, p: np.ndarray) -> np.ndarray:
        """(N, n_rows) joint torques ``Y p`` (the joints of :attr:`rows`)."""
        return (self.stacked(Q, V, A) @ p).reshape(-1, self.n_rows)


def check_state_arrays(Q: np.ndarray, V: np.ndarray, A: np.ndarray, nv: int, file=None) -> None:
    """Raise :class:`DataFileError` on mismatched shapes or non-finite values."""
    for name, x in (("q", Q), ("v", V), ("a", A)):
        if x.ndim != 2 or x.shape[1] != nv:
            raise DataFileError(file, name, f"shape {x.shape}, expected (N, {nv})")
        if not np.all(np.isfinite(x)):
            raise DataFileError(file, name, "contains NaN or inf")
    if not (Q.shape[0] == V.shape[0] == A.shape[0]):
        raise DataFileError(
            file, "q/v/a", f"mismatched lengths {Q.shape[0]}, {V.shape[0]}, {A.shape[0]}"
        )


@dataclass
class BaseParameters:
    """Base parameters ``beta = E^T p`` of the standard parameters ``p``.

    ``independent`` are the indices of the kept standard columns (``p_1``), ``dependent`` the
    others (``p_2``); ``beta = p_1 + combination @ p_2`` and the base regressor is
    ``Y[:, independent]``. ``names``: one readable linear combination per base parameter.
    """

    independent: np.ndarray
    dependent: np.ndarray
    combination: np.ndarray  # (n_base, n_dependent) = R1^-1 R2
    standard_names: list[str]
    tolerance: float
    rank_gap: float  # |R_kk| of the last kept column / first dropped (relative)

    @property
    def n_base(self) -> int:
        return len(self.independent)

    @property
    def matrix(self) -> np.ndarray:
        """(n_standard, n_base) matrix ``E`` with ``beta = E^T p``."""
        n = len(self.standard_names)
        E = np.zeros((n, self.n_base))
        E[self.independent, np.arange(self.n_base)] = 1.0
        E[self.dependent, :] = self.combination.T
        return E

    def from_standard(self, p: np.ndarray) -> np.ndarray:
        return self.matrix.T @ np.asarray(p, float)

    def base_regressor(self, Y: np.ndarray) -> np.ndarray:
        return Y[:, self.independent]

    @property
    def set_names(self) -> list[str]:
        """Standard names of the independent columns: the identity of the base set."""
        return [self.standard_names[i] for i in self.independent]

    @property
    def names(self) -> list[str]:
        out = []
        for b, i in enumerate(self.independent):
            terms = [self.standard_names[i]]
            for c, j in zip(self.combination[b], self.dependent, strict=True):
                if abs(c) > 1e-9:
                    sign = "+" if c > 0 else "-"
                    coef = "" if abs(abs(c) - 1) < 1e-9 else f"{abs(c):.6g}*"
                    terms.append(f"{sign} {coef}{self.standard_names[j]}")
            out.append(" ".join(terms))
        return out


def base_parameters(
    reg: RegressorModel,
    rng: np.random.Generator,
    n_samples: int = 300,
    tolerance: float = BASE_QR_TOLERANCE,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
) -> BaseParameters:
    """Structural base parameters from random states (q in the limits, v, a ~ N(0, 1)).

    Pivoted QR of the stacked regressor (``scipy.linalg.qr(pivoting=True)``); the rank is the
    number of ``|R_kk| > tolerance * |R_00|``. Columns are normalised before the QR so the pivoting
    does not depend on the parameter units; columns below :data:`ZERO_COLUMN_TOLERANCE` of the
    largest norm are zero.
    """
    nv = reg.nv
    lo = -np.pi * np.ones(nv) if lower is None else np.asarray(lower)
    hi = np.pi * np.ones(nv) if upper is None else np.asarray(upper)
    Q = rng.uniform(lo, hi, size=(n_samples, nv))
    V = rng.normal(size=(n_samples, nv)) * 2.0
    A = rng.normal(size=(n_samples, nv)) * 5.0
    Y = reg.stacked(Q, V, A)
    return base_parameters_from_regressor(Y, reg.names, tolerance)


def base_parameters_from_regressor(
    Y: np.ndarray, names: list[str], tolerance: float = BASE_QR_TOLERANCE
) -> BaseParameters:
    """Base parameters of a given (well excited) regressor by pivoted QR."""
    with single_thread_blas():
        return _base_from_regressor(Y, names, tolerance)


def _base_from_regressor(Y: np.ndarray, names: list[str], tolerance: float) -> BaseParameters:
    norms = np.linalg.norm(Y, axis=0)
    zero = norms <= ZERO_COLUMN_TOLERANCE * max(norms.max(), 1e-300)
    scale = np.where(zero, 1.0, norms)
    Ys = Y / scale
    Ys[:, zero] = 0.0
    _, R, piv = scipy.linalg.qr(Ys, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > tolerance * d[0]))
    gap = float(d[rank] / d[0]) if rank < len(d) else 0.0
    # keep the pivot order's independent set but sort it to a readable (standard) order
    indep_piv, dep_piv = piv[:rank], piv[rank:]
    R1 = R[:rank, :rank]
    R2 = R[:rank, rank:]
    comb_s = scipy.linalg.solve_triangular(R1, R2)  # in scaled units
    # undo scaling: beta_s = p1_s + C_s p2_s with p_s = scale * p
    comb = comb_s * scale[dep_piv][None, :] / scale[indep_piv][:, None]
    comb[np.abs(comb) < 1e-10] = 0.0
    order = np.argsort(indep_piv)
    indep = indep_piv[order]
    comb = comb[order]
    dorder = np.argsort(dep_piv)
    return BaseParameters(
        independent=indep,
        dependent=dep_piv[dorder],
        combination=comb[:, dorder],
        standard_names=list(names),
        tolerance=tolerance,
        rank_gap=gap,
    )
