"""Batched forward kinematics of a serial chain of revolute joints on numpy arrays, for the candidate
filters and Jacobians of :mod:`pipeline.calibration.candidates`.

A :class:`Chain` holds the Pinocchio model's joint placements, axes, capsules, flange, reflector and
the nominal tracker (:func:`chain_from_robot`); :func:`kinematics` gives the world frame of every
joint of N configurations, ``R_i = R_{i-1} R_place,i Rot(axis_i, q_i)``, ``o_i = o_{i-1} + R_{i-1}
p_place,i`` (Rodrigues' formula per axis), as stacked BLAS products: one ``pin.forwardKinematics`` per
row is ~6x slower. Tested to 1e-12 against ``RobotModel`` (tests/calibration/test_candidates_fk.py).
:func:`capsule_segments` moves the collision capsules; :func:`last_joint_expanded` and
:func:`with_last_joint` expand prefix rows along the last joint (the coarse-first grid filter)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.robot.model import RobotModel


@dataclass
class Chain:
    """Numpy description of a serial chain taken from a Pinocchio model."""

    R_place: np.ndarray      # (nq,3,3) joint placements in the parent joint frame
    p_place: np.ndarray      # (nq,3)
    axis: np.ndarray         # (nq,3) revolute axes in the joint frame
    capsule_joint: np.ndarray  # (nc,) 0 = base
    capsule_p: np.ndarray    # (nc,2,3) end points in the joint frame of the capsule's parent joint
    capsule_r: np.ndarray    # (nc,)
    flange_R: np.ndarray     # flange placement in joint nq
    flange_p: np.ndarray
    reflector_p: np.ndarray  # reflector in joint nq frame
    reflector_axis_joint: np.ndarray  # reflector axis in joint nq frame
    self_pairs: np.ndarray   # (n_pairs,2)
    floor_caps: np.ndarray
    floor_z: float
    lower: np.ndarray
    upper: np.ndarray
    tracker_R: np.ndarray    # nominal tracker pose in base (p_base = R p_t + t)
    tracker_t: np.ndarray
    max_incidence_rad: float
    noise_const_m: float
    noise_per_m: float

    @property
    def nq(self) -> int:
        return self.R_place.shape[0]


def chain_from_robot(robot: RobotModel, transform_tracker_to_base: pin.SE3 | None = None) -> Chain:
    """Extract the serial chain, capsules, reflector and tracker facts of a RobotModel."""
    model = robot.model
    nq = model.nq
    for i in range(1, model.njoints):
        if model.parents[i] != i - 1 or model.joints[i].nq != 1:
            raise ValueError("candidate filtering needs a serial chain of one-dof joints")
    R_place = np.stack([model.jointPlacements[i].rotation for i in range(1, nq + 1)])
    p_place = np.stack([model.jointPlacements[i].translation for i in range(1, nq + 1)])
    axes = []
    for i in range(1, nq + 1):
        jd = model.joints[i].createData()
        model.joints[i].calc(jd, np.zeros(1))
        s = np.asarray(jd.S).reshape(6)
        if np.linalg.norm(s[:3]) > 1e-12:
            raise ValueError("candidate filtering supports revolute joints only")
        axes.append(s[3:])
    caps = robot.capsules
    cj, cp = [], []
    for c in caps:
        fr = model.frames[robot.frame_id(c.frame)]
        cj.append(int(fr.parentJoint))
        cp.append(np.stack([fr.placement.act(np.asarray(c.p0, float)), fr.placement.act(np.asarray(c.p1, float))]))
    fl = model.frames[robot.frame_id(robot.frame_flange)]
    rf = model.frames[robot.frame_id(robot.frame_reflector)]
    if fl.parentJoint != nq or rf.parentJoint != nq:
        raise ValueError("flange and reflector must hang on the last joint")
    tr = transform_tracker_to_base if transform_tracker_to_base is not None else \
        robot.tracker.transform_tracker_to_base
    return Chain(
        R_place=R_place, p_place=p_place, axis=np.stack(axes),
        capsule_joint=np.array(cj, int), capsule_p=np.array(cp).reshape(-1, 2, 3),
        capsule_r=np.array([c.radius_m for c in caps], float),
        flange_R=fl.placement.rotation.copy(), flange_p=fl.placement.translation.copy(),
        reflector_p=rf.placement.translation.copy(),
        reflector_axis_joint=rf.placement.rotation @ np.asarray(robot.reflector_axis, float),
        self_pairs=np.array(robot.self_collision_pairs, int).reshape(-1, 2),
        floor_caps=np.array(robot.floor_capsules, int),
        floor_z=float(robot.spec.collision.floor_z_m),
        lower=robot.limits.lower_rad.copy(), upper=robot.limits.upper_rad.copy(),
        tracker_R=tr.rotation.copy(), tracker_t=tr.translation.copy(),
        max_incidence_rad=float(robot.tracker.max_incidence_rad),
        noise_const_m=float(robot.tracker.noise_const_m), noise_per_m=float(robot.tracker.noise_per_m),
    )


def _axis_rotation(axis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Rotation matrices (N,3,3) about a fixed unit axis (Rodrigues ``I + sin q K + (1 - cos q) K^2``, entrywise)."""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    out = np.multiply.outer(K.reshape(9), np.sin(q))
    out += np.eye(3).reshape(9, 1)
    out += np.multiply.outer((K @ K).reshape(9), 1 - np.cos(q))
    return np.ascontiguousarray(out.T).reshape(-1, 3, 3)


