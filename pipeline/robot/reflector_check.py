"""The tracker's reflector must lie outside every collision capsule.

A reflector inside a capsule is "in collision" (or hidden by the arm) in every pose, and a search
for candidate calibration poses runs for minutes before it fails. A URDF whose last link frame is
at the wrist centre (ROS-Industrial KUKA and ABB files, whose flange is ``tool0``) puts a
reflector a few centimetres from that frame inside the wrist. The test: over random
configurations inside the limits (seed 0), the reflector's distance to each capsule's segment
minus its radius; a capsule that holds the reflector in at least ``INSIDE_SHARE`` of them holds
it for good (it moves with the flange or turns about an axis through the reflector).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from pipeline.robot.spec import Capsule, RobotSpec

INSIDE_SHARE = 0.5
SAMPLES = 64


def _point_segment_m(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    t = 0.0 if ab @ ab < 1e-18 else float(np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0))
    return float(np.linalg.norm(p - a - t * ab))


def capsules_holding(model: pin.Model, flange_frame: str, offset_m: np.ndarray,
                     capsules: Sequence[Capsule], clearance_m: float = 0.0) -> list[tuple[str, float, float]]:
    """(capsule name, share of configurations, largest depth m) of every capsule that holds the point
    ``offset_m`` (flange frame) in at least ``INSIDE_SHARE`` of random configurations; with
    ``clearance_m``, a capsule grown by it (the point closer than that to its surface)."""
    if not capsules:
        return []
    data = model.createData()
    flange = model.getFrameId(flange_frame)
    # a capsule's frame: a model frame, else a joint of that name (models built in code); else skipped
    frames = [("f", model.getFrameId(c.frame)) if model.existFrame(c.frame) else
              ("j", model.getJointId(c.frame)) if model.existJointName(c.frame) else None for c in capsules]
    # unbounded joints (models built in code): one turn
    lo, hi = np.maximum(model.lowerPositionLimit, -np.pi), np.minimum(model.upperPositionLimit, np.pi)
    lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
    Q = np.random.default_rng(0).uniform(lo, hi, (SAMPLES, model.nq))
    depth = np.empty((SAMPLES, len(capsules)))
    for n, q in enumerate(Q):
        pin.framesForwardKinematics(model, data, q)
        point = data.oMf[flange].act(np.asarray(offset_m, float))
        for k, (capsule, frame) in enumerate(zip(capsules, frames, strict=True)):
            if frame is None:
                depth[n, k] = -np.inf
                continue
            pose = data.oMf[frame[1]] if frame[0] == "f" else data.oMi[frame[1]]
            distance_m = _point_segment_m(point, pose.act(capsule.p0), pose.act(capsule.p1))
            depth[n, k] = capsule.radius_m + clearance_m - distance_m
    share = (depth > 0).mean(axis=0)
    return [(capsules[k].name, float(share[k]), float(depth[:, k].max()))
            for k in map(int, np.flatnonzero(share >= INSIDE_SHARE))]


def describe(holding: list[tuple[str, float, float]]) -> str:
    """``capsule 'link5' in 100 % of configurations (up to 42 mm deep)``, joined."""
    return "; ".join(f"capsule '{name}' in {share:.0%} of configurations (up to {depth * 1e3:.0f} mm deep)"
                     for name, share, depth in holding)


def marker_points(spec: RobotSpec) -> list[tuple[str, str, np.ndarray]]:
    """(robot.yaml field, what, point in the flange frame) of the reflector and of every optical-probe
    diode (diodes sit in the marker frame: flange orientation at the reflector offset)."""
    offset = np.asarray(spec.tool.reflector_offset_m, float)
    points = [("tool.reflector_offset_m", "the reflector", offset)]
    if spec.optical_tracker is not None:
        points += [(f"optical_tracker.probe_diodes_m[{k}]", f"probe diode {k}", offset + np.asarray(d, float))
                   for k, d in enumerate(spec.optical_tracker.probe_diodes_m)]
    return points
