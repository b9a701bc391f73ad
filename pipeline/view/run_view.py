"""``python -m pipeline view [RUN_DIR]``: a run directory in the meshcat viewer.

Loads a run directory, draws the robot (the last model a stage handed on, else the run's nominal
robot), every saved configuration set (arrays ``configurations_<name>`` of shape ``(N, nq)`` in a
stage's ``results.npz``) and every saved trajectory (``trajectory_<name>_t`` ``(N,)`` with
``trajectory_<name>_q`` ``(N, nq)``), and plays them one after the other in a single animation
(:class:`pipeline.view.viewer.Viewer`).
"""

from __future__ import annotations

import re
import signal
import sys
import time
from pathlib import Path
from types import FrameType

import numpy as np

from pipeline.core.artefacts import read_npz
from pipeline.core.config import RunConfig, default_runs_dir, resolve_robot_dir, stage_names
from pipeline.core.errors import PipelineError
from pipeline.core.yaml12 import load_yaml
from pipeline.robot.model import RobotModel
from pipeline.run.stage_io import MANIFEST, RESULTS_NPZ, load_run
from pipeline.view.scene import LAYERS, layer_of
from pipeline.view.viewer import Viewer

TRAJECTORY_RE = re.compile(r"^trajectory_(?P<name>.+)_t$")
CONFIGURATIONS_PREFIX = "configurations_"
COLORS = (0xE6550D, 0x3182BD, 0x31A354, 0x756BB1, 0xD62728, 0x8C564B)


