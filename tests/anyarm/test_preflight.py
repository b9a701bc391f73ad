"""A reflector inside the wrist capsule is named in seconds by `check` and by the candidate search.

A URDF whose last link frame sits at the wrist centre (the ROS-Industrial layout) put the assumed
reflector inside the wrist's capsule: the tracker never sees it, and the search over ~20 million
candidates failed only after minutes. Here a UR5 gets its reflector moved into its last capsule.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import yaml

from pipeline import cli
from pipeline.calibration import candidates as cd
from pipeline.calibration import feasibility as fz
from pipeline.calibration.config import Config
from pipeline.calibration.stage import build_candidates
from pipeline.core.errors import InfeasibleError
from pipeline.robot import model as model_mod
from pipeline.robot.model import RobotModel
from tests.anyarm.test_urdf_only import _erd

#: "seconds": the probe of the search and the check, far below the minutes of the full search
FAST_S = 60.0


def _reflector_inside_last_capsule(tmp_path):
    """The robot folder of a UR5 whose reflector sits in its last capsule, and that capsule's name."""
    ur5 = RobotModel.load(_erd("ur_description/urdf/ur5_robot.urdf"))
    folder = ur5.save(tmp_path / "ur5_inside")
    cap = ur5.capsules[-1]
    frames = ur5.model.frames
    mid = 0.5 * (np.asarray(cap.p0, float) + np.asarray(cap.p1, float))
    in_flange = frames[ur5.frame_id(ur5.frame_flange)].placement.actInv(
        frames[ur5.frame_id(cap.frame)].placement.act(mid))
    robot_yaml = folder / "robot.yaml"
    data = yaml.safe_load(robot_yaml.read_text())
    data["tool"]["reflector_offset_m"] = [float(v) for v in in_flange]
    robot_yaml.write_text(yaml.safe_dump(data))
    return folder, cap.name


def test_probe_counts_add_up_and_find_visible_poses(rx130l):
    chain = cd.chain_from_robot(rx130l)
    diag = fz.probe(chain, cd.FilterMargins(), [c.name for c in rx130l.capsules])
    assert diag.n_feasible > 0
    assert diag.n_sampled == fz.PROBE_CHUNK            # stops at the first chunk with a feasible pose
    assert sum(diag.counts.values()) + diag.n_feasible == diag.n_sampled
    # the same sample through the stage's filter: the same feasible count
    Q = np.random.default_rng(0).uniform(chain.lower, chain.upper, (fz.PROBE_CHUNK, chain.nq))
    assert cd.filter_configurations(chain, Q)[1]["feasible"] == diag.n_feasible


def test_incidence_cause_names_the_reflector_axis(rx130l):
    chain = cd.chain_from_robot(rx130l)
    margins = cd.FilterMargins(incidence_rad=rx130l.tracker.max_incidence_rad + 0.1)   # a closed cone
    diag = fz.probe(chain, margins, [c.name for c in rx130l.capsules], size=2 * fz.PROBE_CHUNK)
    assert diag.n_feasible == 0 and diag.n_sampled == 2 * fz.PROBE_CHUNK
    assert diag.counts["incidence"] > 0 and diag.counts["occlusion"] == 0
    err = fz.infeasible_error(diag, rx130l.spec.path)
    assert err.field == "tool.reflector_axis" and "max_incidence_deg" in err.problem


def test_search_stops_early_naming_the_capsule(tmp_path, monkeypatch):
    folder, last = _reflector_inside_last_capsule(tmp_path)
    # loading refuses such a robot already; switch that check off to reach the search's own early stop
    monkeypatch.setattr(model_mod, "capsules_holding", lambda *args: [])
    robot = RobotModel.load(folder)
    for candidates in ("random", "grid"):
        cfg = Config(candidates=candidates)
        t0 = time.perf_counter()
        with pytest.raises(InfeasibleError) as info:
            build_candidates(robot, cfg, np.eye(7 * robot.nq + 21), np.random.default_rng(0))
        assert time.perf_counter() - t0 < FAST_S
        err = info.value
        assert err.field == "tool.reflector_offset_m" and str(err.file).endswith("robot.yaml")
        assert f"inside capsule {last} in every sampled pose" in err.problem
        assert "no feasible candidate configuration" in err.problem
    margins = cd.FilterMargins(Config().margin_collision_m, math.radians(Config().margin_incidence_deg),
                               Config().margin_beam_m)
    diag = fz.probe(cd.chain_from_robot(robot), margins, [c.name for c in robot.capsules])
    assert diag.n_feasible == 0 and diag.inside[last] == diag.n_sampled < fz.PROBE_SIZE


def test_check_names_the_reflector_problem_in_seconds(tmp_path, capsys):
    folder, last = _reflector_inside_last_capsule(tmp_path)
    t0 = time.perf_counter()
    code = cli.main(["check", "--config", "configs/quick.yaml", "--stages", "calibration",
                     "--set", f"robot={folder}", "--out", str(tmp_path / "runs")])
    assert time.perf_counter() - t0 < FAST_S
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {folder / 'robot.yaml'}: tool.reflector_offset_m: ")
    assert "capsule" in lines[0] and last in lines[0]
    assert not (tmp_path / "runs").exists()


def test_check_passes_the_built_in_robot(tmp_path, capsys):
    code = cli.main(["check", "--config", "configs/quick.yaml", "--out", str(tmp_path / "runs")])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert out.out.startswith("ok: ")


def test_check_names_a_colliding_ik_seed(tmp_path, capsys):
    code = cli.main(["check", "--config", "configs/quick.yaml", "--stages", "control", "--out", str(tmp_path),
                     "--set", "control.ik_seeds_deg=[[0, 0, 140, 0, 0, 0]]"])
    err = capsys.readouterr().err
    assert code == 2
    assert "control.ik_seeds_deg: " in err and "collision" in err
