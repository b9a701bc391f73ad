"""notebooks/03_control.ipynb runs top to bottom in the quick setting."""

from __future__ import annotations

import pytest

#: a smaller quick setting: the ISO path's line alone (the quick profile's line and large circle: the control
#: stage test, tests/control/test_stage.py)
SMALL = {"SETTINGS": {"control.iso.segments": ["line"]}}


def _check(run) -> None:   # run: ExecutedNotebook (tests/conftest.py)
    """The notebook printed its figures' numbers and showed its figures inline."""
    text = run.text
    assert run.images, "no figure shown inline (no image/png output)"
    assert "velocity loop PM" in text and "real-time factor" in text
    assert "elastic_flat" in text and "settling time after the path" in text


def test_control_notebook_executes(tmp_path, execute_notebook):
    """Every cell on a shorter path (the same code path: servo design and Bode plot, the feedforward
    variants on the hidden robot, settling); the slow twin runs the notebook as shipped."""
    run = execute_notebook("03_control.ipynb", tmp_path, SMALL)
    _check(run)
    text = run.text
    assert "segments: ['line P2-P4']" in text        # the setting reached the notebook


@pytest.mark.slow
def test_control_notebook_executes_as_shipped(tmp_path, execute_notebook):
    """The notebook with its own quick setting (what a user runs): the line and the large circle."""
    _check(execute_notebook("03_control.ipynb", tmp_path))
