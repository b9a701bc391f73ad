"""notebooks/04_trajectories.ipynb runs top to bottom in the quick setting."""

from __future__ import annotations

from pathlib import Path

import nbformat
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[2] / "notebooks" / "04_trajectories.ipynb"


def test_trajectory_notebook_executes(tmp_path, ptp_problem):  # ptp_problem: compiled library in the cache
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "ours with toppra's constraints" in text and "vs ruckig" in text and "simulated max torque ratio" in text
