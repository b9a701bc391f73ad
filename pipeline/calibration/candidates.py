"""Candidate measurement configurations: grid / random generation, batched filtering, Jacobians.

Filtering (DESIGN.md "Sensors"; paper 000 §2.2, §3; paper 004 §3.4): inside the joint limits, no
self-collision between capsules of non-adjacent links, no capsule below the floor (with a clearance
margin), and a *predicted* line of sight from the nominal tracker pose (incidence between reflector
axis and beam ``<= max_incidence - margin``, the beam clear of every link capsule). The sensor
decides at measurement time; the margins make the prediction conservative.

The full 13^6 grid (paper 004: 13 values per axis, ~4.8 million) is filtered coarse-first: the 5-axis
prefix grid is checked for everything that does not depend on axis 6, then only the surviving prefixes are
expanded along axis 6 in chunks. All kinematics is batched numpy on the Pinocchio model's joint placements
(:mod:`pipeline.calibration.batch_kinematics`); it is a filter only (decisions that must match the sensor are
re-checked with Pinocchio, e.g. :mod:`pipeline.calibration.gradient_design`).

The whitened candidate Jacobians: the first-order model of :mod:`pipeline.calibration.error_model` at x = 0 in
closed form (a twist (v, w) on a frame F moves a point p by ``R_F v + (R_F w) x (p - o_F)``), tested against CasADi."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields

import numpy as np
import pinocchio as pin

# Chain, chain_from_robot and kinematics are named here too: callers build a chain and its candidates from one module
from pipeline.calibration.batch_kinematics import (  # noqa: F401
    Chain,
    Kinematics,
    capsule_segments,
    chain_from_robot,
    kinematics,
    last_joint_expanded,
    with_last_joint,
)
from pipeline.core.forks import fork_map
from pipeline.core.progress import TaskHandle
from pipeline.robot.collision import segment_distances
from pipeline.robot.instruments import BEAM_END_CLEARANCE_M


@dataclass
class FilterMargins:
    """Conservative margins of the predicted feasibility."""

    collision_m: float = 0.01
    incidence_rad: float = np.deg2rad(3.0)
    beam_m: float = 0.02


def _collision_ok(chain: Chain, seg: np.ndarray, margins: FilterMargins, pairs: np.ndarray,
                  floor: np.ndarray) -> np.ndarray:
    """``(N,)`` every capsule clear of the floor and of every other capsule of ``pairs`` by the margin. The floor
    first (cheap), then pair by pair (the most rejecting on the first 256 rows first) on the rows still clear
    only: the same row-wise arithmetic, so the same mask, without the distances of rows already rejected."""
    ok = np.ones(seg.shape[0], bool)
    for c in floor:
        ok &= seg[:, c, :, 2].min(axis=1) - chain.capsule_r[c] - chain.floor_z >= margins.collision_m
    used = np.unique(pairs)                     # (n_used, 2, N, 3): the end points of the paired capsules
    ends, slot = np.ascontiguousarray(seg[:, used].transpose(1, 2, 0, 3)), {c: i for i, c in enumerate(used.tolist())}

    def clear(a: int, b: int, rows: np.ndarray) -> np.ndarray:
        p = [ends[slot[c], k].take(rows, axis=0) for c, k in ((a, 0), (a, 1), (b, 0), (b, 1))]
        return segment_distances(*p) - chain.capsule_r[a] - chain.capsule_r[b] >= margins.collision_m

    rows = np.flatnonzero(ok)
    for a, b in sorted(pairs.reshape(-1, 2).tolist(), key=lambda p: clear(p[0], p[1], rows[:256]).sum()):
        rows = rows[clear(a, b, rows)]
    ok[:] = False
    ok[rows] = True
    return ok


def incidence_ok(chain: Chain, kin: Kinematics, margins: FilterMargins) -> np.ndarray:
    """Incidence angle between the reflector axis and the beam ``<= max_incidence - margin``."""
    beam = chain.tracker_t[None] - kin.p_reflector
    dist = np.linalg.norm(beam, axis=1)
    cosang = np.einsum("ni,ni->n", kin.reflector_axis, beam) / np.maximum(dist, 1e-12)
    return cosang >= np.cos(max(chain.max_incidence_rad - margins.incidence_rad, 0.0))


def beam_blockers(chain: Chain, kin: Kinematics, seg: np.ndarray, margins: FilterMargins,
                  idx: np.ndarray) -> np.ndarray:
    """(len(idx), nc) mask: capsule c blocks the beam of configuration ``idx[k]``.

    Like the sensor: the beam from the tracker to a point ``BEAM_END_CLEARANCE_M`` before the
    reflector, clear of each capsule by ``margins.beam_m`` (no margin for the reflector's own link:
    rigid, known geometry)."""
    beam = chain.tracker_t[None] - kin.p_reflector[idx]
    dist = np.linalg.norm(beam, axis=1)
    p0 = kin.p_reflector[idx] + BEAM_END_CLEARANCE_M * (beam / np.maximum(dist, 1e-12)[:, None])
    p1 = np.broadcast_to(chain.tracker_t, p0.shape)
    out = np.zeros((len(idx), seg.shape[1]), bool)
    for c in range(seg.shape[1]):
        d = segment_distances(p0, p1, seg[idx, c, 0], seg[idx, c, 1])
        margin = 0.0 if chain.capsule_joint[c] == chain.nq else margins.beam_m
        out[:, c] = d - chain.capsule_r[c] < margin
    return out


def _visibility_ok(chain: Chain, kin: Kinematics, seg: np.ndarray, margins: FilterMargins,
                   incidence_checked: bool = False) -> np.ndarray:     # incidence_checked: every row within it
    ok = np.ones(len(seg), bool) if incidence_checked else incidence_ok(chain, kin, margins)
    idx = np.flatnonzero(ok)
    if idx.size:
        ok[idx[beam_blockers(chain, kin, seg, margins, idx).any(axis=1)]] = False
    return ok


def filter_configurations(chain: Chain, Q: np.ndarray, margins: FilterMargins | None = None, visibility: bool = True,
                          chunk: int = 200_000, reasons: bool = True) -> tuple[np.ndarray, dict]:
    """Feasibility mask of ``Q`` and counts of the reasons for rejection. ``reasons=False``: the same mask sooner,
    the incidence (2 % of random poses pass) before the capsules of its rows; a row failing both counts as hidden."""
    margins = margins or FilterMargins()
    Q = np.atleast_2d(np.asarray(Q, float))
    mask = np.zeros(len(Q), bool)
    counts = {"total": len(Q), "limits": 0, "collision": 0, "visibility": 0}
    for s in range(0, len(Q), chunk):
        Qc = Q[s : s + chunk]
        ok = np.all((Qc >= chain.lower) & (Qc <= chain.upper), axis=1)
        counts["limits"] += int((~ok).sum())
        kin, rows = kinematics(chain, Qc), np.arange(len(Qc))
        if visibility and not reasons:
            inc = incidence_ok(chain, kin, margins)
            counts["visibility"] += int((ok & ~inc).sum())
            ok &= inc
            rows = np.flatnonzero(ok)
            kin = Kinematics(*(getattr(kin, f.name)[rows] for f in fields(Kinematics)))
        seg = capsule_segments(chain, kin)
        col = _collision_ok(chain, seg, margins, chain.self_pairs, chain.floor_caps)
        counts["collision"] += int((ok[rows] & ~col).sum())
        ok[rows] &= col
        if visibility:
            vis = _visibility_ok(chain, kin, seg, margins, incidence_checked=not reasons)
            counts["visibility"] += int((ok[rows] & ~vis).sum())
            ok[rows] &= vis
        mask[s : s + len(Qc)] = ok
    counts["feasible"] = int(mask.sum())
    return mask, counts


def grid_values(chain: Chain, n_per_axis: int | list[int]) -> list[np.ndarray]:
    """Midpoints of ``n`` equal intervals of each joint range (paper 004 §3.4: 13 per axis)."""
    ns = [n_per_axis] * chain.nq if np.isscalar(n_per_axis) else list(n_per_axis)
    return [chain.lower[i] + (np.arange(n) + 0.5) * (chain.upper[i] - chain.lower[i]) / n
            for i, n in enumerate(ns)]


def filter_grid(chain: Chain, n_per_axis: int | list[int] = 13, margins: FilterMargins | None = None,
                chunk: int = 20_000, progress: TaskHandle | None = None,
                visibility: Callable[[Kinematics, np.ndarray], np.ndarray] | None = None
                ) -> tuple[np.ndarray, np.ndarray, dict]:
    """Coarse-first filtering of the full joint-space grid: the feasible configurations (M, nq) in lexicographic
    grid order, their flat grid indices, and counts. The prefix grid over axes 1..nq-1 (the last axis does not
    move capsules off the last link) is checked for collisions between capsules not on the last joint; survivors
    are expanded along the last axis in chunks and checked for the remaining pairs, floor and visibility.
    ``progress``: an optional :class:`pipeline.core.progress.TaskHandle` advanced over the collision-free prefixes.
    ``visibility(kinematics, capsule_segments) -> mask``: another sensor's line of sight (e.g. the optical 6-D
    tracker, :mod:`pipeline.sim.optical_tracker`) instead of the laser tracker's."""
    t0 = time.perf_counter()
    margins = margins or FilterMargins()
    vals = grid_values(chain, n_per_axis)
    nq = chain.nq
    sizes = [len(v) for v in vals]
    total = int(np.prod(sizes))
    last = nq
    pre_pairs = np.array([p for p in chain.self_pairs if chain.capsule_joint[p].max() < last], int).reshape(-1, 2)
    post_pairs = np.array([p for p in chain.self_pairs if chain.capsule_joint[p].max() >= last], int).reshape(-1, 2)
    pre_floor = np.array([c for c in chain.floor_caps if chain.capsule_joint[c] < last], int)
    post_floor = np.array([c for c in chain.floor_caps if chain.capsule_joint[c] >= last], int)
    # prefix grid (axes 1..nq-1) built level by level, keeping only collision-free prefixes
    prefix = np.zeros((1, 0))
    for i in range(nq - 1):
        prefix = np.concatenate([np.repeat(prefix, sizes[i], axis=0),
                                 np.tile(vals[i], len(prefix))[:, None]], axis=1)
        Qp = np.concatenate([prefix, np.zeros((len(prefix), nq - prefix.shape[1]))], axis=1)
        pairs = np.array([p for p in pre_pairs if chain.capsule_joint[p].max() == i + 1], int).reshape(-1, 2)
        floor = np.array([c for c in pre_floor if chain.capsule_joint[c] == i + 1], int)
        if len(pairs) or len(floor):
            keep = np.ones(len(Qp), bool)
            for s in range(0, len(Qp), 100_000):
                kin = kinematics(chain, Qp[s : s + 100_000])
                seg = capsule_segments(chain, kin)
                keep[s : s + 100_000] = _collision_ok(chain, seg, margins, pairs, floor)
            prefix = prefix[keep]
    n_prefix_ok = len(prefix)
    if progress is not None:
        progress.update(total=n_prefix_ok)
    # expand along the last axis
    feas_Q, counts = [], {"total": total, "prefix_collision_free": n_prefix_ok,
                          "collision": 0, "visibility": 0}
    n_last = sizes[-1]

    def expand(k: int) -> tuple[np.ndarray, int, int]:
        """Chunk ``k`` of the prefixes along the last axis: (feasible rows, collisions, not visible)."""
        P = prefix[k * chunk : (k + 1) * chunk]
        kin = kinematics(chain, np.concatenate([P, np.zeros((len(P), 1))], axis=1))
        rows, R_last, seg = last_joint_expanded(chain, kin, capsule_segments(chain, kin), vals[-1])
        ok = _collision_ok(chain, seg, margins, post_pairs, post_floor)
        idx = np.flatnonzero(ok)
        if not idx.size:
            return np.zeros((0, nq)), int((~ok).sum()), 0
        sub = with_last_joint(chain, kin, rows[idx], R_last[idx])
        vis = (_visibility_ok(chain, sub, seg[idx], margins) if visibility is None
               else visibility(sub, seg[idx]))
        keep = idx[vis]
        return (np.concatenate([P[rows[keep]], vals[-1][keep % n_last][:, None]], axis=1),
                int((~ok).sum()), int((~vis).sum()))

    # the chunks are independent: side by side on the available cores, results in chunk order
    n_chunks = -(-len(prefix) // chunk)
    for k, (rows, n_collision, n_hidden) in enumerate(fork_map(expand, n_chunks)):
        counts["collision"] += n_collision
        counts["visibility"] += n_hidden
        feas_Q.append(rows)
        if progress is not None:
            progress.advance(len(prefix[k * chunk : (k + 1) * chunk]))
    Qf = np.concatenate(feas_Q) if feas_Q else np.zeros((0, nq))
    # flat grid indices (lexicographic, axis 1 slowest)
    steps = [(chain.upper[i] - chain.lower[i]) / sizes[i] for i in range(nq)]
    ks = np.rint((Qf - chain.lower) / np.array(steps) - 0.5).astype(np.int64)
    flat = np.ravel_multi_index(ks.T, sizes) if len(Qf) else np.zeros(0, np.int64)
    counts["collision"] += total - n_prefix_ok * n_last
    counts["feasible"] = len(Qf)
    counts["time_s"] = time.perf_counter() - t0
    return Qf, flat, counts


def random_candidates(chain: Chain, n: int, rng: np.random.Generator, margins: FilterMargins | None = None,
                      max_draws: int = 50, visibility: bool = True, count_all: bool = False) -> tuple[np.ndarray, dict]:
    """``n`` feasible uniformly random configurations (batches drawn until enough), rejection counts of the draws
    filtered (unless ``count_all``: the last batch's up to its n-th feasible draw, reasons as ``reasons=False``)."""
    out, counts = [], {"total": 0, "limits": 0, "collision": 0, "visibility": 0, "feasible": 0}
    have, rate = 0, 0.01
    for _ in range(max_draws):
        size = int(min(max(1.3 * (n - have) / rate, 2000), 400_000))
        Q = rng.uniform(chain.lower, chain.upper, size=(size, chain.nq))
        start, chunk = 0, size if count_all else 2048   # doubling chunks: row by row the same arithmetic
        while start < size and have < n:
            mask, c = filter_configurations(chain, Q[start : start + chunk], margins, visibility=visibility,
                                            reasons=count_all)
            for k in counts:
                counts[k] += c.get(k, 0)
            out.append(Q[start : start + chunk][mask])
            have += int(mask.sum())
            start, chunk = start + chunk, 2 * chunk
        rate = max(counts["feasible"] / max(counts["total"], 1), 1e-4)
        if have >= n:
            break
    return np.concatenate(out)[:n], counts


def _skew_batch(v: np.ndarray) -> np.ndarray:
    z = np.zeros(v.shape[0])
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1), np.stack([v[:, 2], z, -v[:, 0]], 1),
                     np.stack([-v[:, 1], v[:, 0], z], 1)], 1)


