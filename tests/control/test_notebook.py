"""notebooks/03_control.ipynb runs top to bottom in the quick setting."""

from __future__ import annotations


def test_control_notebook_executes(tmp_path, execute_notebook):
    text = execute_notebook("03_control.ipynb", tmp_path)
    assert "velocity loop PM" in text and "real-time factor" in text
    assert "elastic_flat" in text and "settling time after the path" in text
