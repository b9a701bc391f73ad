"""Shared set-up of the identification tests: a stage context without the runner.

``calibrated_robot`` gives the nominal robot the hidden robot's kinematics (what a perfect
calibration stage would hand on); tests may read the truth, stage code may not.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pipeline import cli
from pipeline.core.config import CONFIGS_DIR, load_config, to_plain
from pipeline.core.progress import Progress
from pipeline.core.typed_config import build_dataclass
from pipeline.identification import stage
from pipeline.robot.model import RobotModel
from pipeline.robot.parameters import apply_kinematic_errors
from pipeline.robot.public_arms import arm_file, corpus_arm
from pipeline.sim.truth import RealRobot, TruthConfig
from pipeline.stage_api import StageContext, stage_rng


def calibrated_robot(nominal: RobotModel, real: RealRobot) -> RobotModel:
    model = apply_kinematic_errors(nominal.model, real.kinematic_errors, nominal.frame_flange,
                                   (nominal.frame_tcp, nominal.frame_reflector))
    model.armature = nominal.model.armature.copy()
    return nominal.with_model(model)


#: the default hidden robot without load-dependent Coulomb friction: the truth of the tests whose
#: friction models (viscous + Coulomb, Stribeck) contain the truth's (without the load-dependent
#: candidate the fitted Coulomb parameters are biased by a few per cent)
NO_LOAD_FRICTION = TruthConfig(coulomb_load_coefficient=0.0)


def quick_context(tmp_path: Path, seed: int = 1, robot: str = "rx130l", overrides: dict | None = None,
                  calibrated: bool = True, truth: TruthConfig | None = None) -> tuple[StageContext, RealRobot]:
    """Quick-profile context of the identification stage (config from configs/quick.yaml); the
    hidden robot of ``truth`` (default: the default TruthConfig)."""
    cfg = load_config(CONFIGS_DIR / "quick.yaml")
    section: dict[str, Any] = {}
    raw = cfg.sections.get("identification")
    if raw is not None:
        section.update(raw if isinstance(raw, dict) else to_plain(raw))
    section.update(overrides or {})
    config = build_dataclass(stage.Config, section, "identification", "test")
    nominal = RobotModel.load(robot)
    real = RealRobot.create(nominal, seed, truth)
    rob = calibrated_robot(nominal, real) if calibrated else nominal.copy()
    out = tmp_path / "identification"
    out.mkdir(parents=True, exist_ok=True)
    ctx = StageContext(run=cfg, config=config, robot=rob, real=real, upstream={}, out_dir=out,
                       rng=stage_rng(seed, "identification"), progress=Progress(enabled=False))
    return ctx, real


def true_base(real: RealRobot, E: np.ndarray) -> np.ndarray:
    return E.T @ np.asarray(real.dynamic_parameters, float)


def identify_recorded_bag(tmp_path: Path, arm: str, bag: Path,
                          stages: str = "identification") -> tuple[Path, dict[str, Any]]:
    """A recorded bag through the CLI as a user would: the corpus arm's URDF through ``robot init``
    (no options), then ``run --stages <stages>`` with ``bag`` as ``identification.data_file`` and
    every other setting at its default. Asserts exit 0; returns (the run's folder, the identification
    summary). Skips when the arm's package is not installed."""
    urdf = arm_file(corpus_arm(arm))
    if urdf is None:
        pytest.skip(f"the package of the {arm} URDF is not installed")
    folder = tmp_path / arm
    folder.mkdir()
    shutil.copy(urdf, folder / f"{arm}.urdf")
    assert cli.main(["robot", "init", str(folder / f"{arm}.urdf")]) == 0
    out = tmp_path / "runs"
    code = cli.main(["run", "--set", f"robot={folder}", "--stages", stages,
                     "--set", f"identification.data_file={bag}", "--out", str(out)])
    assert code == 0
    run = out / arm
    return run, json.loads((run / "identification" / "summary.json").read_text())
