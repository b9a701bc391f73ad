"""Capsule collision model: link-link and link-floor distances.

Each link carries one or two capsules (a segment swept by a sphere, ``robot.yaml``). The
distance between two capsules is the segment-segment distance minus both radii; a
negative value is a penetration depth. The batched numpy version serves the candidate
filtering of millions of configurations; :func:`coal_capsule_distance` is the reference
(tested to agree). Floor distance: lowest end point height minus radius.
"""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin


@dataclass
class CapsuleDistances:
    """Signed clearances (m) at one configuration; negative means penetration."""

    pair_names: list[tuple[str, str]]
    pair_m: np.ndarray
    floor_names: list[str]
    floor_m: np.ndarray

    @property
    def self_min_m(self) -> float:
        return float(self.pair_m.min()) if self.pair_m.size else np.inf

    @property
    def floor_min_m(self) -> float:
        return float(self.floor_m.min()) if self.floor_m.size else np.inf


def segment_distances(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Minimum distances between segments ``p0p1`` and ``q0q1`` (arrays ``(..., 3)``), vectorised.

    Closed-form clamp of the two segment parameters (Ericson, *Real-Time Collision
    Detection*, §5.1.9), with the parallel/degenerate cases handled by the clamps.
    """
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = np.einsum("...i,...i->...", d1, d1)
    e = np.einsum("...i,...i->...", d2, d2)
    f = np.einsum("...i,...i->...", d2, r)
    c = np.einsum("...i,...i->...", d1, r)
    b = np.einsum("...i,...i->...", d1, d2)
    denom = a * e - b * b
    tiny = 1e-14
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > tiny * np.maximum(a * e, tiny), np.clip((b * f - c * e) / denom, 0.0, 1.0), 0.0)
        s = np.where(a > tiny, s, 0.0)
        t = np.where(e > tiny, (b * s + f) / np.where(e > tiny, e, 1.0), 0.0)
        # t outside [0, 1]: clamp it and recompute s for the clamped t
        t_clamped = np.clip(t, 0.0, 1.0)
        s_from_t = np.where(a > tiny, np.clip((t_clamped * b - c) / np.where(a > tiny, a, 1.0), 0.0, 1.0), 0.0)
        s = np.where(t != t_clamped, s_from_t, s)
        t = t_clamped
    closest_p = p0 + s[..., None] * d1
    closest_q = q0 + t[..., None] * d2
    return np.linalg.norm(closest_p - closest_q, axis=-1)


def point_segment_distances(point: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """Distances from points to segments ``p0p1`` (arrays broadcast on the leading axes)."""
    d = p1 - p0
    length2 = np.einsum("...i,...i->...", d, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(length2 > 1e-14, np.einsum("...i,...i->...", point - p0, d) / length2, 0.0)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(point - (p0 + t[..., None] * d), axis=-1)


def coal_capsule_distance(a0: np.ndarray, a1: np.ndarray, radius_a: float,
                          b0: np.ndarray, b1: np.ndarray, radius_b: float) -> float:
    """Signed distance between two world-frame capsules computed by coal (reference)."""
    def placed(p0: np.ndarray, p1: np.ndarray, radius: float) -> tuple[coal.Capsule, coal.Transform3s]:
        axis = p1 - p0
        length = float(np.linalg.norm(axis))
        rotation = np.eye(3)
        if length > 1e-12:
            rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), axis / length).matrix()
        return coal.Capsule(radius, length), coal.Transform3s(rotation, 0.5 * (p0 + p1))

    shape_a, pose_a = placed(a0, a1, radius_a)
    shape_b, pose_b = placed(b0, b1, radius_b)
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    return float(coal.distance(shape_a, pose_a, shape_b, pose_b, request, result))
