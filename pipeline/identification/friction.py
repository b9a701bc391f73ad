"""Non-linear (Stribeck) friction on top of the linear base model (``friction_model: stribeck``).

The linear model has viscous and (smoothed) Coulomb friction per joint, ``fv v + fc tanh(v / w)``
(:mod:`.regressor`). The Stribeck model adds the excess of static over Coulomb friction that
decays with speed (Armstrong-Hélouvry, Dupont & Canudas de Wit 1994, "A survey of models, analysis
tools and compensation methods for the control of machines with friction", Automatica 30(7),
eq. of the "Stribeck" steady-state curve):

    tau_f,j = fv_j v + (fc_j + fs_j exp(-(v / vs_j)^2)) tanh(v / w)

with ``fs_j >= 0`` the static excess and ``vs_j > 0`` the Stribeck velocity. ``tau`` is linear in
the base parameters ``beta`` and in ``fs`` but not in ``vs``; all are estimated together by
IPOPT with exact derivatives (CasADi automatic differentiation, exact Hessian) minimising the
residual weighted by the per-joint noise sigmas (the WLS weights, Gautier), started from the WLS
estimate with ``fs = 0``. ``log vs`` is the variable (``vs`` in [``VS_MIN``, ``VS_MAX``]).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from pipeline.errors import SolverError
from pipeline.interrupts import raise_if_interrupted
from pipeline.solver_status import is_success

FRICTION_MODELS = ("viscous_coulomb", "stribeck")
#: bounds of the Stribeck velocity [rad/s] (joint side)
VS_MIN_RAD_S = 1e-3
VS_MAX_RAD_S = 5.0
VS_START_RAD_S = 0.05


@dataclass
class StribeckFit:
    beta: np.ndarray
    static_excess_Nm: np.ndarray  # fs per joint
    stribeck_velocity_rad_s: np.ndarray  # vs per joint
    coulomb_width_rad_s: float
    status: str
    iterations: int

    def stribeck_torque(self, v: np.ndarray) -> np.ndarray:
        """(N, nq) the Stribeck excess torque ``fs exp(-(v/vs)^2) tanh(v/w)``."""
        return stribeck_torque(v, self.static_excess_Nm, self.stribeck_velocity_rad_s, self.coulomb_width_rad_s)

    def predict(self, Wb: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(N, nq) torques of the base regressor ``Wb`` (sample-major rows) and velocities ``v``."""
        nq = np.asarray(v).shape[1]
        return (Wb @ self.beta).reshape(-1, nq) + self.stribeck_torque(v)


def stribeck_torque(v: np.ndarray, fs: np.ndarray, vs: np.ndarray, width_rad_s: float) -> np.ndarray:
    v = np.asarray(v, float)
    s = np.tanh(v / width_rad_s) if width_rad_s > 0 else np.sign(v)
    return np.asarray(fs, float) * np.exp(-((v / np.asarray(vs, float)) ** 2)) * s


