"""Least-squares and physically consistent estimation of the dynamic parameters.

Paper ``004_abbe750b8bbcc3aa.txt`` §4.1 (overdetermined system (28), ``tau = W p_b``).

* **OLS** on the base regressor ``W`` (rows sample-major, ``k*nv + j``).
* **WLS, Gautier's weighting** (Gautier & Poignet 2001): from the OLS residual ``rho_j`` of joint
  ``j`` (``r_j`` rows, ``c_j`` base parameters acting on that joint)
  ``sigma_j^2 = ||rho_j||^2 / (r_j - c_j)``; rows of joint ``j`` are divided by ``sigma_j`` and
  the estimate is re-solved. Covariance ``(W^T S^-1 W)^-1`` assumes white residuals; the one the
  stage reports and scores with is the HAC sandwich of :func:`hac_covariance` (Newey & West 1987).
* **Physically consistent** estimate of the *standard* parameters: each link's parameters come
  from its log-Cholesky parameters ``theta`` (Rucker & Wensing 2022): the pseudo-inertia
  ``J = U U^T`` with ``U = e^alpha [[e^d1, s12, s13, t1], [0, e^d2, s23, t2], [0, 0, e^d3, t3],
  [0, 0, 0, 1]]`` is positive definite for every ``theta`` (so the mass is positive and the
  inertia satisfies the triangle inequalities). Rotor inertia, viscous and Coulomb friction have
  a positive lower bound. IPOPT (through CasADi, exact Hessian) minimises

      ||S^-1/2 (Y p(theta) - tau)||^2 + lambda * sum(((p - p_nominal) / p_scale)^2)

  The small ``lambda`` term picks, among the models that fit equally well, the one closest to the
  nominal model: it fixes the standard parameters the data cannot identify.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from pipeline.core.blas import single_thread_blas
from pipeline.core.errors import DataFileError, SolverError
from pipeline.core.interrupts import raise_if_interrupted

#: lower bound of rotor inertia (kg m^2) and friction (N m s/rad, N m) in the physical fit
POSITIVE_LOWER_BOUND = 1e-6


@dataclass
class LeastSquaresEstimate:
    """Result of OLS or WLS on the base regressor."""

    beta: np.ndarray  # base parameters
    covariance: np.ndarray  # (n_base, n_base)
    joint_sigma_Nm: np.ndarray  # residual sigma per joint (Gautier)
    residual_Nm: np.ndarray  # (N, nv) unweighted residual tau - W beta
    method: str

    @property
    def sigma(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def rms_Nm(self) -> float:
        return float(np.sqrt(np.mean(self.residual_Nm**2)))


def _check_system(W: np.ndarray, y: np.ndarray, nv: int) -> None:
    if W.ndim != 2 or y.ndim != 1 or W.shape[0] != y.shape[0]:
        raise DataFileError(None, "regressor/torque", f"mismatched shapes {W.shape}, {y.shape}")
    if W.shape[0] % nv:
        raise DataFileError(None, "regressor", f"{W.shape[0]} rows are not a multiple of {nv}")
    if not (np.all(np.isfinite(W)) and np.all(np.isfinite(y))):
        raise DataFileError(None, "regressor/torque", "contains NaN or inf")
    n_samples = W.shape[0] // nv
    # Gautier's per-joint variance sigma_j^2 = ||rho_j||^2 / (r_j - c_j) needs r_j > c_j: ask for
    # more samples than parameters (not only more equations)
    if n_samples <= W.shape[1]:
        raise DataFileError(
            None,
            "samples",
            f"{n_samples} samples ({W.shape[0]} equations) for {W.shape[1]} parameters: "
            "need more samples than parameters",
        )


def _joint_sigmas(W: np.ndarray, res: np.ndarray, nv: int) -> np.ndarray:
    """Gautier's per-joint sigma ``||rho_j||^2 / (r_j - c_j)``: ``r_j`` the joint's rows that carry an
    equation (a row whose regressor is zero has none: :mod:`.dwell`), ``c_j`` the columns they reach."""
    sig = np.empty(nv)
    for j in range(nv):
        rows = W[j::nv]
        c_j = int(np.sum(np.linalg.norm(rows, axis=0) > 0))
        r_j = int(np.sum(np.any(rows != 0, axis=1)))
        dof = max(r_j - c_j, 1)
        sig[j] = np.sqrt(np.sum(res[:, j] ** 2) / dof)
    return np.maximum(sig, 1e-12)


def ols(W: np.ndarray, y: np.ndarray, nv: int) -> LeastSquaresEstimate:
    """Ordinary least squares; covariance from one residual variance of all rows."""
    with single_thread_blas():
        return _ols(W, y, nv)


def _ols(W: np.ndarray, y: np.ndarray, nv: int) -> LeastSquaresEstimate:
    _check_system(W, y, nv)
    beta, *_ = np.linalg.lstsq(W, y, rcond=None)
    res = (y - W @ beta).reshape(-1, nv)
    dof = max(W.shape[0] - W.shape[1], 1)
    s2 = float(np.sum(res**2) / dof)
    cov = s2 * np.linalg.pinv(W.T @ W)
    return LeastSquaresEstimate(beta, cov, _joint_sigmas(W, res, nv), res, "ols")


def weighted_solution(W: np.ndarray, y: np.ndarray, joint_sigma: np.ndarray) -> np.ndarray:
    """``argmin sum_k sum_i (y_ki - W_ki beta)^2 / sigma_i^2``: the least-squares solution with torque row ``i``
    of every sample (rows sample-major) weighted by ``1 / sigma_i`` (no covariance; :func:`wls` for that)."""
    sigma = np.asarray(joint_sigma, float)
    w = np.tile(1.0 / sigma, W.shape[0] // len(sigma))
    return np.linalg.lstsq(W * w[:, None], np.asarray(y, float) * w, rcond=None)[0]


def wls(W: np.ndarray, y: np.ndarray, nv: int, iterations: int = 1) -> LeastSquaresEstimate:
    """Gautier's weighted least squares (per-joint residual sigma from the previous fit)."""
    with single_thread_blas():
        return _wls(W, y, nv, iterations)


