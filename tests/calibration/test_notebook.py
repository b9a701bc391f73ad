"""notebooks/01_calibration.ipynb runs top to bottom in the quick setting."""

from __future__ import annotations

from pathlib import Path

import nbformat
import pytest

from pipeline.calibration.notebook import build

#: a smaller quick setting: fewer random candidates and held-out poses (the same code path: candidate
#: filter, selection, measurement, fit, validation, the other selection algorithms); the quick profile's
#: calibration itself: tests/calibration/test_calibration.py (the stage through the runner)
SMALL = {"SETTINGS": {"calibration.n_random_candidates": 400, "calibration.n_heldout": 200}}


def _check(run) -> None:   # run: ExecutedNotebook (tests/conftest.py)
    """The notebook printed its figures' numbers and showed its figures inline."""
    text = run.text
    assert run.images, "no figure shown inline (no image/png output)"
    assert "held-out RMS error before" in text and "x noise sigma" in text


def test_calibration_notebook_executes(tmp_path, execute_notebook):
    """Every cell on a smaller setting; the slow twin runs the notebook as shipped."""
    _check(execute_notebook("01_calibration.ipynb", tmp_path, SMALL))


@pytest.mark.slow
def test_calibration_notebook_executes_as_shipped(tmp_path, execute_notebook):
    """The notebook with its own quick setting (what a user runs)."""
    _check(execute_notebook("01_calibration.ipynb", tmp_path))


def test_notebook_file_is_up_to_date():
    nb = nbformat.read(Path(__file__).resolve().parents[2] / "notebooks" / "01_calibration.ipynb", as_version=4)
    assert [c.source for c in nb.cells] == [c.source for c in build().cells]
