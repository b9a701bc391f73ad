"""Stage directories on disk: staging and committing, writing a result, checking its integrity,
loading it back.

* A stage writes everything into ``<run>/.<stage>.partial-XXXX/`` and the directory is renamed
  to ``<run>/<stage>/`` only when complete (:func:`commit_stage_dir`); an old ``<stage>/`` is
  moved aside first and deleted afterwards. A stage that fails leaves no ``<stage>/``. Files are
  written atomically (:mod:`pipeline.core.artefacts`).
* :func:`write_stage_result` writes a :class:`~pipeline.stage_api.StageResult` into a staging
  directory; ``manifest.json`` records the SHA-256 of every file the stage wrote (its extra
  files too) and the hash of the run-level settings (:func:`run_key_sha256`); ``inputs.sha256``
  comes last: the hash of everything the stage's result depends on (:func:`inputs_hash`); the
  runner reuses a stage whose stored hash equals the new one.
* :func:`stage_problem` says why a finished stage directory cannot be trusted (a file missing,
  truncated or edited, no manifest), or None; reuse and :func:`load_stage_output` both use it.
* :func:`write_rejected` keeps a result that failed a quality gate in ``<run>/<stage>.rejected/``
  for inspection: no ``inputs.sha256``, so it is never reused or loaded as a stage.
* A handed-on robot is saved losslessly (:mod:`pipeline.robot.exact`).

Layout of a stage directory::

    summary.json   headline figures      results.npz   arrays      results.json  details
    *.png          figures               report.md     markdown    robot/        URDF + robot.yaml
    manifest.json  stage, hash, figures, timing          inputs.sha256
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import zipfile
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pipeline
from pipeline.core import artefacts
from pipeline.core import config as config_mod
from pipeline.core.config import to_plain
from pipeline.core.errors import PipelineError
from pipeline.core.forks import fork_map
from pipeline.core.yaml12 import YAMLError, load_yaml
from pipeline.robot.exact import load_exact_robot, save_exact_robot
from pipeline.robot.model import RobotModel
from pipeline.stage_api import PROVENANCE_FILE, RECORDED, SIMULATED, Provenance, StageOutput, StageResult

SUMMARY = "summary.json"
RESULTS_NPZ = "results.npz"
RESULTS_JSON = "results.json"
REPORT_MD = "report.md"
MANIFEST = "manifest.json"
INPUTS_HASH = "inputs.sha256"
ROBOT_DIR = "robot"

#: files of a stage directory that are not covered by the manifest's SHA-256 list
UNHASHED = (MANIFEST, INPUTS_HASH)
REJECTED_SUFFIX = ".rejected"


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def directory_hashes(folder: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file under ``folder`` except :data:`UNHASHED`."""
    return {str(p.relative_to(folder)): file_sha256(p) for p in sorted(folder.rglob("*"))
            if p.is_file() and str(p.relative_to(folder)) not in UNHASHED}


def run_key_sha256(seed: int, robot: str, truth: object) -> str:
    """Hash of the run-level settings every stage shares (seed, robot, ``truth`` section): stage
    directories with different values come from different runs (:func:`load_run`)."""
    payload = {"seed": seed, "robot": str(robot), "truth": to_plain(truth) or {}}
    return hashlib.sha256(artefacts.stable_json(payload).encode()).hexdigest()


def _write_payload(stage_dir: Path, result: StageResult) -> list[str]:
    artefacts.write_json(stage_dir / SUMMARY, result.summary)
    artefacts.write_npz(stage_dir / RESULTS_NPZ, result.arrays)
    artefacts.write_json(stage_dir / RESULTS_JSON, result.data)
    figures = []
    # rendering the PNGs is most of a stage's writing time: side by side on forked workers (the same bytes)
    keys, figs = list(result.figures), list(result.figures.values())
    for key, fig, png in zip(keys, figs, fork_map(lambda k: artefacts.figure_png(figs[k]), len(figs)), strict=True):
        artefacts.save_figure(stage_dir / f"{key}.png", fig, png=png)
        figures.append(f"{key}.png")
    if result.report_md:
        artefacts.write_text(stage_dir / REPORT_MD, result.report_md.rstrip() + "\n")
    if result.robot is not None:
        save_exact_robot(result.robot, stage_dir / ROBOT_DIR)
    return figures


