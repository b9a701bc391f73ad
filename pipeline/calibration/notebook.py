"""Writes ``notebooks/01_calibration.ipynb`` (``python -m pipeline.calibration.notebook``)."""

from __future__ import annotations

import sys
from pathlib import Path

CELLS: list[tuple[str, str]] = [
    ("markdown", """# Stage 1: optimal calibration configurations and geometric calibration

Quick setting (`configs/quick.yaml`): random candidates instead of the 13^6 grid. Steps: the identifiable
parameter set of the tracker measurement model (SVD + ordered QR, paper 002/003), candidate filtering
(limits, capsule collisions, floor, tracker visibility), selection by remove-and-replace on the minimum
singular value (paper 004), measurement with the simulated laser tracker, registration + Levenberg-Marquardt,
and validation on 1000 held-out poses."""),
    ("code", """%matplotlib inline
import numpy as np
from IPython.display import Markdown, display

from pipeline.run.stages import quick_config
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot
from pipeline.stage_api import stage_rng
from pipeline.calibration import stage as st, design as ds, indices as ix, validate as va, plots

SETTINGS = {}   # parameter: settings over configs/quick.yaml, e.g. {"calibration.n_heldout": 200}
run = quick_config(**SETTINGS)
cfg = run.section("calibration")
robot = RobotModel.load(run.robot)
real = RealRobot.create(robot, run.seed)   # the hidden robot: only its tracker is used below
rng = stage_rng(run.seed, "calibration")
cfg"""),
    ("code", """out = st.calibrate(robot, real, cfg, rng)
display(Markdown(out.report.markdown(max_rows=12)))"""),
    ("code", """s = st.summary_of(out, cfg)
print(f"selected {s['n_configurations']} of {s['n_candidates']} candidates by {s['selection_method']} "
      f"on {s['index_name']} = {s['index_value']:.4g} in {s['selection_time_s']:.2f} s")
print(f"held-out RMS error before {1e3 * s['heldout_rms_position_error_before_m']:.3f} mm, "
      f"after {1e6 * s['heldout_rms_position_error_after_m']:.1f} µm "
      f"(= {s['rms_after_over_sigma']:.2f} x noise sigma: sensor + repeatability + remainder), "
      f"predicted {1e6 * s['predicted_rms_position_error_m']:.1f} µm")
display(Markdown(va.table_markdown(out.validation)))"""),
    ("markdown", """## The same candidates, other selection algorithms and indices

Each algorithm reports its index value, run time and number of index evaluations."""),
    ("code", """G = out.candidates.G
rows = ["| algorithm | index | value | time [s] | evaluations |", "|---|---|---|---|---|"]
for method in ("remove_and_replace", "detmax", "bsaa", "random"):
    for name in ("O3",):
        res = ds.select(method, G, ix.IndexSpec(name), 30, np.random.default_rng(0))
        rows.append(f"| {method} | {name} | {res.index_value:.4g} | {res.run_time_s:.2f} | {res.evaluations} |")
display(Markdown("\\n".join(rows)))"""),
    ("code", """fig1 = plots.error_histograms(out.validation["errors_before_m"], out.validation["errors_after_m"],
                              out.validation["noise_total_sigma_m"], out.validation["predicted_rms_m"])
fig2 = plots.index_history(out.selection.history, out.selection.index_name, out.selection.method)
display(fig1, fig2)"""),
    ("markdown", """## 3-D view (meshcat)

Set `SHOW_VIEWER = True` to open a meshcat scene with the chosen configurations, the tracker and the beams."""),
    ("code", """SHOW_VIEWER = False
if SHOW_VIEWER:
    from pipeline.view.calibration import show_calibration
    viewer = show_calibration(out.robot, out.measurements.Q, out.estimate.transform_tracker_to_base)
    display(viewer.jupyter_cell())"""),
]


def build():
    import nbformat  # optional: the dev extra (writing notebooks is a developer task)

    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    for k, (kind, src) in enumerate(CELLS):
        cell = nbformat.v4.new_markdown_cell(src) if kind == "markdown" else nbformat.v4.new_code_cell(src)
        cell.id = f"cell-{k + 1:02d}"    # fixed ids: writing the notebook again changes nothing else
        nb.cells.append(cell)
    return nb


def write(path: str | Path) -> Path:
    import nbformat  # optional: the dev extra (writing notebooks is a developer task)

    path = Path(path)
    nbformat.write(build(), path)
    return path


if __name__ == "__main__":
    target = sys.argv[1] if len(sys.argv) > 1 else str(Path(__file__).resolve().parents[2] / "notebooks"
                                                          / "01_calibration.ipynb")
    print(write(target))