def nominal_jacobian(chain: Chain, Q: np.ndarray, transform_tracker_to_base: pin.SE3,
                     chunk: int = 100_000) -> tuple[np.ndarray, np.ndarray]:
    """Tracker-frame reflector positions (N,3) and Jacobian (N,3,n_x) at ``x = 0``.

    Column layout = :class:`~pipeline.calibration.error_model.MeasurementModel` ``names``:
    ``j{i}.dx..rz`` (6 nq), ``j{i}.dq`` (nq), ``base.*`` (6), ``tool.*`` (6), ``tracker.*`` (6),
    ``reflector.*`` (3).
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    nq = chain.nq
    n_x = 7 * nq + 12 + 9
    R0 = np.asarray(transform_tracker_to_base.rotation)
    t0 = np.asarray(transform_tracker_to_base.translation)
    Y = np.empty((len(Q), 3))
    J = np.empty((len(Q), 3, n_x))
    for s in range(0, len(Q), chunk):
        kin = kinematics(chain, Q[s : s + chunk])
        n = kin.p_reflector.shape[0]
        p = kin.p_reflector
        Jb = np.empty((n, 3, n_x))  # base-frame rows
        for i in range(nq):
            Rf, of = kin.Rpre[:, i], kin.opre[:, i]
            Jb[:, :, 6 * i : 6 * i + 3] = Rf
            Jb[:, :, 6 * i + 3 : 6 * i + 6] = -_skew_batch(p - of) @ Rf
            a = Rf @ chain.axis[i]
            Jb[:, :, 6 * nq + i] = np.cross(a, p - of)
        b = 7 * nq
        Jb[:, :, b : b + 3] = np.eye(3)
        Jb[:, :, b + 3 : b + 6] = -_skew_batch(p)
        Jb[:, :, b + 6 : b + 9] = kin.R_flange
        Jb[:, :, b + 9 : b + 12] = -_skew_batch(p - kin.o_flange) @ kin.R_flange
        Jb[:, :, b + 18 : b + 21] = kin.R_flange  # reflector offset in the flange-aligned frame
        y = (p - t0) @ R0                          # R0^T (p - t0)
        Jc = np.einsum("ji,njk->nik", R0, Jb)      # R0^T Jb
        Jc[:, :, b + 12 : b + 15] = -np.eye(3)
        Jc[:, :, b + 15 : b + 18] = _skew_batch(y)  # -w x y = y x w
        Y[s : s + n] = y
        J[s : s + n] = Jc
    return Y, J


def with_compliance_columns(J: np.ndarray, tau_Nm: np.ndarray) -> np.ndarray:
    """``J`` (N, m, 7 nq + 21) of :func:`nominal_jacobian` with the joint compliance columns appended
    (the elastostatic layout of :class:`~pipeline.calibration.error_model.MeasurementModel`).

    ``q_link = q - c tau(q)`` (paper 000 Outlook; error_model.py), so at ``c = 0``
    ``dy/dc_j = -tau_j(q) dy/dq_j`` and ``dy/dq_j`` is the joint zero-offset column ``j{j}.dq``
    (indices ``6 nq .. 7 nq - 1``). ``tau_Nm`` (N, nq): the static joint torques of each row."""
    nq = tau_Nm.shape[1]
    return np.concatenate([J, -tau_Nm[:, None, :] * J[:, :, 6 * nq : 7 * nq]], axis=2)


def noise_sigma(chain: Chain, Y: np.ndarray) -> np.ndarray:
    """Isotropic tracker sigma (m) at the range of each tracker-frame point (DESIGN.md)."""
    return chain.noise_const_m + chain.noise_per_m * np.linalg.norm(Y, axis=1)


@dataclass
class CandidateSet:
    """Feasible candidates with their whitened Jacobians wrt the identifiable parameters."""

    Q: np.ndarray            # (N,nq)
    Y: np.ndarray            # (N,3) predicted tracker-frame reflector positions (nominal)
    sigma_m: np.ndarray      # (N,)
    G: np.ndarray            # (N,3,p) whitened Jacobian blocks (J / sigma)
    basis: np.ndarray        # (n_full, p) identifiable parameter basis
    counts: dict = field(default_factory=dict)
    grid_index: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.Q)


def build_candidate_set(chain: Chain, Q: np.ndarray, basis: np.ndarray, T0: pin.SE3, counts: dict | None = None,
                        grid_index: np.ndarray | None = None, dtype=np.float64,
                        static_torques: Callable[[np.ndarray], np.ndarray] | None = None) -> CandidateSet:
    """Whitened Jacobian blocks ``J P / sigma`` (identifiable basis P) for feasible configurations.

    A basis with rows beyond the geometric ``7 nq + 21`` holds joint compliances (elastostatic
    model): ``static_torques(Q) -> (N, nq)`` (N m) then gives the gravity torques of the compliance
    columns (:func:`with_compliance_columns`)."""
    P = np.asarray(basis, float)
    N = len(Q)
    n_geo = 7 * chain.nq + 21
    if P.shape[0] > n_geo and static_torques is None:
        raise ValueError("a basis with compliance rows needs the static torques of the candidates")
    G = np.empty((N, 3, P.shape[1]), dtype)
    Y = np.empty((N, 3))
    for s in range(0, N, 50_000):
        y, J = nominal_jacobian(chain, Q[s : s + 50_000], T0)
        if P.shape[0] > n_geo and static_torques is not None:
            J = with_compliance_columns(J, np.asarray(static_torques(Q[s : s + 50_000]), float))
        Y[s : s + len(y)] = y
        sig = noise_sigma(chain, y)
        G[s : s + len(y)] = (J @ P) / sig[:, None, None]
    return CandidateSet(np.asarray(Q, float), Y, noise_sigma(chain, Y), G, P, counts or {}, grid_index)
