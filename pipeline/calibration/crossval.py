"""k-fold cross-validation of a calibration on the user's own readings (no held-out file needed).

The poses (rows of the measurement file; the three fitted rows of a 6-D pose stay together) are
split into ``k`` folds in file order modulo ``k``; each fold is predicted by the least-squares fit
(:func:`pipeline.calibration.estimate.estimate`, same identifiable set) of the other folds, without
the readings the outlier test rejected. The RMS of the position errors of the left-out poses is
an honest out-of-sample accuracy; it exceeds the in-sample fit residual by the estimation noise.
"""

from __future__ import annotations

import numpy as np

from pipeline.calibration import measure as ms
from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.estimate import estimate
from pipeline.errors import PipelineError


def cross_validate(mm: MeasurementModel, rec: ms.Measurements, basis: np.ndarray, rejected: np.ndarray,
                   folds: int, max_iterations: int) -> dict:
    """Per-fold and overall RMS position error (m) of the left-out poses (module docstring)."""
    pose = rec.pose_index if rec.pose_index is not None else np.arange(len(rec))
    keep = np.ones(len(rec), bool)
    keep[np.asarray(rejected, int)] = False
    fold_of = pose % folds
    errors: list[np.ndarray] = []
    per_fold: list[float | None] = []
    origin = np.all(rec.offset_m == 0, axis=1) if rec.offset_m is not None else np.ones(len(rec), bool)
    for f in range(folds):
        train = keep & (fold_of != f)
        test = keep & (fold_of == f) & origin
        if not test.any():
            per_fold.append(None)
            continue

        def part(a: np.ndarray | None, m: np.ndarray) -> np.ndarray | None:
            return None if a is None else a[m]

        try:
            est = estimate(mm, rec.Q[train], rec.Y[train], rec.sigma_m[train], basis, f"fold {f + 1}",
                           max_iterations, part(rec.payload_mounted, train), part(rec.offset_m, train))
        except PipelineError:
            per_fold.append(None)   # this fold's training poses do not excite every parameter
            continue
        pred = mm.predict(rec.Q[test], est.x, est.registration, part(rec.payload_mounted, test),
                          part(rec.offset_m, test))
        e = np.linalg.norm(rec.Y[test] - pred, axis=1)
        errors.append(e)
        per_fold.append(float(np.sqrt(np.mean(e ** 2))))
    all_e = np.concatenate(errors) if errors else np.zeros(0)
    return {"folds": int(folds), "n_poses": int(all_e.size),
            "rms_position_error_m": float(np.sqrt(np.mean(all_e ** 2))) if all_e.size else None,
            "per_fold_rms_m": per_fold,
            "n_folds_not_regular": int(sum(v is None for v in per_fold))}
