"""Exact reuse: a robot handed on through the disk equals the in-process one bit for bit, and a
run once through equals the same run made stage by stage with reuse (timings excepted)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.robot.exact import load_exact_robot, robots_equal, save_exact_robot
from pipeline.robot.model import RobotModel
from pipeline.run.runner import run_pipeline


def _perturbed(name: str, seed: int) -> RobotModel:
    robot = RobotModel.load(name)
    model = robot.model.copy()
    rng = np.random.default_rng(seed)
    for j in range(1, model.njoints):
        model.jointPlacements[j] = model.jointPlacements[j] * pin.exp6(rng.normal(0.0, 1e-3, 6))
        inertia = model.inertias[j]
        model.inertias[j] = pin.Inertia(inertia.mass * (1 + 0.1 * rng.random()), inertia.lever + rng.normal(0, 1e-3, 3),
                                        inertia.inertia * (1 + 0.1 * rng.random()))
    model.armature = model.armature * (1 + 0.1 * rng.random(model.nv))
    perturbed = robot.with_model(model)
    perturbed.spec.tracker.max_incidence_rad = 0.1 + rng.random()
    perturbed.spec.actuation.viscous_Nms_rad = perturbed.spec.actuation.viscous_Nms_rad * (1 + rng.random())
    return perturbed


@pytest.mark.parametrize("name", ["rx130l", "staubli_tx40"])
def test_saved_robot_reloads_bit_for_bit(tmp_path, name):
    for seed in range(3):
        robot = _perturbed(name, seed)
        folder = save_exact_robot(robot, tmp_path / f"{name}{seed}")
        back = load_exact_robot(folder)
        assert robots_equal(robot, back)
        q = np.random.default_rng(seed).uniform(-1, 1, robot.nq)
        assert np.array_equal(robot.fk(q).homogeneous, back.fk(q).homogeneous)
        assert np.array_equal(robot.mass_matrix(q), back.mass_matrix(q))


#: keys of wall-clock measurements (results such as plan durations or settling times are compared)
TIMING_WORDS = ("solve_time", "search_time", "compile_time", "stage_time", "selection_time", "reference_time",
                "cpu_time", "cpu_ratio", "run_time", "runtime", "realtime", "speedup", "timings", "compile_s")


def _drop_timings(value: object) -> object:
    if isinstance(value, dict):
        return {k: _drop_timings(v) for k, v in value.items() if not any(w in k for w in TIMING_WORDS)}
    if isinstance(value, list):
        return [_drop_timings(v) for v in value]
    return value


def _differences(a: object, b: object, path: str = "") -> list[str]:
    """Dotted paths where two JSON values differ (for a readable failure)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in sorted(set(a) | set(b)) for d in _differences(a.get(k), b.get(k), f"{path}.{k}")]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True)) for d in _differences(x, y, f"{path}[{i}]")]
    return [] if a == b else [path or "."]


def _compare(a: Path, b: Path) -> list[str]:
    problems = []
    with np.load(a / "results.npz") as za, np.load(b / "results.npz") as zb:
        if za.files != zb.files:
            problems.append("npz keys")
        problems += [f"results.npz:{k}" for k in za.files if not np.array_equal(za[k], zb[k], equal_nan=True)]
    for name in ("summary.json", "results.json"):
        once, steps = (_drop_timings(json.loads((d / name).read_text())) for d in (a, b))
        problems += [f"{name}:{d}" for d in _differences(once, steps)]
    if (a / "robot").is_dir() and not robots_equal(load_exact_robot(a / "robot"), load_exact_robot(b / "robot")):
        problems.append("robot")
    return problems


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["rx130l", "staubli_tx40"])
def test_run_once_through_equals_stage_by_stage_with_reuse(tmp_path, robot):
    small = [f"robot={robot}", "calibration.n_random_candidates=400", "calibration.n_configurations=24",
             "calibration.n_heldout=100"]
    stages = ("model", "calibration", "identification", "control", "trajectory")
    quiet = {"out_root": tmp_path, "log": lambda m: None}
    run_pipeline(load_config(CONFIGS_DIR / "quick.yaml", [*small, "name=once"], stages), **quiet)   # every stage
    for stage in stages:
        result = run_pipeline(load_config(CONFIGS_DIR / "quick.yaml", [*small, "name=steps"], stage), **quiet)
        assert result.ran == [stage]
    for stage in stages:
        assert _compare(tmp_path / "once" / stage, tmp_path / "steps" / stage) == [], stage
