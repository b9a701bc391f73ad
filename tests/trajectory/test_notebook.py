"""notebooks/04_trajectories.ipynb runs top to bottom in the quick setting."""

from __future__ import annotations


def test_trajectory_notebook_executes(tmp_path, execute_notebook, ptp_problem):  # ptp_problem: warm PtP cache
    text = execute_notebook("04_trajectories.ipynb", tmp_path)
    assert "ours with toppra's constraints" in text and "vs ruckig" in text and "simulated max torque ratio" in text
    assert "move + settle [s]" in text and "TCP path error max (links)" in text
