"""``python -m pipeline check``: the plan ``run`` would follow, first calibration pass included,
computed without writing anything (:mod:`pipeline.run.second_pass`, :func:`pipeline.run.runner.prepare_run`).

* No first pass wanted: the plan of :func:`~pipeline.run.runner.prepare_run`.
* A first pass whose stages are all reusable: its results are read (not written) and the second
  pass's plan is computed exactly as ``run`` would (the gravity model enters the inputs hash by
  content, so the first pass's robot folder gives the same hashes as ``run``'s copy of it).
  Without a second pass (``auto`` below the threshold) the first pass's stages are reused.
* A first pass that must run: this run's stages depend on its results, so they are reported as
  running after it, with the first pass's reasons.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from pipeline.core import config as config_mod
from pipeline.core.config import RunConfig
from pipeline.run import second_pass
from pipeline.run.runner import Prepared, prepare_run
from pipeline.run.stage_io import load_stage_output
from pipeline.run.stage_plan import unavailable_stages


def check_run(cfg: RunConfig, out_root: str | Path | None = None, force: bool | Sequence[str] = False) -> Prepared:
    """What :func:`pipeline.run.runner.run_pipeline` would do with the same arguments; writes nothing."""
    prep = prepare_run(cfg, out_root, force)
    available = [n for n in config_mod.stage_names() if n not in unavailable_stages(prep.nominal)]
    first_pass, why_not = second_pass.decision(cfg, [p.name for p in prep.plans], available)
    if not first_pass:
        return replace(prep, second_pass=why_not)
    first = prepare_run(second_pass.first_pass_config(cfg), second_pass.first_pass_root(prep.run_dir), force)
    todo = {n: r for n, r in first.reasons.items() if r is not None}
    if todo:
        why = "; ".join(f"{n}: {r}" for n, r in todo.items())
        return replace(prep, reasons={p.name: f"after the first calibration pass ({why})" for p in prep.plans})
    outputs = {n: load_stage_output(first.run_dir / n) for n in first.reasons}
    second = second_pass.second_pass_config(cfg, outputs, prep.run_dir, write=False)
    if second is None:     # the first pass's stages are reused (copied into this run)
        return replace(prep, reasons={p.name: None if p.name in outputs else prep.reasons[p.name]
                                      for p in prep.plans})
    return prepare_run(second, prep.run_dir.parent, force)