def _wls(W: np.ndarray, y: np.ndarray, nv: int, iterations: int) -> LeastSquaresEstimate:
    est = _ols(W, y, nv)
    for _ in range(iterations):
        w = np.tile(1.0 / est.joint_sigma_Nm, W.shape[0] // nv)
        Ww = W * w[:, None]
        beta, *_ = np.linalg.lstsq(Ww, y * w, rcond=None)
        res = (y - W @ beta).reshape(-1, nv)
        cov = np.linalg.pinv(Ww.T @ Ww)
        est = LeastSquaresEstimate(beta, cov, _joint_sigmas(W, res, nv), res, "wls")
    # the covariance assumes the weights are the true sigmas: rescale by the weighted residual
    n_dof = max(W.shape[0] - W.shape[1], 1)
    chi2 = float(np.sum((est.residual_Nm / est.joint_sigma_Nm) ** 2) / n_dof)
    est.covariance = est.covariance * chi2
    return est


@dataclass
class HacCovariance:
    """Heteroskedasticity and autocorrelation consistent covariance (:func:`hac_covariance`)."""

    covariance: np.ndarray
    bandwidth: float  # Bartlett lag window: weights 1 - l / (bandwidth + 1)
    white_ratio: float  # mean over parameters of the HAC variance / the white-residual WLS variance

    @property
    def sigma(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))


def andrews_bandwidth(scores: np.ndarray) -> float:
    """Bartlett-kernel bandwidth of Andrews (1991, Econometrica 59(3), eqs. 6.2 and 6.4): an AR(1)
    fitted to each score series ``g_a`` (rho_a, innovation variance s_a^2),
    ``alpha(1) = sum 4 rho^2 s^4 / ((1-rho)^6 (1+rho)^2) / sum s^4 / (1-rho)^4`` and
    ``S = 1.1447 (alpha(1) T)^(1/3)``, at most ``T - 1`` lags."""
    g = np.asarray(scores, float)
    T = g.shape[0]
    x, x1 = g[1:], g[:-1]
    den = np.sum(x1**2, axis=0)
    rho = np.clip(np.where(den > 0, np.sum(x * x1, axis=0) / np.where(den > 0, den, 1.0), 0.0), -0.97, 0.97)
    s2 = np.mean((x - rho * x1) ** 2, axis=0)
    num = np.sum(4 * rho**2 * s2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2))
    dnm = np.sum(s2**2 / (1 - rho) ** 4)
    alpha = num / dnm if dnm > 0 else 0.0
    return float(min(1.1447 * (alpha * T) ** (1.0 / 3.0), T - 1))