def write_stage_result(stage_dir: Path, name: str, result: StageResult, inputs_sha256: str,
                       duration_s: float, run_key: str = "", inputs: Mapping | None = None) -> None:
    """Write a StageResult into a (staging) directory; manifest with file hashes, ``inputs.sha256`` last."""
    figures = _write_payload(stage_dir, result)
    artefacts.write_json(stage_dir / MANIFEST, {
        "stage": name,
        "inputs_sha256": inputs_sha256,
        "run_key_sha256": run_key,
        "figures": figures,
        "has_robot": result.robot is not None,
        "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "duration_s": round(duration_s, 3),
        "package_version": pipeline.__version__,
        "files_sha256": directory_hashes(stage_dir),
        **({"inputs": to_plain(inputs)} if inputs else {}),
    })
    artefacts.write_text(stage_dir / INPUTS_HASH, inputs_sha256 + "\n")


def changed_inputs(old: object, new: Mapping, stage: str) -> str:
    """``": <what>"`` naming the inputs that differ between a stage's recorded inputs (its
    manifest's ``inputs``) and the new ones: settings of its section, run settings, robot files,
    upstream stages, package version, source code; "" when nothing was recorded."""
    if not isinstance(old, Mapping) or not new:
        return ""
    what: list[str] = []
    old_cfg, new_cfg = old.get("config") or {}, new.get("config") or {}
    if isinstance(old_cfg, Mapping) and isinstance(new_cfg, Mapping):
        what += [f"{stage}.{k}" for k in sorted(set(old_cfg) | set(new_cfg)) if old_cfg.get(k) != new_cfg.get(k)]
    old_up, new_up = old.get("upstream") or {}, new.get("upstream") or {}
    what += [f"upstream stage {s}" for s in sorted(set(old_up) | set(new_up)) if old_up.get(s) != new_up.get(s)]
    names = {"run": "run settings (seed, robot, truth, settings read from other sections)",
             "robot_files": "robot files", "version": "package version", "code": "source code"}
    what += [text for key, text in names.items() if to_plain(old.get(key)) != to_plain(new.get(key))]
    return f": {', '.join(what)}" if what else ""


def write_rejected(staging: Path, final: Path, name: str, result: StageResult, reason: str) -> Path:
    """Keep a result that failed its quality gate in ``final`` (``<run>/<stage>.rejected/``)."""
    figures = _write_payload(staging, result)
    artefacts.write_json(staging / MANIFEST, {
        "stage": name, "rejected": True, "reason": reason, "figures": figures,
        "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "package_version": pipeline.__version__, "files_sha256": directory_hashes(staging),
    })
    return commit_stage_dir(staging, final)


