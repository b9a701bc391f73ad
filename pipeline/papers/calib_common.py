"""Helpers shared by the calibration studies (``python -m pipeline study calib-004|calib-design``;
modules :mod:`~pipeline.papers.calib_004`, :mod:`~pipeline.papers.calib_design`): runs over seeds
or arms in parallel with joblib (``--jobs``), results written to ``data/studies/<name>/result.json``.
"""

from __future__ import annotations

from joblib import Parallel, delayed

from pipeline.papers import registry as studies


def run_parallel(fn, items, jobs: int):
    """``[fn(i) for i in items]``, on ``jobs`` joblib workers when ``jobs > 1``."""
    if jobs <= 1:
        return [fn(i) for i in items]
    return Parallel(n_jobs=jobs)(delayed(fn)(i) for i in items)


def save_result(name: str, result: dict) -> None:
    """Write ``result`` to ``data/studies/<name>/result.json`` (:func:`pipeline.papers.registry.study_dir`)."""
    print()
    studies.save_result(name, result)