@dataclass
class Kinematics:
    """Batched world kinematics of N configurations."""

    Rpre: np.ndarray   # (N,nq,3,3)
    opre: np.ndarray   # (N,nq,3)
    Rpost: np.ndarray  # (N,nq,3,3)
    p_reflector: np.ndarray  # (N,3)
    R_flange: np.ndarray     # (N,3,3)
    o_flange: np.ndarray     # (N,3)
    reflector_axis: np.ndarray  # (N,3) world


def kinematics(chain: Chain, Q: np.ndarray) -> Kinematics:
    """World frames of every joint (before and after its motion), flange and reflector for ``Q`` (N, nq)."""
    Q = np.atleast_2d(np.asarray(Q, float))
    N, nq = Q.shape[0], chain.nq
    Rpre, opre, Rpost = np.empty((nq, N, 3, 3)), np.empty((nq, N, 3)), np.empty((nq, N, 3, 3))
    R, o = np.broadcast_to(np.eye(3), (N, 3, 3)), np.zeros((N, 3))
    for i in range(nq):
        np.matmul(R.reshape(-1, 3), chain.R_place[i], out=Rpre[i].reshape(-1, 3))
        np.add(o, _times(R, chain.p_place[i]), out=opre[i])
        np.matmul(Rpre[i], _axis_rotation(chain.axis[i], Q[:, i]), out=Rpost[i])
        R, o = Rpost[i], opre[i]
    by_row = [np.moveaxis(a, 0, 1) for a in (Rpre, opre, Rpost)]     # (N, nq, ...) views
    return Kinematics(by_row[0], by_row[1], by_row[2], o + _times(R, chain.reflector_p), _times(R, chain.flange_R),
                      o + _times(R, chain.flange_p), _times(R, chain.reflector_axis_joint))


def _times(R: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``R @ B`` for a stack ``R`` (N,3,3), one BLAS product of its 3N rows (OpenBLAS: the stacked product's bits)."""
    return (R.reshape(-1, 3) @ B).reshape(R.shape[:-1] + B.shape[1:])


def capsule_segments(chain: Chain, kin: Kinematics) -> np.ndarray:
    """World capsule end points (N, nc, 2, 3)."""
    N = kin.Rpost.shape[0]
    out = np.empty((N, len(chain.capsule_r), 2, 3))
    for c, j in enumerate(chain.capsule_joint):
        if j == 0:
            out[:, c] = chain.capsule_p[c][None]
        else:
            out[:, c] = np.einsum("nij,kj->nki", kin.Rpost[:, j - 1], chain.capsule_p[c]) + kin.opre[:, j - 1, None]
    return out


def last_joint_expanded(chain: Chain, kin: Kinematics, seg: np.ndarray, q_last: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every row of ``kin`` (its last joint's angle unused) with each angle of ``q_last``: the prefix
    row of each expanded row, the last joint's world rotation, the capsule segments (``seg`` of the
    prefixes, those on the last link moved); row by row the arithmetic of :func:`kinematics`."""
    rows = np.repeat(np.arange(len(seg)), len(q_last))
    R_last = kin.Rpre[rows, -1] @ _axis_rotation(chain.axis[-1], np.tile(q_last, len(seg)))
    seg_all, o_last = seg[rows], kin.opre[rows, -1, None]
    for c in np.flatnonzero(np.asarray(chain.capsule_joint) == chain.nq):
        seg_all[:, c] = np.einsum("nij,kj->nki", R_last, chain.capsule_p[c]) + o_last
    return rows, R_last, seg_all


def with_last_joint(chain: Chain, kin: Kinematics, rows: np.ndarray, R_last: np.ndarray) -> Kinematics:
    """The :class:`Kinematics` of prefix rows ``rows`` with the last joint's world rotation ``R_last``."""
    Rpost, o = kin.Rpost[rows], kin.opre[rows, -1]
    Rpost[:, -1] = R_last
    return Kinematics(kin.Rpre[rows], kin.opre[rows], Rpost, o + _times(R_last, chain.reflector_p),
                      _times(R_last, chain.flange_R), o + _times(R_last, chain.flange_p),
                      _times(R_last, chain.reflector_axis_joint))