def read_manifest(stage_dir: Path) -> dict:
    """``manifest.json`` of a stage directory ({} when absent or unreadable)."""
    try:
        data = json.loads((stage_dir / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def stage_problem(stage_dir: Path) -> str | None:
    """Why the finished stage directory cannot be trusted, or None (all recorded files intact)."""
    if read_inputs_hash(stage_dir) is None:
        return "not a finished stage directory (no inputs.sha256)"
    manifest = read_manifest(stage_dir)
    files = manifest.get("files_sha256")
    if not isinstance(files, Mapping):
        return "manifest.json is missing, unreadable or records no file checksums"
    if manifest.get("inputs_sha256") != read_inputs_hash(stage_dir):
        return "inputs.sha256 differs from the manifest"
    for rel, digest in files.items():
        path = stage_dir / rel
        if not path.is_file():
            return f"{rel} is missing"
        if file_sha256(path) != digest:
            return f"{rel} was changed or truncated after the stage wrote it (SHA-256 differs)"
    return None


def load_stage_output(stage_dir: str | Path, robot: RobotModel | None = None, verify: bool = True) -> StageOutput:
    """Load ``summary.json``, ``results.npz``, ``results.json`` and ``robot/`` of a stage.

    ``robot``: an already loaded RobotModel to use instead of reading ``robot/`` again.
    ``verify``: check the files against the manifest's SHA-256 first (:func:`stage_problem`);
    a damaged stage raises :class:`PipelineError` naming the file.
    """
    d = Path(stage_dir)
    problem = stage_problem(d) if verify else None
    if problem is not None:
        raise PipelineError(d, None, problem)
    if not (d / INPUTS_HASH).exists():
        raise PipelineError(d, None, "not a finished stage directory (no inputs.sha256)")
    try:
        summary = artefacts.read_json(d / SUMMARY) if (d / SUMMARY).exists() else {}
        arrays = artefacts.read_npz(d / RESULTS_NPZ) if (d / RESULTS_NPZ).exists() else {}
        data = artefacts.read_json(d / RESULTS_JSON) if (d / RESULTS_JSON).exists() else {}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise PipelineError(d, None, f"cannot read the stage's files ({' '.join(str(exc).split())})") from None
    if robot is None and (d / ROBOT_DIR).is_dir():
        robot = load_exact_robot(d / ROBOT_DIR)
    return StageOutput(summary=summary, arrays=arrays, data=data, robot=robot, path=d)


def load_run(run_dir: str | Path) -> dict[str, StageOutput]:
    """Every finished stage of a run directory, in run order (unknown stage dirs last).

    Each stage is verified against its manifest's SHA-256 list; a run whose stage directories
    come from different run settings (seed, robot, truth: another ``config.yaml``) is refused.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise PipelineError(run_dir, None, "run directory not found")
    names = [s for s in config_mod.stage_names() if (run_dir / s / INPUTS_HASH).exists()]
    names += sorted(p.name for p in run_dir.iterdir() if p.is_dir() and not p.name.startswith(".")
                    and p.name not in names and (p / INPUTS_HASH).exists())
    expected = _config_run_key(run_dir / "config.yaml")
    for name in names:
        recorded = read_manifest(run_dir / name).get("run_key_sha256")
        if expected is not None and recorded != expected:
            raise PipelineError(run_dir / name, None, "mixed run: this stage was made with other run settings "
                                "(seed, robot or truth) than config.yaml; re-run it or use another run directory")
    return {n: load_stage_output(run_dir / n) for n in names}


def _config_run_key(path: Path) -> str | None:
    """The run key of a run's ``config.yaml`` (None when there is none)."""
    if not path.is_file():
        return None
    try:
        data = load_yaml(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, YAMLError) as exc:
        raise PipelineError(path, None, f"cannot read ({' '.join(str(exc).split())})") from None
    if not isinstance(data, Mapping):
        raise PipelineError(path, None, "not a run configuration")
    robot = str(data.get("robot", ""))
    return run_key_sha256(data.get("seed", 0), Path(robot).name or robot, data.get("truth") or {})


# --------------------------------------------------------------------------------------------
# Stage directories
# --------------------------------------------------------------------------------------------
def new_stage_dir(run_dir: str | Path, stage: str) -> Path:
    """Create the staging directory ``<run_dir>/.<stage>.partial-XXXX/``."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    path = Path(tempfile.mkdtemp(dir=run_dir, prefix=f".{stage}.partial-"))
    os.chmod(path, 0o777 & ~artefacts.UMASK)
    return path


def commit_stage_dir(staging: str | Path, final: str | Path) -> Path:
    """Rename the complete ``staging`` directory to ``final``, replacing an old one."""
    staging, final = Path(staging), Path(final)
    old: Path | None = None
    if final.exists():
        old = Path(tempfile.mkdtemp(dir=final.parent, prefix=f".{final.name}.old-"))
        os.rmdir(old)
        os.replace(final, old)
    os.replace(staging, final)
    artefacts.fsync_dir(final.parent)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return final


def discard_stage_dir(staging: str | Path) -> None:
    shutil.rmtree(staging, ignore_errors=True)


def clean_leftovers(run_dir: str | Path) -> None:
    """Remove ``.<stage>.partial-*`` / ``.<stage>.old-*`` directories left by a killed run."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        return
    for p in run_dir.iterdir():
        if p.is_dir() and p.name.startswith(".") and (".partial-" in p.name or ".old-" in p.name):
            shutil.rmtree(p, ignore_errors=True)


def read_inputs_hash(stage_dir: str | Path) -> str | None:
    """The stored inputs hash of a finished stage directory, or None."""
    p = Path(stage_dir) / INPUTS_HASH
    try:
        return p.read_text(encoding="utf-8").strip() or None
    except OSError:
        return None


# --------------------------------------------------------------------------------------------
# Inputs hash
# --------------------------------------------------------------------------------------------
def inputs_hash(
    stage: str,
    stage_config: object,
    run: Mapping[str, Any],
    robot_files_sha256: str,
    upstream: Mapping[str, str],
    package_version: str,
    code_sha256: str = "",
) -> str:
    """sha256 of everything a stage's result depends on.

    ``run``: run-level settings that matter (seed, robot, truth section); ``upstream``: stage
    name -> its inputs hash; ``code_sha256``: hash of the stage's source files (optional).
    """
    payload = {
        "stage": stage,
        "config": stage_config,
        "run": run,
        "robot_files": robot_files_sha256,
        "upstream": dict(sorted(upstream.items())),
        "version": package_version,
        "code": code_sha256,
    }
    return hashlib.sha256(artefacts.stable_json(payload).encode()).hexdigest()


#: the stages that measure the arm (tracker readings, joint torques): recorded from one arm or
#: simulated on the hidden robot
MEASURING_STAGES = ("calibration", "identification")


def combined_arms(stages: Mapping[str, Provenance]) -> str:
    """One sentence when a planned stage combines a recorded measurement of the arm with a simulated
    one of the hidden robot (two different arms: e.g. a simulated identification starting from a
    recorded calibration's kinematics, or a control stage using a simulated calibration and a
    recorded identification), else "". A stage's own measurement and those of its upstream
    :data:`MEASURING_STAGES` are compared."""
    combining = []
    for name, record in stages.items():
        measured = {n: stages[n] for n in (*record.upstream, name) if n in MEASURING_STAGES and n in stages
                    and (stages[n].recorded or stages[n].simulated)}
        if {p.kind for p in measured.values()} >= {RECORDED, SIMULATED}:
            combining.append((name, measured))
    if not combining:
        return ""
    _, measured = combining[0]
    what = ", ".join(f"{n} is {p.label()}" for n, p in measured.items())
    return (f"two different arms combined: {what}; {', '.join(n for n, _ in combining)} "
            f"{'uses' if len(combining) == 1 else 'use'} both, so its figures mix the arm measured with the "
            "simulated robot (record both stages from the same arm, or simulate both)")


def write_provenance(run_dir: Path, stages: Mapping[str, Provenance], second_pass: str) -> Path:
    """``<run>/provenance.json``: each planned stage's provenance, whether two different arms are
    combined (:func:`combined_arms`) and whether the second calibration pass ran, and why (rewritten
    only when it changes)."""
    record = {"stages": {name: p.to_dict() for name, p in stages.items()}, "arms_combined": combined_arms(stages),
              "second_pass": second_pass}
    path = Path(run_dir) / PROVENANCE_FILE
    try:
        if artefacts.read_json(path) == record:
            return path
    except (OSError, ValueError):
        pass
    return artefacts.write_json(path, record)

