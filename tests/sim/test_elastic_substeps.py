"""The elastic plant's substep against the fastest mode of the coupled joints: TIAGo's arm (light
wrist links beside nearly aligned axes), whose coupled wrist mode is several times faster than the
per-joint estimate ``k (1/J_m + 1/M_ii)``, is integrated with ``h omega_max <= 1`` on every pose."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy.linalg import eigh

from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.sim.plant import MODE_STEP, Plant, deflection_rates
from pipeline.sim.truth import RealRobot, TruthConfig

TIAGO_URDF = "tiago_description/robots/tiago_no_hand.urdf"
#: velocity-loop sample of the drives (paper 004 §2.3: 200 µs)
VELOCITY_SAMPLE_S = 200e-6
#: a pose of TIAGo's arm with strongly coupled wrist joints (the start of a corpus PtP move), rad
COUPLED_POSE_RAD = np.array([0.7039, -0.3334, -2.6591, 1.7830, -1.3820, -0.6835, -1.6036])


@pytest.fixture(scope="module")
def tiago_plant() -> Plant:
    urdf = example_arm_urdf(TIAGO_URDF)
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    plant = RealRobot.create(RobotModel.load(urdf), 1, TruthConfig()).plant
    assert plant.elastic
    return plant


def _two_mass_rates(plant: Plant, q: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Fastest spring and damper rates of the 2 nq masses (links at ``q``, rotors) joined by the
    transmission's springs and dampers, from the generalized eigenproblems ``K x = w^2 M x`` and
    ``D x = c M x``; and the per-joint estimate ``sqrt(k (1/J_m + 1/M_ii(q)))``."""
    tr, model = plant.transmission, plant._link_model
    n = model.nq
    m = pin.crba(model, model.createData(), q)
    m = np.triu(m) + np.triu(m, 1).T
    mass = np.block([[m, np.zeros((n, n))], [np.zeros((n, n)), np.diag(tr.motor_inertia_kgm2)]])
    spring = np.block([[np.eye(n), -np.eye(n)], [-np.eye(n), np.eye(n)]])
    k = spring * np.tile(tr.stiffness_Nm_rad, 2)[None, :]
    k = 0.5 * (k + k.T)
    d = spring * np.tile(tr.damping_Nms_rad, 2)[None, :]
    d = 0.5 * (d + d.T)
    omega = float(np.sqrt(eigh(k, mass, eigvals_only=True).max()))
    c = float(eigh(d, mass, eigvals_only=True).max())
    per_joint = np.sqrt(tr.stiffness_Nm_rad * (1 / tr.motor_inertia_kgm2 + 1 / np.diag(m)))
    return omega, c, per_joint


def test_deflection_rates_are_the_two_mass_eigenvalues(tiago_plant):
    for q in (COUPLED_POSE_RAD, np.zeros(7)):
        omega, c, _ = _two_mass_rates(tiago_plant, q)
        got = deflection_rates(tiago_plant._link_model, q, tiago_plant.transmission)
        np.testing.assert_allclose(got, (omega, c), rtol=1e-8)


def test_substep_resolves_the_coupled_wrist_mode_on_every_pose(tiago_plant):
    h = VELOCITY_SAMPLE_S / tiago_plant.substeps_for(VELOCITY_SAMPLE_S)
    omega, _, per_joint = _two_mass_rates(tiago_plant, COUPLED_POSE_RAD)
    assert omega > 1.5 * per_joint.max()           # the coupling, not one joint, sets the fastest mode
    assert h * omega <= MODE_STEP
    model = tiago_plant._link_model
    rng = np.random.default_rng(7)                 # poses other than the plant's own sample
    for q in rng.uniform(model.lowerPositionLimit, model.upperPositionLimit, (100, model.nq)):
        omega, c, _ = _two_mass_rates(tiago_plant, q)
        assert h * omega <= MODE_STEP and h**2 * omega**2 < 4.0 - 2.0 * h * c   # symplectic Euler stable
