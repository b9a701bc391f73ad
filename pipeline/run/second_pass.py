"""The second calibration pass, run by the runner (``calibration.second_pass``).

Calibration comes before identification, so its elastostatic model (joint compliance times the
gravity torque, :mod:`pipeline.calibration.elastostatic`) uses the nominal inertias. On an arm
whose own weight takes a large share of its torque limits, their error (data-sheet or CAD masses:
10-20 %) moves the TCP by more than the tracker noise, and the calibration stage predicts it: the
gravity model's share of the predicted held-out error (``gravity_model_share`` in its summary). A
second pass calibrates again with the inertias the identification found. The runner runs it as two
runs, each one-way (robot model -> calibration -> identification -> ...):

1. a first pass of ``calibration`` and ``identification`` (and their upstream stages) with the same
   configuration, under ``<run>/first_pass/<name>/``;
2. when ``second_pass`` is ``always``, or ``auto`` and the first pass's ``gravity_model_share`` is at
   least :data:`GRAVITY_SHARE_FOR_SECOND_PASS`, this run with ``calibration.gravity_model`` set to a
   copy of the first pass's identified robot. The copy's folder is named by the hash of its files,
   ``<runs>/.gravity_models/<sha>``: a changed first pass changes this run's inputs (nothing stale
   is reused), and the path does not depend on the run's name. Otherwise this run is the first pass
   again, and its stages are reused from it (same inputs, nothing computed twice).

A run whose stages include calibration gets its first pass whenever the robot has an identification
stage, also when identification itself is not selected (``--stages calibration``): the same
configuration gives the same calibration whichever stages are selected. Both passes draw from the
same seed, so the hidden robot is the same.

The identified inertias must be those of the arm calibrated: the second pass runs only when both
stages are recorded (inertias identified from recorded torques of the arm whose tracker file is
calibrated) or both simulated (the same hidden robot). A recorded calibration file with a simulated
identification, or a simulated calibration with a recorded torque log, gets no first pass and no
second pass; :func:`decision` says why (console, ``provenance.json``, headline). The first pass's
results stay in its folder for comparison (first -> second pass in the run log).
"""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

from pipeline.calibration.config import Config as CalibrationConfig
from pipeline.core import artefacts
from pipeline.core.config import RunConfig
from pipeline.run import stage_io
from pipeline.run.stages import stage_provenance
from pipeline.stage_api import StageOutput
from pipeline.summaries import CalibrationSummary

#: ``auto`` runs the second pass when the gravity model makes up at least this share of the first
#: pass's predicted held-out error (variance share, calibration summary ``gravity_model_share``):
#: removing it lowers the predicted RMS by at least 1 - sqrt(1 - 0.25) = 13 %
GRAVITY_SHARE_FOR_SECOND_PASS = 0.25
FIRST_PASS_FOLDER = "first_pass"
#: content-addressed copies of first-pass robots, under the runs folder
GRAVITY_MODELS_FOLDER = ".gravity_models"


def decision(cfg: RunConfig, planned: list[str], available: list[str]) -> tuple[bool, str]:
    """Whether this run starts with a first pass, and why not (empty when it does, or when no
    second pass is in question: no calibration planned, no identification stage for the robot,
    ``second_pass: never`` or a gravity model given). A first pass needs a calibration and an
    identification of the same provenance: both recorded or both simulated (module doc)."""
    cal = cfg.sections.get("calibration")
    if not (isinstance(cal, CalibrationConfig) and cal.second_pass != "never" and cal.gravity_model is None
            and "calibration" in planned and "identification" in available):
        return False, ""
    cal_from, ident_from = stage_provenance(cfg, "calibration"), stage_provenance(cfg, "identification")
    if cal_from.recorded and not ident_from.recorded:
        return False, (f"no second calibration pass: the calibration is {cal_from.label()} but the identification "
                       "would be simulated, and the simulated robot's inertias are not those of the arm measured "
                       "(identification.data_file: a torque log of the same arm enables it)")
    if ident_from.recorded and not cal_from.recorded:
        return False, (f"no second calibration pass: the identification is {ident_from.label()} but the "
                       "calibration is simulated, and the recorded inertias are not those of the simulated robot")
    return True, ""


def wanted(cfg: RunConfig, planned: list[str], available: list[str]) -> bool:
    """Whether this run starts with a first pass (:func:`decision`)."""
    return decision(cfg, planned, available)[0]


def first_pass_config(cfg: RunConfig) -> RunConfig:
    """The first pass: the same configuration, its stages up to identification."""
    return replace(cfg, stages=["identification"], origins={**cfg.origins, "stages": "calibration.second_pass"})


def first_pass_root(run_dir: Path) -> Path:
    return run_dir / FIRST_PASS_FOLDER


def gravity_share(outputs: dict[str, StageOutput]) -> float | None:
    """The first pass's gravity-model share of the predicted error (None: not predicted)."""
    return CalibrationSummary.read(outputs["calibration"].summary).gravity_model_share


def second_pass_config(cfg: RunConfig, outputs: dict[str, StageOutput], run_dir: Path,
                       write: bool = True) -> RunConfig | None:
    """This run's configuration with the first pass's identified robot as gravity model, or None
    when ``auto`` finds the gravity model's share below :data:`GRAVITY_SHARE_FOR_SECOND_PASS`.
    ``write=False`` (``check``) names the first pass's robot folder itself: the same content,
    hence the same inputs hash (the runner hashes the gravity model's files, not its path)."""
    cal = cfg.section("calibration", CalibrationConfig)
    share = gravity_share(outputs)
    if cal.second_pass == "auto" and (share is None or share < GRAVITY_SHARE_FOR_SECOND_PASS):
        return None
    robot = outputs["identification"].path / "robot"
    if not write:
        return replace(cfg, sections={**cfg.sections, "calibration": replace(cal, gravity_model=str(robot))})
    target = (run_dir.parent / GRAVITY_MODELS_FOLDER / artefacts.hash_tree(robot)[:16]).resolve()
    target.parent.mkdir(parents=True, exist_ok=True)
    if not target.is_dir():
        partial = target.with_name(f".{target.name}.partial")
        shutil.rmtree(partial, ignore_errors=True)
        shutil.copytree(robot, partial)
        partial.rename(target)
    sections = {**cfg.sections, "calibration": replace(cal, gravity_model=str(target))}
    return replace(cfg, sections=sections)


def reuse_first_pass(outputs: dict[str, StageOutput], run_dir: Path) -> list[str]:
    """Copy the first pass's stage folders into ``run_dir`` (same inputs: the runner reuses them)
    where this run has none with the same inputs hash; a replaced folder is moved aside first
    (``.<stage>.old-*``, removed by the runner's clean-up). Returns the stages copied."""
    run_dir.mkdir(parents=True, exist_ok=True)
    copied = []
    for name, out in outputs.items():
        target = run_dir / name
        if target.exists() and stage_io.read_inputs_hash(target) == stage_io.read_inputs_hash(out.path):
            continue
        copied.append(name)
        partial = run_dir / f".{name}.partial-first-pass"
        shutil.rmtree(partial, ignore_errors=True)
        shutil.copytree(out.path, partial)
        if target.exists():
            old = run_dir / f".{name}.old-first-pass"
            shutil.rmtree(old, ignore_errors=True)
            target.rename(old)
            partial.rename(target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            partial.rename(target)
    return copied
