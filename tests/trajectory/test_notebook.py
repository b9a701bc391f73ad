"""notebooks/04_trajectories.ipynb runs top to bottom in the quick setting."""

from __future__ import annotations

import pytest

#: a smaller quick setting: coarser CP grids (IK samples, path grid, smooth intervals) and the PtP front
#: reduced to the main plan; the PtP problem itself (intervals, compile flags) stays the quick profile's,
#: whose compiled library the ``ptp_problem`` fixture has on disk (the CP plans and the PtP sweep on the
#: quick grids: tests/trajectory/test_stage.py, test_cp.py, test_ptp.py)
SMALL = {"SETTINGS": {"trajectory.cp_ik_points": 40, "trajectory.cp_n_grid": 60,
                      "trajectory.cp_smooth_intervals": 25},
         "PARETO_K2": []}


def _check(run) -> None:   # run: ExecutedNotebook (tests/conftest.py)
    """The notebook printed its figures' numbers and showed its figures inline."""
    text = run.text
    assert run.images, "no figure shown inline (no image/png output)"
    assert "ours with toppra's constraints" in text and "vs ruckig" in text and "simulated max torque ratio" in text
    assert "move + settle [s]" in text and "TCP path error max (links)" in text


def test_trajectory_notebook_executes(tmp_path, execute_notebook, ptp_problem):  # ptp_problem: warm PtP cache
    """Every cell on a smaller setting (the same code path: CP plans, PtP plan, simulation on the hidden
    robot, settling study); the slow twin runs the notebook as shipped (the PtP front's k2 = 1 point)."""
    run = execute_notebook("04_trajectories.ipynb", tmp_path, SMALL)
    _check(run)
    text = run.text
    assert "path line: " in text and "ptp_energy_at_ruckig_duration: " in text


@pytest.mark.slow
def test_trajectory_notebook_executes_as_shipped(tmp_path, execute_notebook, ptp_problem):
    """The notebook with its own quick setting (what a user runs): the quick CP grids and the PtP front."""
    _check(execute_notebook("04_trajectories.ipynb", tmp_path))
