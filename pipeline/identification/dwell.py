"""The rows of a record at which a joint dwells: held by its dry friction, its effort not a function of the state.

A joint of a recorded arm that stays still while the others move (a wrist waiting at a position) is
held by its static friction: its drive logs whatever torque, within the breakaway band, keeps it
there, which depends on the motion's history (presliding, the position loop's integrator), not on
the state the rigid-body model and the friction law see (Armstrong-Hélouvry, Dupont & Canudas de
Wit 1994, Automatica 30(7), §2: static friction is a force of constraint, not a function of the
velocity). Fitted, those rows pull the base parameters towards torques the model cannot produce; the
simulated arm whose dry friction sticks leaves the same band out for the same reason
(:func:`.measure.without_stiction_band`).

Joint ``j`` dwells at sample ``k`` when ``|v_j| < DWELL_SPEED_RAD_S`` over a contiguous run of at
least ``MIN_DWELL_S`` (a velocity reversal passes the band in a few samples and is not a dwell; at
rest for that long, the joint is held). Its rows at those samples carry no equation in the fits (the
regressor row and the torque set to zero: no least-squares fit sees them; Gautier's per-joint sigma
counts the rows that have an equation, :func:`.estimate._joint_sigmas`); the other joints' rows of the
same samples stay. The validation scores every sample of the held-out tail, dwells included: only
the fits leave them out.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from pipeline.identification.measure import ProcessedData

#: a joint slower than this is at rest (rad/s, 0.3 deg/s)
DWELL_SPEED_RAD_S = 0.005
#: ... when it stays so for at least this long (s)
MIN_DWELL_S = 0.2


def dwell_rows(v_rad_s: np.ndarray, sample_time_s: float) -> np.ndarray:
    """(N, n) bool: the samples at which each column of the velocities ``v_rad_s`` (N, n) dwells (module doc)."""
    slow = np.abs(np.asarray(v_rad_s, float)) < DWELL_SPEED_RAD_S
    min_run = max(int(np.ceil(MIN_DWELL_S / sample_time_s)), 1)
    out = np.zeros_like(slow)
    for j in range(slow.shape[1]):
        edges = np.flatnonzero(np.diff(np.concatenate([[0], slow[:, j].astype(np.int8), [0]])))
        for start, stop in zip(edges[0::2], edges[1::2], strict=True):
            if stop - start >= min_run:
                out[start:stop, j] = True
    return out


@dataclass
class Dwells:
    """The rows of a record's torque columns at which their joint dwells (:func:`dwell_rows`)."""

    rows: np.ndarray  # (N, n_rows) bool

    @classmethod
    def of(cls, data: ProcessedData) -> Dwells:
        v = data.v if data.rows is None else data.v[:, data.rows]
        return cls(dwell_rows(v, data.sample_time_s))

    @property
    def per_joint(self) -> np.ndarray:
        """(n_rows,) int: the dwell rows of each torque column."""
        return np.sum(self.rows, axis=0).astype(int)

    def without_equations(self, data: ProcessedData, first: int | None = None) -> ProcessedData:
        """``data`` with the dwell rows (of the first ``first`` samples; None: all) carrying no equation:
        regressor row, torque and velocity of that joint zero (the velocity so that a friction term of
        the row, e.g. the Stribeck or load-dependent column, is zero there too)."""
        n, nr = data.tau.shape
        mask = self.rows.copy()
        if first is not None:
            mask[first:] = False
        if not mask.any():
            return data
        Y = data.Y.reshape(n, nr, -1).copy()
        Y[mask] = 0.0
        tau = np.where(mask, 0.0, data.tau)
        cols = np.arange(data.v.shape[1]) if data.rows is None else np.asarray(data.rows)
        v = data.v.copy()
        v_full = None if data.v_full is None else data.v_full.copy()
        for i, j in enumerate(cols):
            v[mask[:, i], j] = 0.0
            if v_full is not None:
                v_full[mask[:, i], :, j] = 0.0
        return replace(data, Y=Y.reshape(n * nr, -1), tau=tau, v=v, v_full=v_full)

    def summary(self, per_joint: Callable[[np.ndarray], list]) -> dict:
        """Summary entries: the dwell rows per joint left out of the fits (``per_joint``: a value per torque
        column to all joints) and the rule."""
        counts = per_joint(self.per_joint)
        return {"dwell_rows_left_out_of_fits": [None if c is None else int(c) for c in counts],
                "dwell_rule": f"|v| < {DWELL_SPEED_RAD_S} rad/s for at least {MIN_DWELL_S} s"}
