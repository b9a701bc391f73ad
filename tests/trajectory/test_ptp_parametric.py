"""The PtP NLP with the arm's parameters (dynamic parameters, joint placements) as NLP parameters:
the same plans as the NLP with them as constants of the code, and one generated code for every
calibration and identification of the arm (interpreted, small grid: no gcc build)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from pipeline.core import codegen
from pipeline.robot.symbolic import SymbolicRobot
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.ptp import (
    DERIVATIVE_DIRECTIONS,
    PtpProblem,
    energy_weights,
    nlp_functions,
    nlp_library_key,
)

N_INTERVALS = 6
#: tight tolerances: both NLPs converge to the same optimum (their code rounds differently, so a
#: loose tolerance stops them at different points within it)
IPOPT = {"ipopt.tol": 1e-10, "ipopt.constr_viol_tol": 1e-10, "ipopt.mu_strategy": "adaptive"}


def recalibrated(robot, seed: int):
    """A copy with masses, centres of mass, inertia tensors and joint placements moved as a calibration
    and an identification move them (10 % mass, 1 cm lever, 1e-4 kg m^2 and 1 mrad and 1 mm placement)."""
    arm = robot.copy()
    rng = np.random.default_rng(seed)
    model = arm.model
    for i in range(1, model.njoints):
        inertia = model.inertias[i]
        spread = 0.01 * rng.standard_normal((3, 3))
        model.inertias[i] = pin.Inertia(inertia.mass * (1.0 + 0.1 * rng.standard_normal()),
                                        inertia.lever + 0.01 * rng.standard_normal(3),
                                        inertia.inertia + spread @ spread.T)
        placement = model.jointPlacements[i]
        model.jointPlacements[i] = pin.SE3(placement.rotation @ pin.exp3(1e-3 * rng.standard_normal(3)),
                                           placement.translation + 1e-3 * rng.standard_normal(3))
    return arm


def problem(arm, parametric: bool) -> tuple[PtpProblem, PlanningModel]:
    pm = PlanningModel.from_robot(arm)
    return PtpProblem(pm, SymbolicRobot(arm), N_INTERVALS, jit=False, ipopt_options=IPOPT,
                      parametric=parametric), pm


#: session fixtures that take seconds and serve several tests: their tests run on one pytest-xdist
#: worker, so each is built once per ``make test`` (tests/conftest.py, pytest_collection_modifyitems)
SHARED_COSTLY_FIXTURES = frozenset({"problems"})


@pytest.fixture(scope="session")   # built once per worker, also when pytest-xdist comes back to this file
def problems(rx130l):
    """(parametric, constant) problem pairs of two recalibrated arms."""
    return [(problem(arm, True), problem(arm, False)) for arm in (recalibrated(rx130l, 1), recalibrated(rx130l, 2))]


def nlp_code_key(p: PtpProblem) -> str:
    """SHA-256 of the NLP's own C code (objective and constraints; the derivative functions are derived
    from it, and generating the Hessian's code would take a second per problem)."""
    return codegen.library_key(nlp_functions(p.solver)[:1], "ptp")


def test_parametric_plans_equal_constant_ones(problems, big_move):
    """The first arm's plan with its parameters as NLP parameters equals the one with them as constants;
    the second arm's parametric plan differs from it (its parameters reach the plan through the same code)."""
    def plan(p, pm):
        return p.solve(*big_move, k1=1.0, k2=0.01, weights=energy_weights(pm, "normalised"))

    parametric, constant = (plan(*p) for p in problems[0])
    assert parametric.duration_s == pytest.approx(constant.duration_s, abs=1e-8)
    assert np.allclose(parametric.q_nodes, constant.q_nodes, atol=1e-7)
    other_arm = plan(*problems[1][0])
    assert abs(other_arm.duration_s - parametric.duration_s) > 1e-4


def test_one_code_serves_every_arm(problems):
    """The key that names the compiled library (:func:`nlp_library_key`) and the NLP's C code are the
    same for two arms with the parameters as NLP parameters, and differ with them as constants."""
    (parametric_1, _), (parametric_2, _) = (pair[0] for pair in problems)
    assert parametric_1.library_key == parametric_2.library_key
    assert nlp_code_key(parametric_1) == nlp_code_key(parametric_2)
    assert not np.allclose(parametric_1.model_parameters, parametric_2.model_parameters)
    # with the parameters as constants of the code, each arm needs its own build
    (constant_1, _), (constant_2, _) = (pair[1] for pair in problems)
    assert constant_1.library_key != constant_2.library_key
    assert nlp_code_key(constant_1) != nlp_code_key(constant_2)
    # the key follows what the code is generated from: other gcc flags, another library
    assert nlp_library_key(parametric_1.solver, {}, ("-O0",)) != nlp_library_key(parametric_1.solver, {}, ("-O1",))


def test_derivative_batches_give_the_same_bits(rx130l):
    """The NLP's gradient, constraint Jacobian and Lagrangian Hessian are the same to the last bit
    whether CasADi propagates all their directional derivatives of the RNEA in one call (64 at most) or
    in batches of ``DERIVATIVE_DIRECTIONS`` (half the generated code); the batches do reach the code."""
    pm = PlanningModel.from_robot(rx130l)
    sym = SymbolicRobot(rx130l)
    one_call, batches = (PtpProblem(pm, sym, N_INTERVALS, jit=False, derivative_directions=n)
                         for n in (64, DERIVATIVE_DIRECTIONS))
    names = [set(p.solver.get_function()) for p in (one_call, batches)]
    assert names[0] == names[1] and one_call.library_key != batches.library_key
    rng = np.random.default_rng(3)
    x = rng.standard_normal(one_call.n_x)
    x[0] = 1.0   # the duration
    p = np.abs(rng.standard_normal(one_call.n_p))
    lam_g = rng.standard_normal(one_call.n_g)
    for name, args in (("nlp_grad", (x, p, 1.0, lam_g)), ("nlp_jac_g", (x, p)), ("nlp_hess_l", (x, p, 1.0, lam_g))):
        values = [[out.full() for out in s.solver.get_function(name).call([ca.DM(a) for a in args])]
                  for s in (one_call, batches)]
        for a, b in zip(*values, strict=True):
            assert np.array_equal(a, b), name
