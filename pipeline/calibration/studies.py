"""Helpers shared by the calibration paper studies (``python -m pipeline study calib-004|calib-000|
calib-002|calib-003``; modules :mod:`~pipeline.calibration.paper_004`, :mod:`~pipeline.calibration.paper_000`,
:mod:`~pipeline.calibration.paper_002`, :mod:`~pipeline.calibration.paper_003`): runs over seeds or arms
in parallel with joblib (``--jobs``), results written to ``data/studies/<name>/result.json``, one
simulated calibration scored on held-out poses.
"""

from __future__ import annotations

import json

from joblib import Parallel, delayed

from pipeline.calibration import measure as ms
from pipeline.calibration import stage as st
from pipeline.calibration import validate as va
from pipeline.calibration.estimate import estimate
from pipeline.studies import study_dir


def _parallel(fn, items, jobs: int):
    if jobs <= 1:
        return [fn(i) for i in items]
    return Parallel(n_jobs=jobs)(delayed(fn)(i) for i in items)


def _save(name: str, result: dict) -> None:
    path = study_dir(name) / "result.json"
    path.write_text(json.dumps(result, indent=1, default=float))
    print(f"\nwritten {path}")


def _calibrate_with(robot, real, mm, basis, Q, rng, n_heldout: int):
    meas = ms.measure_simulated(real, Q, rng)
    est = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis)
    held = st.heldout_measurements(robot, real, est, st.Config(n_heldout=n_heldout), rng)
    return va.validate(mm, est, held), len(meas)
