"""notebooks/01_calibration.ipynb runs top to bottom in the quick setting."""

from __future__ import annotations

from pathlib import Path

import nbformat

from pipeline.calibration.notebook import build


def test_calibration_notebook_executes(tmp_path, execute_notebook):
    text = execute_notebook("01_calibration.ipynb", tmp_path)
    assert "held-out RMS error before" in text and "x noise sigma" in text


def test_notebook_file_is_up_to_date():
    nb = nbformat.read(Path(__file__).resolve().parents[2] / "notebooks" / "01_calibration.ipynb", as_version=4)
    assert [c.source for c in nb.cells] == [c.source for c in build().cells]
