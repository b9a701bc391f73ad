"""The excitation design's criterion: the condition number of the stacked base regressor.

``W = [Y_b(q(t_k), v(t_k), a(t_k))]_k`` over the samples of one period, ``G = W^T W``;
``f = log lambda_max(G) - log lambda_min(G)`` (``= 2 log cond W``, Swevers et al. 1997; paper
``004_abbe750b8bbcc3aa.txt`` §4.2), or ``-log det G`` (D-optimality), or the smooth surrogate of
``log cond`` (see :mod:`pipeline.identification.design`). Value and exact gradient
(``d lambda = u^T dG u`` for a simple eigenvalue) are computed in CasADi callbacks for IPOPT; the
regressor comes from the symbolic bridge (:func:`regressor_casadi`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import casadi as ca
import numpy as np

from pipeline.core.compiled_on_demand import CompiledOnDemand
from pipeline.identification.regressor import BaseParameters, RegressorModel
from pipeline.robot.symbolic import SymbolicRobot


def regressor_casadi(sym: SymbolicRobot, reg: RegressorModel, base: BaseParameters) -> ca.Function:
    """``Y_b(q, v, a)`` as a CasADi function: inertial columns from ``sym.regressor`` (the
    symbolic bridge), actuator columns from the gear matrix (same formulas as
    :meth:`RegressorModel.actuator_columns`), then the base columns; only the torque rows of the
    joints the fit uses (``reg.rows``), so the design scores the regressor the fit solves."""
    nq = reg.nv
    q, v, a = ca.SX.sym("q", nq), ca.SX.sym("v", nq), ca.SX.sym("a", nq)
    y_sym = sym.regressor(q, v, a)
    n_link_cols = reg.n_parameters - 4 * nq
    y_links = y_sym[:, :n_link_cols]
    K = reg.gear_matrix
    kd = np.abs(np.diag(K))
    vm = ca.mtimes(ca.DM(K), v)
    am = ca.mtimes(ca.DM(K), a)
    w = reg.joint_coulomb_width_rad_s
    cols = []
    for group in range(4):
        for j in range(nq):
            kj = ca.DM(K[j].reshape(-1, 1))
            if group == 0:
                cols.append(kj * am[j] / kd[j] ** 2)
            elif group == 1:
                cols.append(kj * vm[j] / kd[j] ** 2)
            elif group == 2:
                s = ca.tanh(vm[j] / (kd[j] * w[j])) if w[j] > 0 else ca.sign(vm[j])
                cols.append(kj * s / kd[j])
            else:
                e = np.zeros((nq, 1))
                e[j] = 1.0
                cols.append(ca.DM(e))
    y = ca.horzcat(y_links, *cols)
    rows = list(range(nq)) if reg.rows is None else [int(j) for j in reg.rows]
    yb = y[rows, [int(i) for i in base.independent]]
    return ca.Function("regressor_base", [q, v, a], [yb], ["q", "v", "a"], ["Yb"])


class ExcitationCriterion:
    """Value and exact gradient of the excitation criterion.

    Works on the sample states ``S`` (3 nq x N, column k = [q; v; a] at sample k) -- the NLP's
    lifted variables -- or on Fourier coefficients through the basis (``*_coefficients``)."""

    def __init__(
        self,
        y_base: ca.Function,
        basis: tuple[np.ndarray, np.ndarray, np.ndarray],
        nq: int,
        criterion: str = "cond",
        softness: float = 0.0,
    ) -> None:
        if criterion not in ("cond", "logdet"):
            raise ValueError(f"criterion must be 'cond' or 'logdet', got {criterion!r}")
        self.criterion = criterion
        self.softness = float(softness)
        self.bq, self.bv, self.ba = basis
        self.n = self.bq.shape[0]
        self.nq = nq
        self.nb = y_base.size2_out(0)
        self.n_rows = y_base.size1_out(0)  # torque rows per sample: the joints the fit uses
        q, v, a = (ca.SX.sym(s, nq) for s in "qva")
        gbar = ca.SX.sym("gbar", self.n_rows, self.nb)
        yb = y_base(q, v, a)
        inner = ca.sum1(ca.sum2(yb * gbar))
        state = ca.vertcat(q, v, a)
        y_s = ca.Function("y_s", [state], [yb])
        vjp = ca.Function("vjp", [state, gbar], [ca.gradient(inner, state)])
        self._y = CompiledOnDemand(y_s, subdir="excitation")
        self._vjp = CompiledOnDemand(vjp, subdir="excitation")
        self.n_evals = 0

    def states(self, x: np.ndarray) -> np.ndarray:
        """Fourier coefficients (flat, row-major (nq, 2L+1)) -> S (3 nq, N)."""
        c = np.asarray(x, float).reshape(self.nq, -1)
        return np.vstack([c @ self.bq.T, c @ self.bv.T, c @ self.ba.T])

    def matrix_states(self, S: np.ndarray) -> np.ndarray:
        yb = self._y.mapped(self.n)(S)[0]  # (n_rows, N*nb), blocks per sample
        return yb.reshape(self.n_rows, self.n, self.nb).transpose(1, 0, 2).reshape(-1, self.nb)

    def matrix(self, x: np.ndarray) -> np.ndarray:
        return self.matrix_states(self.states(x))

    def value_and_gradient_states(
        self, S: np.ndarray, gradient: bool = True
    ) -> tuple[float, np.ndarray | None]:
        self.n_evals += 1
        W = self.matrix_states(S)
        G = W.T @ W
        lam, U = np.linalg.eigh(G)
        lam = np.maximum(lam, 1e-300)
        if self.criterion == "cond" and self.softness > 0:
            # smooth surrogate: soft max minus soft min of log(lambda) (log-sum-exp, sharpness
            # 1/softness); tends to log(lambda_max / lambda_min) as softness -> 0
            ll = np.log(lam)
            b = 1.0 / self.softness
            w_hi = np.exp(b * (ll - ll.max()))
            w_lo = np.exp(-b * (ll - ll.min()))
            f = float(ll.max() + np.log(w_hi.sum()) / b - ll.min() + np.log(w_lo.sum()) / b)
            w_hi, w_lo = w_hi / w_hi.sum(), w_lo / w_lo.sum()
            dG = (U * ((w_hi - w_lo) / lam)) @ U.T
        elif self.criterion == "cond":
            f = float(np.log(lam[-1]) - np.log(lam[0]))
            dG = np.outer(U[:, -1], U[:, -1]) / lam[-1] - np.outer(U[:, 0], U[:, 0]) / lam[0]
        else:
            f = float(-np.sum(np.log(lam)) / self.nb)
            dG = -(U / lam) @ U.T / self.nb
        if not gradient:
            return f, None
        dW = 2.0 * W @ dG  # df/dW, (N*n_rows, nb)
        gbar = dW.reshape(self.n, self.n_rows, self.nb).transpose(1, 0, 2).reshape(self.n_rows, -1)
        return f, self._vjp.mapped(self.n)(S, gbar)[0]  # (3 nq, N)

    def value_and_gradient(self, x: np.ndarray, gradient: bool = True) -> tuple[float, np.ndarray | None]:
        """Criterion and gradient with respect to the Fourier coefficients."""
        f, gs = self.value_and_gradient_states(self.states(x), gradient)
        if gs is None:
            return f, None
        nq = self.nq
        grad = gs[:nq] @ self.bq + gs[nq : 2 * nq] @ self.bv + gs[2 * nq :] @ self.ba
        return f, grad.ravel()


def condition_number(W: np.ndarray) -> float:
    s = np.linalg.svd(W, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


class CriterionCallback(ca.Callback):
    """CasADi callback wrapping :class:`ExcitationCriterion` (value + exact gradient)."""

    def __init__(self, name: str, crit: ExcitationCriterion) -> None:
        ca.Callback.__init__(self)
        self.crit = crit
        self.shape = (3 * crit.nq, crit.n)
        self._jac: _CriterionGradient | None = None
        self.construct(name, {})

    def get_n_in(self) -> int:
        return 1

    def get_n_out(self) -> int:
        return 1

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(*self.shape)

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(1, 1)

    def eval(self, arg: Sequence[ca.DM]) -> list[float]:
        f, _ = self.crit.value_and_gradient_states(np.asarray(arg[0]), gradient=False)
        return [f]

    def has_jacobian(self) -> bool:
        return True

    def get_jacobian(self, name: str, inames: Sequence[str], onames: Sequence[str],
                     opts: Mapping[str, object]) -> ca.Function:
        self._jac = _CriterionGradient(name, self.crit)
        return self._jac


class _CriterionGradient(ca.Callback):
    def __init__(self, name: str, crit: ExcitationCriterion) -> None:
        ca.Callback.__init__(self)
        self.crit = crit
        self.shape = (3 * crit.nq, crit.n)
        self.construct(name, {})

    def get_n_in(self) -> int:
        return 2

    def get_n_out(self) -> int:
        return 1

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(*self.shape) if i == 0 else ca.Sparsity.dense(1, 1)

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(1, self.shape[0] * self.shape[1])

    def eval(self, arg: Sequence[ca.DM]) -> list[ca.DM]:
        _, g = self.crit.value_and_gradient_states(np.asarray(arg[0]))
        assert g is not None                       # asked with gradient=True
        return [ca.DM(g.reshape(1, -1, order="F"))]


# ------------------------------------------------------------------------------ optimisation
