"""A stand-in for ``RobotModel`` (duck-typed) used while the foundation is written.

Modified-DH RX130L-like arm of /work/shared/DESIGN.md with the stated masses, rotor inertia and
friction. Only the attributes the control stage uses are provided.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pinocchio as pin

DH = [  # alpha_{i-1}, a_{i-1}, theta offset, d_i
    (0.0, 0.0, 0.0, 0.550),
    (-np.pi / 2, 0.0, -np.pi / 2, 0.0),
    (0.0, 0.625, -np.pi / 2, 0.0),
    (-np.pi / 2, 0.0, 0.0, 0.925),
    (np.pi / 2, 0.0, 0.0, 0.0),
    (-np.pi / 2, 0.0, np.pi, 0.110),
]
MASS = [45.0, 35.0, 20.0, 22.0, 2.0, 0.3]
COM = [(0, 0, -0.2), (0.3, 0, 0.1), (0, -0.2, 0), (0, 0, -0.3), (0, 0, 0.02), (0, 0, 0.01)]


def _placement(alpha: float, a: float, theta: float, d: float) -> pin.SE3:
    rx = pin.SE3(pin.utils.rotate("x", alpha), np.zeros(3))
    tx = pin.SE3(np.eye(3), np.array([a, 0.0, 0.0]))
    rz = pin.SE3(pin.utils.rotate("z", theta), np.zeros(3))
    tz = pin.SE3(np.eye(3), np.array([0.0, 0.0, d]))
    return rx * tx * rz * tz


class DevRobot:
    def __init__(self, model: pin.Model | None = None) -> None:
        if model is None:
            model = pin.Model()
            parent = 0
            for i, (al, a, th, d) in enumerate(DH):
                parent = model.addJoint(parent, pin.JointModelRZ(), _placement(al, a, th, d), f"j{i + 1}")
                c = np.array(COM[i], float)
                r = 0.08 if i < 4 else 0.04
                inertia = pin.Inertia(MASS[i], c, MASS[i] * r**2 * np.eye(3))
                model.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
            model.addFrame(pin.Frame("flange", 6, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
            tcp = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.15]))
            model.addFrame(pin.Frame("tcp", 6, 0, tcp, pin.FrameType.OP_FRAME))
            model.armature = np.array([3.0, 3.0, 1.0, 0.2, 0.2, 0.1])
        self.model = model
        self.name = "dev"
        self.nq = model.nq
        self.frame_tcp = "tcp"
        self.frame_flange = "flange"
        deg = np.pi / 180
        self.limits = SimpleNamespace(
            lower_rad=np.array([-160, -137.5, -142.5, -270, -105, -270]) * deg,
            upper_rad=np.array([160, 137.5, 142.5, 270, 120, 270]) * deg,
            velocity_rad_s=np.array([200, 200, 255, 315, 360, 870]) * deg,
            effort_Nm=np.array([550.0, 500, 220, 55, 40, 30]),
            acceleration_rad_s2=np.full(6, 10.0),
        )
        self.actuation = SimpleNamespace(
            gear_ratio=np.array([100.0, 100, 100, 70, 60, 50]),
            rotor_inertia_kgm2=np.array(model.armature).copy(),
            viscous_Nms_rad=np.array([20.0, 20, 10, 3, 3, 1.5]),
            coulomb_Nm=np.array([25.0, 25, 15, 5, 5, 3]),
            coulomb_smoothing_rad_s=0.01,
        )
        self._data = model.createData()

    def new_data(self) -> pin.Data:
        return self.model.createData()

    def copy(self) -> DevRobot:
        other = DevRobot(self.model.copy())
        other.actuation = SimpleNamespace(**{k: np.copy(v) for k, v in vars(self.actuation).items()})
        other.limits = SimpleNamespace(**{k: np.copy(v) for k, v in vars(self.limits).items()})
        return other

    def friction_torque(self, v: np.ndarray) -> np.ndarray:
        a = self.actuation
        return a.viscous_Nms_rad * v + a.coulomb_Nm * np.tanh(v / a.coulomb_smoothing_rad_s)

    def inverse_dynamics(self, q, v, a) -> np.ndarray:
        return pin.rnea(self.model, self._data, q, v, a) + self.friction_torque(v)

    def forward_dynamics(self, q, v, tau) -> np.ndarray:
        return pin.aba(self.model, self._data, q, v, tau - self.friction_torque(v))

    def fk(self, q, frame: str = "tcp") -> pin.SE3:
        fid = self.model.getFrameId(frame)
        pin.framesForwardKinematics(self.model, self._data, q)
        return pin.SE3(self._data.oMf[fid])

    def positions(self, Q, frame: str = "tcp") -> np.ndarray:
        return np.array([self.fk(q, frame).translation for q in np.atleast_2d(Q)])

    def jacobian(self, q, frame: str = "tcp") -> np.ndarray:
        fid = self.model.getFrameId(frame)
        return pin.computeFrameJacobian(self.model, self._data, q, fid, pin.LOCAL_WORLD_ALIGNED)

    def ik(self, target: pin.SE3, q0, frame: str = "tcp", position_only: bool = False):
        q = np.array(q0, float)
        fid = self.model.getFrameId(frame)
        ok = False
        err = np.zeros(6)
        for _ in range(100):
            pin.framesForwardKinematics(self.model, self._data, q)
            cur = self._data.oMf[fid]
            err = np.concatenate([target.translation - cur.translation,
                                  pin.log3(target.rotation @ cur.rotation.T)])
            if np.linalg.norm(err[:3]) < 1e-10 and np.linalg.norm(err[3:]) < 1e-10:
                ok = True
                break
            J = self.jacobian(q, frame)
            q = q + np.linalg.solve(J.T @ J + 1e-10 * np.eye(6), J.T @ err)
        return SimpleNamespace(q=q, success=ok, position_error_m=float(np.linalg.norm(err[:3])),
                               rotation_error_rad=float(np.linalg.norm(err[3:])), message="")


def perturbed(robot: DevRobot, seed: int = 1) -> DevRobot:
    """A 'truth' copy: inertias +-15 %, friction +-20 %, placements 0.5 mm / 0.3 mrad."""
    rng = np.random.default_rng(seed)
    t = robot.copy()
    m = t.model
    for j in range(1, m.njoints):
        p = m.inertias[j].toDynamicParameters()
        p = p * (1 + 0.15 * rng.standard_normal(10))
        inertia = pin.Inertia.FromDynamicParameters(p)
        m.inertias[j] = inertia if inertia.mass > 0 else m.inertias[j]
        M = m.jointPlacements[j]
        dM = pin.exp6(np.concatenate([5e-4 * rng.standard_normal(3), 3e-4 * rng.standard_normal(3)]))
        m.jointPlacements[j] = M * dM
    m.armature = m.armature * (1 + 0.1 * rng.standard_normal(6))
    t.actuation.rotor_inertia_kgm2 = np.array(m.armature).copy()
    t.actuation.viscous_Nms_rad *= 1 + 0.2 * rng.standard_normal(6)
    t.actuation.coulomb_Nm *= 1 + 0.2 * rng.standard_normal(6)
    return t
