"""notebooks/02_identification.ipynb runs top to bottom in the quick setting."""

from __future__ import annotations


def test_identification_notebook_executes(tmp_path, execute_notebook):
    text = execute_notebook("02_identification.ipynb", tmp_path)
    assert "base parameters" in text and "cond optimised" in text and "tx40_heldout_rms_Nm_physical" in text
