"""Every dynamic result checked in MuJoCo (truth.engine: mujoco), and the loop to the arm through files alone.

Slow: whole runs. The default profile on the RX130L and the example-robot-data Panda:

- identification: >= 95 % of the base parameters within 3 sigma of the base parameters read from the
  compiled mjModel, held-out validation torque RMS <= 1.1 sigma on every joint (outside the stiction
  band; a joint at rest on the whole path by the Coulomb law at rest), >= 95 % of the held samples
  within the Coulomb band;
- control: the model-based feedforward (full_friction: MuJoCo's joints are rigid) cuts the ISO 9283
  path's largest TCP error >= 5x against no feedforward;
- trajectory: every executed plan within the torque limits (the command averaged over the velocity
  samples, as the stage gates it) and its executed duration within 1 % of the plan's.

The file-only loop (quick profile): design -> export -> arm play -> record -> identify -> plan ->
export -> arm play -> arm verify (every recorded effort within its limit), every command exiting 0.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.core.config import CONFIGS_DIR
from pipeline.run.runner import run_pipeline
from pipeline.run.stages import load_config
from tests.example_arms import robot_setting

REPO = Path(__file__).resolve().parents[2]


def _summary(run: Path, stage: str) -> dict:
    return json.loads((run / stage / "summary.json").read_text())


def executed_plans(traj: dict) -> dict[str, tuple[float, float, float]]:
    """``plan -> (executed duration, planned duration, max averaged torque ratio)`` of every executed plan."""
    out = {}
    for key, executed in traj.items():
        if not key.endswith("_sim_duration_s"):
            continue
        plan = key[: -len("_sim_duration_s")]
        planned = traj.get(f"{plan}_duration_s", traj.get("ptp_ruckig_duration_s") if "at_ruckig" in plan else None)
        out[plan] = (float(executed), float(planned), float(traj[f"{plan}_sim_max_averaged_torque_ratio"]))
    return out


@pytest.mark.slow
@pytest.mark.study   # default profile on two arms: about an hour on 2 cores
@pytest.mark.parametrize("name", ["rx130l", "panda"])
def test_identification_control_and_trajectories_hold_in_mujoco(name: str, tmp_path: Path) -> None:
    cfg = load_config(None, [f"robot={robot_setting(name)}", f"name={name}", "truth.engine=mujoco"])
    run_pipeline(cfg, out_root=tmp_path, log=lambda m: None)
    run = tmp_path / name
    ident = _summary(run, "identification")
    assert ident["fraction_within_3sigma"] >= 0.95
    assert max(ident["validation_rms_over_noise"]) <= 1.1, ident["validation_rms_over_noise"]
    held = ident["validation_held_within_coulomb_band"]   # the samples in the stiction band (docs/mujoco.md)
    assert min(h for h in held if h is not None) >= 0.95, held
    errors = _summary(run, "control")["tcp_error_max_m"]
    assert errors["none"] >= 5.0 * errors["full_friction"], errors
    plans = executed_plans(_summary(run, "trajectory"))
    assert plans
    for plan, (executed, planned, ratio) in plans.items():
        assert ratio <= 1.0, (plan, ratio)
        assert abs(executed / planned - 1.0) <= 0.01, (plan, executed, planned)


def _cli(*args: str) -> None:
    done = subprocess.run([sys.executable, "-m", "pipeline", *args], cwd=REPO, capture_output=True, text=True)
    assert done.returncode == 0, (args, done.stderr[-2000:])


@pytest.mark.slow
@pytest.mark.study   # default profile on two arms: about an hour on 2 cores
@pytest.mark.parametrize("name", ["rx130l", "panda"])
def test_the_loop_to_the_arm_runs_through_files_alone(name: str, tmp_path: Path) -> None:
    robot = robot_setting(name)
    quick = str(CONFIGS_DIR / "quick.yaml")
    common = ["--config", quick, "--set", f"robot={robot}", "--set", f"name={name}", "--set", "truth.engine=mujoco"]
    _cli("run", *common, "--stages", "identification", "--out", str(tmp_path / "design"))          # design
    _cli("export", str(tmp_path / "design" / name), "--to", str(tmp_path / "export1"))             # export
    record = tmp_path / "excitation_record"
    _cli("arm", "play", str(tmp_path / "export1" / "excitation"), "--engine", "mujoco", "--out", str(record),
         "--robot", robot)                                                                         # play, record
    _cli("run", *common, "--set", f"identification.data_file={record}", "--stages", "identification,trajectory",
         "--out", str(tmp_path / "plan"))                                                          # identify, plan
    _cli("export", str(tmp_path / "plan" / name), "--to", str(tmp_path / "export2"))               # export
    motions = sorted(p for p in (tmp_path / "export2").glob("trajectory_*") if p.is_dir())
    assert motions
    for motion in motions:                                                                         # play, verify
        _cli("arm", "play", str(motion), "--engine", "mujoco", "--out", str(tmp_path / f"{motion.name}_record"),
             "--robot", robot, "--hold-s", "0.5")
        _cli("arm", "verify", str(motion), str(tmp_path / f"{motion.name}_record"), "--robot",
             str(tmp_path / "export2" / "robot"))