def find_saved_motions(run_dir: str | Path) -> tuple[dict[str, np.ndarray], dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Configuration sets and trajectories saved by the stages of a run.

    Returns ``({"<stage>/<name>": Q}, {"<stage>/<name>": (t, q)})``.
    """

    configurations: dict[str, np.ndarray] = {}
    trajectories: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for stage, out in load_run(run_dir).items():
        if not (out.path / RESULTS_NPZ).exists():
            continue
        arrays = read_npz(out.path / RESULTS_NPZ)
        for key, value in arrays.items():
            if key.startswith(CONFIGURATIONS_PREFIX):
                configurations[f"{stage}/{key[len(CONFIGURATIONS_PREFIX):]}"] = value
            m = TRAJECTORY_RE.match(key)
            if m and f"trajectory_{m['name']}_q" in arrays:
                trajectories[f"{stage}/{m['name']}"] = (value, arrays[f"trajectory_{m['name']}_q"])
    return configurations, trajectories


def is_run_dir(path: str | Path) -> bool:
    """``path`` holds a run: a ``config.yaml`` or a stage folder with a ``manifest.json``."""

    path = Path(path)
    if not path.is_dir():
        return False
    if (path / "config.yaml").is_file():
        return True
    return any(p.is_dir() and not p.name.startswith(".") and (p / MANIFEST).is_file() for p in path.iterdir())


def latest_run_dir(runs_dir: str | Path | None = None) -> Path | None:

    base = Path(runs_dir) if runs_dir is not None else default_runs_dir()
    if not base.is_dir():
        return None
    runs = [p for p in base.iterdir() if p.is_dir() and (p / "config.yaml").exists()]
    return max(runs, key=lambda p: p.stat().st_mtime) if runs else None


def robot_of_run(run_dir: Path) -> RobotModel:
    """The last robot a stage of the run handed on, else the run's nominal robot."""
    for stage in reversed(stage_names()):
        if (run_dir / stage / "robot" / "robot.yaml").exists():
            return RobotModel.load(run_dir / stage / "robot")
    cfg_file = run_dir / "config.yaml"
    robot = RunConfig().robot
    if cfg_file.exists():
        robot = (load_yaml(cfg_file.read_text(encoding="utf-8")) or {}).get("robot", robot)
    return RobotModel.load(resolve_robot_dir(RunConfig(robot=str(robot), source=str(cfg_file))))


def view_run(run_dir: str | Path | None = None, *, robot: str | None = None, configurations: str | None = None,
             trajectory: str | None = None, open_browser: bool = False, wait: bool = True) -> Viewer:
    """``python -m pipeline view``: show a run's robot, configuration sets and trajectories."""

    path = Path(run_dir) if run_dir is not None else latest_run_dir()
    if run_dir is not None and not Path(run_dir).is_dir():
        raise PipelineError(run_dir, None, "run directory not found")
    if run_dir is not None and not is_run_dir(run_dir):
        raise PipelineError(run_dir, None, "not a run directory (no config.yaml and no stage folder with "
                                           "manifest.json; make one with `python -m pipeline run`)")
    if robot is not None:
        model = RobotModel.load(resolve_robot_dir(RunConfig(robot=robot, source="--robot")))
        if path is not None:
            run_robot = robot_of_run(path)
            if run_robot.nq != model.nq:
                raise PipelineError(path, "--robot", f"{model.name} has {model.nq} joints but the run's robot "
                                    f"{run_robot.name} has {run_robot.nq}: its motions cannot be drawn on it")
            if run_robot.name != model.name:
                print(f"WARNING: --robot {model.name} is not this run's robot ({run_robot.name}): its "
                      "configurations and trajectories are drawn on another arm", file=sys.stderr)
    elif path is not None:
        model = robot_of_run(path)
    else:
        model = RobotModel.load(resolve_robot_dir(RunConfig()))
    sets, trajs = find_saved_motions(path) if path is not None else ({}, {})
    if configurations is not None:
        sets = {k: v for k, v in sets.items() if configurations in (k, k.split("/", 1)[-1])}
        if not sets:
            raise PipelineError(path, configurations, "no such configuration set in this run")
        trajs = {} if trajectory is None else trajs
    if trajectory is not None:
        trajs = {k: v for k, v in trajs.items() if trajectory in (k, k.split("/", 1)[-1])}
        if not trajs:
            raise PipelineError(path, trajectory, "no such trajectory in this run")
        sets = {} if configurations is None else sets
    viewer = Viewer(model, open_browser=open_browser)
    for k, (name, Q) in enumerate(sets.items()):
        if Q.ndim == 2 and Q.shape[1] == model.nq:
            layer = layer_of(name, trajectory=False)
            color = LAYERS[layer][0] if layer in LAYERS else COLORS[k % len(COLORS)]
            if layer not in ("candidates", "held-out poses"):     # many poses: points only, no clip
                viewer._clips.append((name, np.arange(len(Q), dtype=float), Q))
            viewer.show_points(viewer._tcp_points(Q, "tcp"), name, color, layer=layer)
    for k, (name, (t, q)) in enumerate(trajs.items()):
        if q.ndim == 2 and q.shape[1] == model.nq and len(t) == len(q):
            layer = layer_of(name, trajectory=True)
            color = LAYERS[layer][0] if layer in LAYERS else COLORS[(k + 3) % len(COLORS)]
            viewer._clips.append((name, np.asarray(t, float), q))
            viewer.show_path(viewer._tcp_points(q[:: max(1, len(q) // 500)], "tcp"), name, color, layer=layer)
    viewer.animate()
    what = ", ".join([*(f"configurations {n}" for n in sets), *(f"trajectory {n}" for n in trajs)])
    print(f"robot {model.name} from {path or 'robots/'}; showing: {what or 'the robot only'}", file=sys.stderr)
    print(f"open {viewer.url}", flush=True)
    print("layers (scene tree of the page's Controls panel, each can be hidden):\n" + viewer.legend_text(),
          flush=True)
    if wait:
        print("press Ctrl-C to stop the viewer", file=sys.stderr)

        def _stop(signum: int, frame: FrameType | None) -> None:    # SIGTERM ends the meshcat server like Ctrl-C
            raise KeyboardInterrupt

        previous = signal.signal(signal.SIGTERM, _stop)
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
        finally:
            signal.signal(signal.SIGTERM, previous)
            viewer.close()
    return viewer