def hac_covariance(J: np.ndarray, residual: np.ndarray, joint_sigma_Nm: np.ndarray,
                   white_covariance: np.ndarray | None = None) -> HacCovariance:
    """Newey & West (1987, Econometrica 55(3)) sandwich covariance of a weighted least-squares
    estimate with Jacobian ``J`` (the regressor; for a non-linear nested fit the Jacobian of the
    model at the estimate, so the covariance is the joint one) and ``residual`` (rows sample-major,
    ``k*n_rows + j``), weights ``1 / joint_sigma_Nm`` (Gautier). Valid when the residuals are
    correlated in time (filtering, decimation, unmodelled friction and elasticity) and across the
    joints of a sample:

        X = S^-1/2 J, e = S^-1/2 residual, g_k = sum over sample k's rows of X_r e_r,
        Cov = n/(n-p) (X^T X)^-1 [G_0 + sum_{l=1}^{L} (1 - l/(L+1)) (G_l + G_l^T)] (X^T X)^-1,
        G_l = sum_k g_k g_{k-l}^T,

    Bartlett weights, bandwidth ``L`` by Andrews' (1991) AR(1) plug-in rule
    (:func:`andrews_bandwidth`). ``white_covariance``: the white-residual one, for the ratio."""
    nv = len(joint_sigma_Nm)
    n = J.shape[0] // nv
    w = np.tile(1.0 / np.asarray(joint_sigma_Nm, float), n)
    X = J * w[:, None]
    e = np.asarray(residual, float).ravel() * w
    G = (X * e[:, None]).reshape(n, nv, -1).sum(axis=1)  # (n, p) scores per sample
    bw = andrews_bandwidth(G)
    meat = G.T @ G
    for lag in range(1, int(np.floor(bw)) + 1):
        gl = G[lag:].T @ G[:-lag]
        meat += (1.0 - lag / (bw + 1.0)) * (gl + gl.T)
    bread = np.linalg.pinv(X.T @ X)
    p = J.shape[1]
    cov = bread @ meat @ bread * (n / max(n - p, 1))
    cov = 0.5 * (cov + cov.T)
    if white_covariance is None:
        return HacCovariance(cov, bw, float("nan"))
    k = white_covariance.shape[0]
    white = np.clip(np.diag(white_covariance), 1e-300, None)
    return HacCovariance(cov, bw, float(np.mean(np.diag(cov)[:k] / white)))


def wls_hac_covariance(W: np.ndarray, y: np.ndarray, est: LeastSquaresEstimate) -> HacCovariance:
    """:func:`hac_covariance` of Gautier's WLS estimate ``est`` on ``(W, y)``."""
    return hac_covariance(W, np.asarray(y, float) - W @ est.beta, est.joint_sigma_Nm, est.covariance)


# ----------------------------------------------------------------------------- log-Cholesky


def log_cholesky_to_dynamic(theta):
    """10 log-Cholesky parameters -> 10 dynamic parameters (pin order), numpy or CasADi."""
    is_ca = isinstance(theta, (ca.SX, ca.MX, ca.DM))
    exp = ca.exp if is_ca else np.exp
    al, d1, d2, d3, s12, s23, s13, t1, t2, t3 = (theta[i] for i in range(10))
    ea = exp(al)
    e1, e2, e3 = exp(d1), exp(d2), exp(d3)
    # U upper triangular (row-major entries), J = U U^T, times e^(2 alpha)
    u = [[e1, s12, s13, t1], [0, e2, s23, t2], [0, 0, e3, t3], [0, 0, 0, 1]]

    def jij(i, j):
        return sum(u[i][k] * u[j][k] for k in range(4)) * ea * ea

    S = [[jij(i, j) for j in range(3)] for i in range(3)]
    h = [jij(i, 3) for i in range(3)]
    m = jij(3, 3)
    tr = S[0][0] + S[1][1] + S[2][2]
    vals = [
        m,
        h[0],
        h[1],
        h[2],
        tr - S[0][0],
        -S[0][1],
        tr - S[1][1],
        -S[0][2],
        -S[1][2],
        tr - S[2][2],
    ]
    return ca.vertcat(*vals) if is_ca else np.array(vals, dtype=float)