def fit_stribeck(
    Wb: np.ndarray, y: np.ndarray, v: np.ndarray, beta0: np.ndarray, joint_sigma_Nm: np.ndarray,
    coulomb_width_rad_s: float, max_iter: int = 200,
) -> StribeckFit:
    """Joint weighted least squares of ``beta``, ``fs``, ``vs`` (module doc); raises
    :class:`SolverError` unless IPOPT succeeds (KeyboardInterrupt when interrupted)."""
    v = np.asarray(v, float)
    n, nq = v.shape
    nb = Wb.shape[1]
    w_row = np.tile(1.0 / np.asarray(joint_sigma_Nm, float), n)
    A = ca.DM(Wb * w_row[:, None])
    b = ca.DM(np.asarray(y, float) * w_row)
    beta = ca.MX.sym("beta", nb)
    fs = ca.MX.sym("fs", nq)
    log_vs = ca.MX.sym("log_vs", nq)
    V = ca.DM(v)  # (n, nq)
    sgn = ca.DM(np.tanh(v / coulomb_width_rad_s) if coulomb_width_rad_s > 0 else np.sign(v))
    vs_row = ca.repmat(ca.exp(log_vs).T, n, 1)
    fs_row = ca.repmat(fs.T, n, 1)
    st = fs_row * ca.exp(-((V / vs_row) ** 2)) * sgn  # (n, nq)
    st_w = ca.vec(st.T) * ca.DM(w_row)  # sample-major like y
    r = ca.mtimes(A, beta) + st_w - b
    x = ca.vertcat(beta, fs, log_vs)
    solver = ca.nlpsol("stribeck_fit", "ipopt", {"x": x, "f": 0.5 * ca.sumsqr(r)},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                        "ipopt.max_iter": max_iter, "ipopt.tol": 1e-8})
    lbx = np.concatenate([np.full(nb, -np.inf), np.zeros(nq), np.full(nq, np.log(VS_MIN_RAD_S))])
    ubx = np.concatenate([np.full(nb, np.inf), np.full(nq, np.inf), np.full(nq, np.log(VS_MAX_RAD_S))])
    x0 = np.concatenate([np.asarray(beta0, float), np.zeros(nq), np.full(nq, np.log(VS_START_RAD_S))])
    sol = solver(x0=x0, lbx=lbx, ubx=ubx)
    stats = solver.stats()
    status = str(stats["return_status"])
    raise_if_interrupted(status, "Stribeck friction fit")
    if not is_success(status):
        raise SolverError(None, "identification.friction_model", f"IPOPT returned {status} for the Stribeck fit")
    xs = np.asarray(sol["x"]).ravel()
    return StribeckFit(beta=xs[:nb], static_excess_Nm=xs[nb : nb + nq], stribeck_velocity_rad_s=np.exp(xs[nb + nq :]),
                       coulomb_width_rad_s=float(coulomb_width_rad_s), status=status,
                       iterations=int(stats["iter_count"]))


def compare_friction_models(
    Wb_train: np.ndarray, tau_train: np.ndarray, v_train: np.ndarray, joint_sigma_Nm: np.ndarray,
    coulomb_width_rad_s: float, Wb_val: np.ndarray, tau_val: np.ndarray, v_val: np.ndarray,
    max_iter: int = 200,
) -> dict:
    """Fit ``viscous_coulomb`` (weighted LS) and ``stribeck`` (:func:`fit_stribeck`) on the
    training samples and score both on held-out ones: per joint RMS and the model with the smaller
    mean RMS / sigma (``friction_model_best``). JSON-able."""
    nq = np.asarray(v_train).shape[1]
    sigma = np.asarray(joint_sigma_Nm, float)
    w = np.tile(1.0 / sigma, np.asarray(v_train).shape[0])
    beta_lin = np.linalg.lstsq(Wb_train * w[:, None], np.ravel(tau_train) * w, rcond=None)[0]
    fit = fit_stribeck(Wb_train, np.ravel(tau_train), v_train, beta_lin, sigma, coulomb_width_rad_s, max_iter)
    tau_val = np.asarray(tau_val, float).reshape(-1, nq)
    rms = {
        "viscous_coulomb": np.sqrt(np.mean(((Wb_val @ beta_lin).reshape(-1, nq) - tau_val) ** 2, axis=0)),
        "stribeck": np.sqrt(np.mean((fit.predict(Wb_val, v_val) - tau_val) ** 2, axis=0)),
    }
    best = min(rms, key=lambda k: float(np.mean(rms[k] / sigma)))
    return {
        "friction_heldout_rms_Nm": {k: r.tolist() for k, r in rms.items()},
        "friction_model_best": best,
        "stribeck_static_excess_Nm": fit.static_excess_Nm.tolist(),
        "stribeck_velocity_rad_s": fit.stribeck_velocity_rad_s.tolist(),
        "stribeck_status": fit.status,
    }
