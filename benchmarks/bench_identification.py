"""Speed of the identification building blocks (stage 2), measured in this run.

Run: ``.venv/bin/python benchmarks/bench_identification.py [robot]`` (default rx130l).

1. Numeric regressor (``pin.computeJointTorqueRegressor`` + actuator columns) per sample, against
   one ``pin.rnea`` call (ratio).
2. Excitation criterion ``log cond`` + exact gradient over 100 samples (CasADi mapped regressor and
   vector-Jacobian product), against one evaluation of the value alone (ratio = cost of the
   gradient in value evaluations).
3. The physically consistent fit (IPOPT, log-Cholesky) on 1000 simulated samples.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import pinocchio as pin
from bench_help import exit_on_help

from pipeline.core.blas import single_thread_blas
from pipeline.identification import design as D
from pipeline.identification import estimate as E
from pipeline.identification import fourier
from pipeline.identification.regressor import RegressorModel, base_parameters, standard_parameters
from pipeline.robot.model import RobotModel
from pipeline.robot.symbolic import SymbolicRobot


def _time(f, n: int) -> float:
    t0 = time.perf_counter()
    for _ in range(n):
        f()
    return (time.perf_counter() - t0) / n


def main() -> None:
    name = sys.argv[1] if len(sys.argv) > 1 else "rx130l"
    robot = RobotModel.load(name)
    act = robot.actuation
    reg = RegressorModel(robot.model, act.gear_matrix, act.coulomb_smoothing_rad_s)
    rng = np.random.default_rng(0)
    q, v, a = rng.normal(size=(3, robot.nq))
    data = robot.model.createData()
    t_reg = _time(lambda: reg.regressor(q, v, a), 2000)
    t_rnea = _time(lambda: pin.rnea(robot.model, data, q, v, a), 2000)
    print(f"regressor per sample {t_reg * 1e6:.1f} us = {t_reg / t_rnea:.1f} x pin.rnea ({t_rnea * 1e6:.2f} us)")
    with single_thread_blas():
        base = base_parameters(reg, rng, lower=robot.limits.lower_rad, upper=robot.limits.upper_rad)
        limits = fourier.ExcitationLimits.from_robot(robot, 0.95, 0.95, 0.95, 0.8, 0.05, 0.02)
        sym = SymbolicRobot(robot)
        crit = D.ExcitationCriterion(D.regressor_casadi(sym, reg, base),
                                     fourier.fourier_basis(np.arange(100) * 0.1, 0.1, 5), robot.nq)
        x = fourier.random_trajectory(robot, limits, 5, 0.1, rng).coefficients.ravel()
        t_val = _time(lambda: crit.value_and_gradient(x, gradient=False), 50)
        t_grad = _time(lambda: crit.value_and_gradient(x), 50)
        print(f"criterion value {t_val * 1e3:.2f} ms, value + exact gradient {t_grad * 1e3:.2f} ms "
              f"({t_grad / t_val:.1f} value evaluations for {x.size} variables)")
        Q, V, A = rng.normal(size=(3, 1000, robot.nq))
        Y = reg.stacked(Q, V, A)
        p = standard_parameters(robot.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
        y = Y @ p + 0.1 * rng.normal(size=Y.shape[0])
        t0 = time.perf_counter()
        fit = E.physical_fit(Y, y, robot.nq, p, regularization=1e-3)
        print(f"physical fit on 1000 samples: {time.perf_counter() - t0:.2f} s, {fit.iterations} IPOPT "
              f"iterations, {fit.status}, consistent {fit.consistent}")


if __name__ == "__main__":
    exit_on_help(__doc__)
    main()
