"""The identifiable set as the feasible configurations see it: what the design can identify.

The identifiable set (:func:`pipeline.calibration.design.identify_parameter_set`) comes from random
configurations over the whole joint range. The design chooses among the *feasible* candidates
only (the reflector seen by the tracker within its incidence angle, a clear beam, no collision),
and on some arms these cannot tell every parameter apart: a tool frame at the wrist centre (the
reflector offset and the last joints' offsets move the reading alike in the poses where it is
seen), parallel axes, a wrist too light for its compliance to show. Every selector then fails its
regularity test ("information matrix: singular") although the arm can move and be measured.

Here the set shrinks to what the pool identifies: the stacked whitened Jacobian of the candidates
``G`` (rows: all readings, columns: the identifiable parameters in the design's units) is
column-normalised and factorised by QR with column pivoting (Businger & Golub 1965; the
rank-revealing use of paper 002's SVD detection): ``G Pi = Q R``, ``|R_11| >= |R_22| >= ...``. The
parameters whose ``|R_kk| <= POOL_REL_TOL |R_11|`` are dropped (held at their nominal values, as the
identifiability analysis holds the unidentifiable ones) and the design optimises the rest. The
report lists each dropped parameter and why; ``POOL_REL_TOL = 1e-5`` on the diagonal of ``R``
is the square root of the selectors' regularity test on eigenvalues (1e-10 of the largest,
:func:`pipeline.calibration.design._random_regular_start`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from pipeline.calibration import candidates as cd
from pipeline.calibration.elastostatic import design_basis
from pipeline.calibration.outcome import ModelSetUp

#: a parameter is identifiable from the pool when its pivoted-QR diagonal exceeds this share of the largest
POOL_REL_TOL = 1e-5


@dataclass(frozen=True)
class DroppedParameter:
    """A parameter the feasible configurations cannot identify: its name, the pivoted-QR diagonal
    relative to the largest (its share of independent information) and the sentence saying why."""

    name: str
    relative_r: float
    why: str


def pool_identifiable_columns(G: np.ndarray, rel_tol: float = POOL_REL_TOL) -> tuple[np.ndarray, np.ndarray]:
    """(kept column indices, relative ``|R_kk|`` of every column) of the stacked blocks ``G``
    (N, m, p) by column-pivoted QR of the column-normalised stack (module docstring)."""
    A = np.asarray(G, float).reshape(-1, G.shape[-1])
    norms = np.linalg.norm(A, axis=0)
    An = A / np.where(norms > 0, norms, 1.0)
    _, R, pivots = scipy.linalg.qr(An, mode="economic", pivoting=True)
    diag = np.abs(np.diag(R))
    relative = np.zeros(A.shape[1])
    relative[pivots[:len(diag)]] = diag / max(float(diag[0]) if diag.size else 0.0, 1e-300)
    relative[norms == 0] = 0.0
    return np.flatnonzero(relative > rel_tol), relative


def restrict_to_pool(model: ModelSetUp, cs: cd.CandidateSet, rel_tol: float = POOL_REL_TOL
                     ) -> tuple[cd.CandidateSet, list[DroppedParameter]]:
    """Drop from ``model`` (in place: basis, design basis, identifiability report) and from the
    candidates' Jacobian blocks the parameters the feasible candidates cannot identify; the
    candidate set to design on and the dropped parameters (none: both unchanged)."""
    if len(cs) == 0:
        return cs, []
    keep, relative = pool_identifiable_columns(cs.G, rel_tol)
    p = cs.G.shape[-1]
    if len(keep) == p:
        return cs, []
    names = model.report.identifiable_names
    dropped = [DroppedParameter(names[k], float(relative[k]),
                                f"the {len(cs)} feasible configurations do not tell it apart from the other "
                                f"parameters (pivoted-QR diagonal {relative[k]:.2g} of the largest <= {rel_tol:g}): "
                                "held at its nominal value") for k in range(p) if k not in set(keep)]
    report = model.report
    report.identifiable = [report.identifiable[k] for k in keep]
    report.combined.update({d.name: [] for d in dropped})
    model.basis = model.basis[:, keep]
    model.design_basis = design_basis(model.mm, model.basis)
    cs.G = cs.G[:, :, keep]
    cs.basis = model.basis
    return cs, dropped
