"""Study ``paper-004``: paper 004 §2.3.3, §4 and §5 (identification, control, trajectories) by
running the pipeline's own stages on the RX130L with the paper's settings.

Paper ``004_abbe750b8bbcc3aa.txt`` (Stäubli RX130L): 400 µs cascade with model-based
feedforward on the EN ISO 9283 path at 1 m/s and 5 m/s² (§2.3.3, Fig. 2); Fourier excitation
reaching 5 m/s and 12 m/s² at the TCP, identified model checked against measured motor torques
on the ISO path (§4.3, Fig. 5); time-optimal CP with a torque or speed limit active at every
instant (§5.3, Fig. 8); PtP minimising k1 T + k2 E under joint position, speed and torque
limits (§5.4, eq. 40). The settings are :data:`PAPER_SETTINGS` (also ``configs/paper004.yaml``).

Runs (``pipeline.run.runner.run_pipeline``; each its own run directory under ``--out``):
- ``main``: the chain on the default hidden robot (elastic joints, Stribeck friction), per seed;
- ``rigid`` (experiment): the same on the rigid hidden robot ``TruthConfig.ideal()``, stages up to
  control, to show what the elastic joints do to Fig. 2(b);
- ``acceleration limits`` (experiment): the trajectory stage with joint acceleration limits as
  well (the pipeline's default, not the paper's eqs. 38/40), upstream stages copied from
  ``main`` and reused;
- ``full torque`` (experiment): the identification stage with the excitation allowed the whole
  (estimated) torque limit instead of 80 % of it, to show what holds the excitation's TCP speed.
The stages up to control must pass their quality gates; the trajectory stages are kept when the
servo simulation of their plans fails a gate (``accept_poor``) and the failed gates are a row of
the table: on the elastic hidden robot the paper's literal (acceleration- and jerk-free) optimum
over-excites the joints, which is the paper's own argument (§5) for jerk-continuous plans.
The control stage itself runs the feedforward variants (none, gravity, full, full + friction,
elastic) and the nominal-model feedforward beside the identified one.

Output: the table of :mod:`pipeline.papers.chain_004_rows` (paper, ours, verdict) on stdout and
``<study dir>/result.json``. ``--quick`` uses ``configs/quick.yaml`` sizes with the same paper
settings (the test ``tests/papers/test_chain_004.py``).

Run time on the shared 2-core box (loaded by other jobs), measured once: the full study (seeds
1-3) 42 min (2494 s); ``--quick`` (seed 1) about 3-4 min; ``--report`` (the table from the stored
runs) seconds. Results: ``docs/papers/paper_004_chain.md``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any

from pipeline.core.config import CONFIGS_DIR, RunConfig, load_config
from pipeline.core.errors import PipelineError
from pipeline.core.progress import Progress
from pipeline.papers import chain_004_stiffness as stiff
from pipeline.papers.chain_004_rows import Row, Run, all_rows, markdown
from pipeline.papers.registry import save_result, study_dir
from pipeline.run.runner import run_pipeline
from pipeline.run.stage_io import load_run
from pipeline.sim.truth import TruthConfig

NAME = "paper-004"
FULL_CONFIG = CONFIGS_DIR / "paper004.yaml"
QUICK_CONFIG = CONFIGS_DIR / "quick.yaml"

#: the paper's settings (dotted config keys); configs/paper004.yaml holds the same values
PAPER_SETTINGS: dict[str, Any] = {
    "robot": "rx130l",
    "control.sample_time_s": 4e-4,                            # §2.3.2: 400 µs base sample time
    "control.iso.speed_m_s": 1.0,                              # §2.3.3: TCP 1 m/s ...
    "control.iso.acceleration_m_s2": 5.0,                      # ... and 5 m/s²
    "identification.excitation.max_tcp_speed_m_s": 5.0,        # §4.3: up to 5 m/s ...
    "identification.excitation.max_tcp_acceleration_m_s2": 12.0,   # ... and 12 m/s² at the TCP
    "identification.validation": "iso9283",                    # §4.3: torques checked on ISO 9283
    "trajectory.acceleration_limits": False,                   # eqs. 38/40: speed and torque limits only
}
#: quick: the feedforward variants the rows read (the full profile runs all of them)
QUICK_SETTINGS: dict[str, Any] = {"control.variants": ["none", "full_friction", "elastic_static"]}
#: stages of the rigid-robot experiment (Fig. 2 only)
RIGID_STAGES = ("model", "calibration", "identification", "control")
CHAIN_UPSTREAM = ("model", "calibration", "identification", "control")
#: stages of the excitation experiment (model and calibration copied from the main run)
EXCITATION_STAGES = ("model", "calibration", "identification")


def rigid_truth() -> dict[str, Any]:
    """``truth.*`` values of :meth:`TruthConfig.ideal` (rigid joints, no Stribeck, no gear error)."""
    ideal = TruthConfig.ideal()
    return {f"truth.{f.name}": getattr(ideal, f.name) for f in fields(TruthConfig)}


def chain_config(seed: int, quick: bool, variant: str = "main", stages: Sequence[str] | None = None,
                 accept_poor: bool = False) -> RunConfig:
    """The run config of one chain: ``variant`` main | rigid | acceleration_limits | full_torque."""
    values: dict[str, Any] = {"seed": seed, **PAPER_SETTINGS}
    if quick:
        values.update(QUICK_SETTINGS)
    if variant == "rigid":
        values.update(rigid_truth())
        stages = stages or list(RIGID_STAGES)
    elif variant == "acceleration_limits":
        values["trajectory.acceleration_limits"] = True
    elif variant == "full_torque":
        values["identification.excitation.torque_margin"] = 1.0
        stages = stages or list(EXCITATION_STAGES)
    elif variant != "main":
        raise ValueError(f"unknown variant {variant!r}")
    prefix = "p004q" if quick else "p004"
    values["name"] = f"{prefix}_{variant}_s{seed}"
    cfg = load_config(QUICK_CONFIG if quick else FULL_CONFIG, stages=None if stages is None else list(stages),
                      values=values)
    cfg.accept_poor = accept_poor
    return cfg


def _copy_upstream(src: Path, dst: Path, stages: Sequence[str]) -> None:
    """Seed run ``dst`` with ``src``'s finished stage directories (reused when their inputs
    hashes match, i.e. same seed, robot, truth and stage settings)."""
    dst.mkdir(parents=True, exist_ok=True)
    for name in stages:
        if (src / name).is_dir() and not (dst / name).exists():
            shutil.copytree(src / name, dst / name)


def run_chain(cfg: RunConfig, out: Path, say: Callable[[str], object]) -> Run:
    t0 = time.perf_counter()
    with Progress(enabled=False) as prog:
        res = run_pipeline(cfg, out, progress=prog, log=lambda m: say(f"  [{cfg.name}] {m}"))
    say(f"  [{cfg.name}] {time.perf_counter() - t0:.0f} s (ran {', '.join(res.ran) or 'nothing'})")
    return res.outputs


def run_or_report(cfg: RunConfig, out: Path, say: Callable[[str], object], failures: dict[str, str]) -> Run | None:
    """:func:`run_chain`, or None with the error recorded in ``failures[run name]`` (a stage that
    cannot plan or solve under the paper's settings is a result of the study, not its end)."""
    try:
        return run_chain(cfg, out, say)
    except PipelineError as exc:
        failures[cfg.name] = str(exc)
        say(f"  [{cfg.name}] failed: {exc}")
        return None


def run_study(seeds: Sequence[int], quick: bool, out: Path, experiments: bool = True,
              say: Callable[[str], object] = print,
              failures: dict[str, str] | None = None) -> tuple[list[Row], dict[str, float]]:
    """Every run of the study, then the rows; returns (rows, timings in s). The trajectory runs
    that fail (main and acceleration-limit experiment) are recorded in ``failures`` and their
    seeds left out of the trajectory rows."""
    failures = {} if failures is None else failures
    timings: dict[str, float] = {}
    main: list[Run] = []
    rigid: list[Run] = []
    acc: list[Run] = []
    full_torque: list[Run] = []
    t0 = time.perf_counter()
    for seed in seeds:
        # the stages up to control must pass their quality gates; the trajectory stage with the
        # paper's literal limits is kept even when its servo-simulation gates fail (reported)
        upstream = run_chain(chain_config(seed, quick, stages=CHAIN_UPSTREAM), out, say)
        main.append(run_or_report(chain_config(seed, quick, accept_poor=True), out, say, failures) or upstream)
    timings["main_s"] = time.perf_counter() - t0
    if experiments:
        t0 = time.perf_counter()
        for seed in seeds:
            rigid.append(run_chain(chain_config(seed, quick, "rigid"), out, say))
        timings["rigid_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        for seed in seeds:
            cfg = chain_config(seed, quick, "acceleration_limits", accept_poor=True)
            _copy_upstream(out / chain_config(seed, quick).name, out / cfg.name, CHAIN_UPSTREAM)
            res = run_or_report(cfg, out, say, failures)
            if res is not None:
                acc.append(res)
        timings["acceleration_limits_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        for seed in seeds:
            cfg = chain_config(seed, quick, "full_torque")
            _copy_upstream(out / chain_config(seed, quick).name, out / cfg.name, EXCITATION_STAGES[:2])
            full_torque.append(run_chain(cfg, out, say))
        timings["full_torque_s"] = time.perf_counter() - t0
    return all_rows(main, rigid, acc, full_torque, failures), timings


#: the experiments (run variants) beside the main chain
EXPERIMENTS = ("rigid", "acceleration_limits", "full_torque")


def stored_rows(seeds: Sequence[int], quick: bool, out: Path, failures: dict[str, str] | None = None) -> list[Row]:
    """The rows from the runs already under ``out`` (``--report``: nothing is run; an experiment
    whose run directories are missing is left out)."""
    main = [load_run(out / chain_config(seed, quick).name) for seed in seeds]
    found: dict[str, list[Run]] = {}
    for variant in EXPERIMENTS:
        dirs = [out / chain_config(seed, quick, variant).name for seed in seeds]
        runs = [load_run(d) for d in dirs if d.is_dir()]
        found[variant] = [r for r in runs if variant != "acceleration_limits" or "trajectory" in r]
    return all_rows(main, found["rigid"], found["acceleration_limits"], found["full_torque"], failures or {})


def stiffness_study(scales: Sequence[float], seeds: Sequence[int], out: Path) -> int:
    """Fig. 2(b) against the joint stiffness (:mod:`pipeline.papers.chain_004_stiffness`)."""
    t0 = time.perf_counter()
    print(f"paper 004 Fig. 2(b) against the joint stiffness (quick sizes, the paper's settings, seeds {list(seeds)}, "
          f"joint compliance x {list(scales)}); runs under {out}")
    settings = {**PAPER_SETTINGS, **QUICK_SETTINGS}
    points = stiff.run_stiffness(scales, seeds, lambda cfg: run_chain(cfg, out, print),
                                 lambda seed, s: stiff.stiffness_config(seed, s, QUICK_CONFIG, settings))
    print("\n" + stiff.markdown(points))
    drastic = stiff.largest_drastic_scale(points)
    print("\nlargest compliance scale with a drastic cut on every seed: "
          + ("none of those run" if drastic is None else f"{drastic:g} (stiffness x {1 / drastic:g})"))
    elapsed = time.perf_counter() - t0
    print(f"study time {elapsed:.0f} s")
    save_result(NAME, {"args": {"compliance_scales": list(scales), "seeds": list(seeds)},
                       "paper_settings": settings, "points": points, "largest_drastic_scale": drastic,
                       "time_s": elapsed}, "result-stiffness.json")
    return 0


def study_paper_004(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog=f"study {NAME}", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="configs/quick.yaml sizes (the test)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None, help="default 1 2 3 (--quick: 1)")
    ap.add_argument("--out", type=Path, default=None, help="runs directory (default <study dir>/runs[-quick])")
    ap.add_argument("--no-experiments", action="store_true", help="only the main chain (no rigid / acceleration runs)")
    ap.add_argument("--jobs", type=int, default=1, help="accepted for uniformity; the runs are sequential")
    ap.add_argument("--report", action="store_true", help="only print the table from the runs under --out")
    ap.add_argument("--compliance-scales", type=float, nargs="+", default=None,
                    help="only the Fig. 2(b) stiffness experiment: the chain up to control (quick sizes) on hidden "
                         "robots with joint compliance x S (pipeline.papers.chain_004_stiffness)")
    a = ap.parse_args(argv)
    if a.seeds is None:
        a.seeds = [1] if a.quick or a.compliance_scales else [1, 2, 3]
    out = a.out if a.out is not None else study_dir(NAME) / ("runs-quick" if a.quick else "runs")
    if a.compliance_scales:
        return stiffness_study(a.compliance_scales, a.seeds, out)
    t0 = time.perf_counter()
    print(f"paper 004 §2.3.3, §4, §5 on the RX130L ({'quick' if a.quick else 'full'} sizes, seeds {a.seeds}); "
          f"runs under {out}")
    path = study_dir(NAME) / ("result-quick.json" if a.quick else "result.json")
    failures: dict[str, str] = {}
    if a.report:
        last = json.loads(path.read_text()) if path.exists() else {}
        failures.update(last.get("failures", {}))
        rows = stored_rows(a.seeds, a.quick, out, failures)
        timings = last.get("timings_s", {})
        print("(--report: rows from the stored runs; failures and study time of the last full run)")
    else:
        rows, timings = run_study(a.seeds, a.quick, out, not a.no_experiments, failures=failures)
        timings["total_s"] = time.perf_counter() - t0
    print("\n" + markdown(rows))
    if timings:
        print(f"\nstudy time {timings.get('total_s', float('nan')):.0f} s "
              f"({', '.join(f'{k} {v:.0f}' for k, v in timings.items())})")
    result = {"args": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(a).items()},
              "paper_settings": PAPER_SETTINGS, "rows": [r.to_dict() for r in rows], "timings_s": timings,
              "failures": failures}
    save_result(NAME, result, path.name)
    return 0
