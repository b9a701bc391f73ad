"""The self-collision and floor check of a robot's capsules (:class:`pipeline.robot.model.RobotModel`).

Which pairs are checked: two link capsules whose parent joints are more than one apart (not
neighbouring links) and that ``collision.ignore_pairs`` does not list; the floor is checked for
the capsules on joint ``collision.floor_check_from_joint`` and after. A clearance is the distance
between the capsules' axis segments (:func:`pipeline.robot.collision.segment_distances`) minus
both radii; to the floor, the lowest end point's height above ``collision.floor_z_m`` minus the
radius. A checked pair closer than :data:`PAIR_MARGIN_M` in (almost) every random configuration
would reject every candidate configuration: :func:`always_colliding_pairs`.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pipeline.core.errors import RobotFileError
from pipeline.robot.collision import segment_distances
from pipeline.robot.spec import Capsule, RobotSpec

#: a capsule pair closer than :data:`PAIR_MARGIN_M` in at least this share of random configurations
#: always collides
ALWAYS_COLLIDING_SHARE = 0.95
#: the self-collision clearance the stages keep (``calibration.margin_collision_m``'s default, the ranked
#: default poses): a pair always closer than this rejects every configuration as surely as an overlap
PAIR_MARGIN_M = 0.01
#: assumed (fitted) capsules: pairs overlapping in this share of random configurations are neighbours in
#: all but name (a UR base and shoulder) and are left out of the self-collision check
ASSUMED_COLLIDING_SHARE = 0.3


def checked_pairs(spec: RobotSpec, capsule_joints: list[int]) -> tuple[list[tuple[int, int]], list[int]]:
    """(capsule index pairs checked against each other, capsule indices checked against the floor),
    from the parent joint of each capsule's frame."""
    names = [c.name for c in spec.capsules]
    ignored = {frozenset(pair) for pair in spec.collision.ignore_pairs}
    self_pairs = [(i, k) for i in range(len(spec.capsules)) for k in range(i + 1, len(spec.capsules))
                  if abs(capsule_joints[i] - capsule_joints[k]) > 1
                  and frozenset((names[i], names[k])) not in ignored]
    floor_capsules = [i for i, j in enumerate(capsule_joints) if j >= spec.collision.floor_check_from_joint]
    return self_pairs, floor_capsules


def capsule_segments(model: pin.Model, data: pin.Data, capsules: list[Capsule], frame_ids: list[int],
                     Q: np.ndarray) -> np.ndarray:
    """World end points of every capsule (``frame_ids``: each capsule's frame), shape
    ``(N, n_capsules, 2, 3)``."""
    Q = np.atleast_2d(np.asarray(Q, float))
    local = np.stack([np.stack([c.p0, c.p1]) for c in capsules]) if capsules else np.zeros((0, 2, 3))
    out = np.empty((len(Q), len(capsules), 2, 3))
    for k, q in enumerate(Q):
        pin.forwardKinematics(model, data, q)
        for i, fid in enumerate(frame_ids):
            placement = pin.updateFramePlacement(model, data, fid)
            out[k, i] = local[i] @ placement.rotation.T + placement.translation
    return out


def capsule_clearances(spec: RobotSpec, self_pairs: list[tuple[int, int]], floor_capsules: list[int],
                       segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Self-pair and floor clearances ``(N, n_pairs)``, ``(N, n_floor)`` from capsule segments."""
    radii = np.array([c.radius_m for c in spec.capsules])
    if self_pairs:
        i, k = np.array(self_pairs).T
        pair = segment_distances(segments[:, i, 0], segments[:, i, 1], segments[:, k, 0], segments[:, k, 1])
        pair = pair - radii[i] - radii[k]
    else:
        pair = np.zeros((len(segments), 0))
    floor_idx = np.array(floor_capsules, dtype=int)
    floor = segments[:, floor_idx][..., 2].min(axis=-1) - radii[floor_idx] - spec.collision.floor_z_m
    return pair, floor


def always_colliding_pairs(spec: RobotSpec, self_pairs: list[tuple[int, int]], pair_clearances_m: np.ndarray,
                           fix: bool) -> list[tuple[int, int]]:
    """The checked pairs closer than :data:`PAIR_MARGIN_M` in (almost) every one of the random
    configurations whose clearances ``pair_clearances_m (N, n_pairs)`` are.

    ``fix`` (assumed capsules): a pair overlapping in :data:`ASSUMED_COLLIDING_SHARE` of them is
    added to ``spec.collision.ignore_pairs`` with a stated assumption and returned; otherwise a pair
    overlapping in :data:`ALWAYS_COLLIDING_SHARE` is a :class:`RobotFileError` naming it and the fix.
    """
    share = (pair_clearances_m < PAIR_MARGIN_M).mean(axis=0)
    bad = [self_pairs[i] for i in np.flatnonzero(share >= (ASSUMED_COLLIDING_SHARE if fix
                                                           else ALWAYS_COLLIDING_SHARE))]
    if not bad:
        return []
    names = [(spec.capsules[i].name, spec.capsules[k].name) for i, k in bad]
    if not fix:
        i, k = bad[0]
        raise RobotFileError(spec.path, "capsules", f"capsules '{names[0][0]}' and '{names[0][1]}' overlap in "
                             f"{share[self_pairs.index((i, k))]:.0%} of random configurations (closer than "
                             f"{PAIR_MARGIN_M * 1e3:.0f} mm): shrink "
                             "them (radius_m, p0, p1) or list the pair under collision.ignore_pairs")
    spec.collision.ignore_pairs = list(spec.collision.ignore_pairs) + names
    spec.assumptions.append("capsule pairs overlapping in almost every configuration left out of the "
                            f"self-collision check: {', '.join(f'{a}-{b}' for a, b in names)}")
    return bad