def pseudo_inertia(p10: np.ndarray) -> np.ndarray:
    """4x4 pseudo-inertia ``[[Sigma, h], [h^T, m]]`` of 10 dynamic parameters (pin order)."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = np.asarray(p10, float)
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    sigma = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    J = np.zeros((4, 4))
    J[:3, :3] = sigma
    J[:3, 3] = J[3, :3] = (hx, hy, hz)
    J[3, 3] = m
    return J


def is_physically_consistent(p10: np.ndarray, tol: float = 0.0) -> bool:
    """Pseudo-inertia positive definite (mass > 0, inertia PD and triangle inequalities)."""
    return bool(np.linalg.eigvalsh(pseudo_inertia(p10)).min() > tol)


def dynamic_to_log_cholesky(p10: np.ndarray, min_eig_ratio: float = 1e-6) -> np.ndarray:
    """Inverse map; a non-PD pseudo-inertia is first projected (eigenvalues clipped)."""
    J = pseudo_inertia(p10)
    w, V = np.linalg.eigh(J)
    floor = min_eig_ratio * max(abs(w).max(), 1e-9)
    J = V @ np.diag(np.maximum(w, floor)) @ V.T
    P = np.eye(4)[::-1]
    L = np.linalg.cholesky(P @ J @ P)
    U = P @ L @ P  # upper triangular with U U^T = J
    ea = U[3, 3]
    U = U / ea
    return np.array(
        [
            np.log(ea),
            np.log(U[0, 0]),
            np.log(U[1, 1]),
            np.log(U[2, 2]),
            U[0, 1],
            U[1, 2],
            U[0, 2],
            U[0, 3],
            U[1, 3],
            U[2, 3],
        ]
    )


def parameter_scale(p_nominal: np.ndarray, n_links: int, nv: int) -> np.ndarray:
    """Typical magnitude of each standard parameter for the regularisation term."""
    s = np.empty_like(p_nominal)
    for i in range(n_links):
        blk = p_nominal[10 * i : 10 * i + 10]
        m = max(abs(blk[0]), 0.1)
        s[10 * i] = m
        s[10 * i + 1 : 10 * i + 4] = m * 0.1
        s[10 * i + 4 : 10 * i + 10] = max(m * 0.01, np.abs(blk[4:]).max(), 1e-3)
    ia = p_nominal[10 * n_links : 10 * n_links + nv]
    # a rotor inertia the nominal model leaves at 0 (not given: assumed by robot init, or torques
    # measured on the link side) is no prior to pull towards: the data alone decide it
    s[10 * n_links : 10 * n_links + nv] = np.where(ia == 0.0, np.inf, np.maximum(np.abs(ia), 1e-2))
    # friction and offsets are always identifiable: no pull towards the nominal values
    s[10 * n_links + nv :] = np.inf
    return s


@dataclass
class PhysicalEstimate:
    """Physically consistent standard parameters and the fit statistics."""

    p: np.ndarray
    residual_Nm: np.ndarray
    consistent: bool
    min_pseudo_inertia_eig: list[float]
    iterations: int
    status: str
    details: dict = field(default_factory=dict)

    @property
    def rms_Nm(self) -> float:
        return float(np.sqrt(np.mean(self.residual_Nm**2)))


def physical_fit(
    Y: np.ndarray,
    y: np.ndarray,
    nv: int,
    p_nominal: np.ndarray,
    joint_sigma_Nm: np.ndarray | None = None,
    regularization: float = 1e-4,
    max_iter: int = 500,
    fit_offsets: bool = True,
    min_mass_kg: float = 1e-2,
    min_spread_m: float = 1e-3,
    n_rows: int | None = None,
) -> PhysicalEstimate:
    """Physically consistent least squares on the standard regressor ``Y`` (see module doc).

    ``Y``: (N*n_rows, 10*n_links + 4*nv) standard regressor, ``y`` torques, ``joint_sigma_Nm`` the
    per-row weights (Gautier); ``regularization`` is ``lambda`` relative to the number of rows.
    ``n_rows``: torque rows per sample when only some of the ``nv`` joints are measured (default nv).
    """
    n_std = Y.shape[1]
    n_links = (n_std - 4 * nv) // 10
    if n_links * 10 + 4 * nv != n_std:
        raise DataFileError(None, "regressor", f"{n_std} columns do not match {nv} joints")
    nr = nv if n_rows is None else n_rows
    _check_system(Y, y, nr)
    with single_thread_blas():
        return _physical_fit(Y, y, nv, p_nominal, joint_sigma_Nm, regularization, max_iter, fit_offsets,
                             min_mass_kg, min_spread_m, n_links, nr)


def _physical_fit(Y, y, nv, p_nominal, joint_sigma_Nm, regularization, max_iter, fit_offsets,  # noqa: ANN001
                  min_mass_kg, min_spread_m, n_links, nr) -> PhysicalEstimate:  # noqa: ANN001
    n_std = Y.shape[1]
    sig = np.ones(nr) if joint_sigma_Nm is None else np.asarray(joint_sigma_Nm, float)
    w = np.tile(1.0 / sig, Y.shape[0] // nr)
    # compress: ||A p - b||^2 = ||R p - r||^2 + const
    A = np.hstack([Y * w[:, None], (y * w)[:, None]])
    R = np.linalg.qr(A, mode="r")
    R_p, r_b = R[:n_std, :n_std], R[:n_std, n_std]
    n_rows = Y.shape[0]

    theta = ca.SX.sym("theta", 10 * n_links)
    act = ca.SX.sym("act", 4 * nv)
    p = ca.vertcat(*[log_cholesky_to_dynamic(theta[10 * i : 10 * i + 10]) for i in range(n_links)], act)
    scale = parameter_scale(p_nominal, n_links, nv)
    res = ca.mtimes(ca.DM(R_p), p) - ca.DM(r_b)
    reg = (p - ca.DM(p_nominal)) / ca.DM(scale)
    # normalise by the number of rows so that lambda is independent of the data length
    f = (ca.dot(res, res) + regularization * n_rows * ca.dot(reg, reg)) / n_rows
    x = ca.vertcat(theta, act)
    lbx = -np.inf * np.ones(x.shape[0])
    ubx = np.inf * np.ones(x.shape[0])
    off = 10 * n_links
    lbx[off : off + 3 * nv] = POSITIVE_LOWER_BOUND
    # keep every pseudo-inertia strictly inside the PD cone: mass >= min_mass_kg and each
    # normalised principal spread e^d_k >= min_spread_m (else the optimum sits on the boundary
    # that the log-Cholesky map only reaches at infinity and IPOPT never converges)
    for i in range(n_links):
        lbx[10 * i] = 0.5 * np.log(min_mass_kg)
        lbx[10 * i + 1 : 10 * i + 4] = np.log(min_spread_m)
    if not fit_offsets:
        lbx[off + 3 * nv :] = ubx[off + 3 * nv :] = 0.0
    x0 = np.concatenate(
        [
            *[dynamic_to_log_cholesky(p_nominal[10 * i : 10 * i + 10]) for i in range(n_links)],
            np.maximum(p_nominal[off : off + 3 * nv], 2 * POSITIVE_LOWER_BOUND),
            p_nominal[off + 3 * nv :] if fit_offsets else np.zeros(nv),
        ]
    )
    solver = ca.nlpsol(
        "physical_fit",
        "ipopt",
        {"x": x, "f": f},
        {
            "ipopt.print_level": 0,
            "print_time": False,
            "ipopt.max_iter": max_iter,
            "ipopt.tol": 1e-10,
            "ipopt.sb": "yes",
        },
    )
    x0 = np.clip(x0, lbx + 1e-3, ubx)
    sol = solver(x0=x0, lbx=lbx, ubx=ubx)
    stats = solver.stats()
    raise_if_interrupted(stats["return_status"], "physical fit")
    if not stats["success"] and stats["return_status"] not in (
        "Maximum_Iterations_Exceeded",
        "Solved_To_Acceptable_Level",
    ):
        raise SolverError(None, "physical_fit", f"IPOPT: {stats['return_status']}")
    p_fun = ca.Function("p", [x], [p])
    p_hat = np.asarray(p_fun(sol["x"])).ravel()
    resid = (y - Y @ p_hat).reshape(-1, nr)
    eigs = [
        float(np.linalg.eigvalsh(pseudo_inertia(p_hat[10 * i : 10 * i + 10])).min())
        for i in range(n_links)
    ]
    consistent = bool(
        all(e > 0 for e in eigs) and np.all(p_hat[off : off + 3 * nv] > 0)
    )
    return PhysicalEstimate(
        p=p_hat,
        residual_Nm=resid,
        consistent=consistent,
        min_pseudo_inertia_eig=eigs,
        iterations=int(stats["iter_count"]),
        status=str(stats["return_status"]),
    )
