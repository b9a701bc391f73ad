"""Sweeps: a grid of pipeline runs (seeds × robots × varied settings) and the table of their
headline figures (``python -m pipeline sweep``).

Every grid point is an ordinary run: :func:`pipeline.core.config.load_config` with the sweep's
``--config``, its ``--set`` overrides, the point's ``seed=…``, ``robot=…``, varied settings and
``name=…``, then :func:`pipeline.run.runner.run_pipeline` into ``<out>/runs/<name>/`` (a finished
stage with the same inputs is reused, as with ``run``). Each run returns its flattened
``summary.json`` figures (:mod:`pipeline.run.sweep_table`); the rows are gathered in grid order into
``<out>/sweep.csv``, ``sweep.md`` and ``sweep.png`` (median and 95th percentile per robot).

The runs go to local worker processes through joblib (``jobs``), or, with ``scheduler`` (an
address such as ``tcp://host:8786``, or a ``distributed.Client``), to a Dask distributed cluster
(:func:`pipeline.core.dispatch.map_tasks`):
its workers need this package installed, the robot and config files at the same paths and the
output directory on a shared file system. A run is a pure function of its configuration (every
random number comes from a generator seeded by it, :func:`pipeline.stage_api.stage_rng`), so the
table does not depend on where the runs went, apart from wall-clock timings.

A sweep runs the stages asked for (``stages``) and their upstream stages only: when these hold
calibration but not identification, its points set ``calibration.second_pass: never`` (unless the
sweep sets it), since the second pass's first pass runs identification, whose gates would then fail
a calibration row (the setting is in each run's ``config.yaml``).

Every configuration is loaded (and so validated) before the first run starts: bad input is one
:class:`~pipeline.core.errors.PipelineError` and nothing is written. A run that fails with a
``PipelineError`` (e.g. a quality gate) becomes a row with that one-line error as its ``status``.
"""

from __future__ import annotations

import argparse
import itertools
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from pipeline.core.config import REPO_ROOT, RunConfig, load_config, parse_set
from pipeline.core.dispatch import map_tasks
from pipeline.core.errors import ConfigError, PipelineError
from pipeline.core.progress import Progress
from pipeline.core.yaml12 import dump_yaml
from pipeline.run.runner import run_pipeline
from pipeline.run.stage_plan import plan_stages
from pipeline.run.sweep_table import Cell, Row, flatten_summary, write_outputs

__all__ = ["SweepPoint", "SweepSpec", "parse_seeds", "parse_vary", "grid", "run_point", "run_sweep",
           "add_arguments", "main", "varied_column"]


@dataclass(frozen=True)
class SweepPoint:
    """One run of the grid (everything a worker needs to rebuild its configuration)."""

    name: str
    robot: str
    seed: int
    varied: tuple[tuple[str, Cell], ...]     # (dotted key, value) of the varied settings
    config_path: str | None                  # absolute path of the YAML config (None: defaults)
    overrides: tuple[str, ...]               # the sweep's --set items, then seed/robot/name/varied
    stages: str | None
    runs_dir: str                            # <out>/runs


@dataclass
class SweepSpec:
    """The grid: ``seeds`` × ``robots`` × the product of ``vary`` values, each with ``overrides``."""

    seeds: list[int]
    robots: list[str | None]                 # None: the config's robot
    out_dir: Path
    config_path: str | None = None
    overrides: list[str] = field(default_factory=list)
    vary: dict[str, list[Cell]] = field(default_factory=dict)
    stages: str | None = None
    name: str = "sweep"


def parse_seeds(text: str) -> list[int]:
    """``"0-19"``, ``"1,4,7"`` or ``"0-3,10"`` -> the seeds, in order, without repeats."""
    seeds: list[int] = []
    for part in (p.strip() for p in str(text).split(",")):
        match = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if match is None or (match[2] is not None and int(match[2]) < int(match[1])):
            raise ConfigError("--seeds", part, "expected seeds >= 0 or ranges LO-HI (e.g. 0-19,25)")
        seeds += range(int(match[1]), int(match[2] or match[1]) + 1)
    return list(dict.fromkeys(seeds))


def parse_vary(items: Sequence[str]) -> dict[str, list[Cell]]:
    """``["calibration.n_configurations=[20,40]"]`` -> {key: [20, 40]} (a scalar is one value)."""
    out: dict[str, list[Cell]] = {}
    for item in items:
        keys, value = parse_set(item)
        values = value if isinstance(value, list) else [value]
        if not values or any(isinstance(v, dict | list) for v in values):
            raise ConfigError("--vary", item, "expected KEY=[v1,v2,...] with scalar values")
        out[".".join(keys)] = values
    return out


def _yaml_value(value: Cell) -> str:
    return dump_yaml(value, flow=True).strip()


def _point_name(robot: str, seed: int, k: int | None) -> str:
    return f"{robot}-seed{seed}" + (f"-v{k}" if k is not None else "")


def grid(spec: SweepSpec) -> list[SweepPoint]:
    """The grid points in order (robot, varied settings, seed), their configurations validated."""
    if not spec.seeds:
        raise ConfigError("--seeds", None, "no seeds")
    config_path = str(Path(spec.config_path).resolve()) if spec.config_path else None
    combos = list(itertools.product(*spec.vary.values())) if spec.vary else [()]
    points: list[SweepPoint] = []
    for robot in spec.robots:
        for k, combo in enumerate(combos):
            varied = tuple(zip(spec.vary, combo, strict=True))
            for seed in spec.seeds:
                base = [*spec.overrides, f"seed={seed}"] + ([f"robot={robot}"] if robot else [])
                base += [f"{key}={_yaml_value(v)}" for key, v in varied]
                cfg = load_config(config_path, base, spec.stages)      # validates (PipelineError)
                if spec.stages and _first_pass_not_asked_for(cfg):
                    base.append(f"{SECOND_PASS_KEY}=never")
                    cfg = load_config(config_path, base, spec.stages)
                robot_name = Path(str(cfg.robot)).name
                name = _point_name(robot_name, seed, k if spec.vary else None)
                points.append(SweepPoint(name=name, robot=robot_name, seed=seed, varied=varied,
                                         config_path=config_path, overrides=(*base, f"name={name}"),
                                         stages=spec.stages, runs_dir=str(spec.out_dir / "runs")))
    names = [p.name for p in points]
    if len(set(names)) != len(names):
        raise ConfigError("--robots", ",".join(str(r) for r in spec.robots), "the same robot twice in the grid")
    return points


#: the setting of the second calibration pass, whose first pass runs identification (pipeline.run.second_pass)
SECOND_PASS_KEY = "calibration.second_pass"


def _first_pass_not_asked_for(cfg: RunConfig) -> bool:
    """Whether the planned stages hold calibration but not identification, and the second pass is
    not set: the runner's first pass would run identification too, and its gates could fail the row."""
    planned = {p.name for p in plan_stages(cfg)}
    return "calibration" in planned and "identification" not in planned and SECOND_PASS_KEY not in cfg.field_origins


def run_point(point: SweepPoint) -> Row:
    """Run one grid point (in a worker) and return its row of the table."""
    row: Row = {"run": point.name, "robot": point.robot, "seed": point.seed,
                **{varied_column(k): v for k, v in point.varied}}
    try:
        cfg = load_config(point.config_path, point.overrides, point.stages)
        result = run_pipeline(cfg, out_root=point.runs_dir, progress=Progress(enabled=False), log=_quiet)
    except PipelineError as exc:
        row["status"] = " ".join(exc.one_line().split())
        return row
    row["status"] = "ok"
    for stage, output in result.outputs.items():
        flatten_summary(stage, output.summary, row)
    return row


def varied_column(key: str) -> str:
    """Table column of a varied setting (``set.<key>``: apart from the summaries' own figures)."""
    return f"set.{key}"


def _quiet(_message: str) -> None:
    """Workers do not print the runner's stage messages (the sweep shows one bar)."""


def run_sweep(spec: SweepSpec, jobs: int = 1, scheduler: object = None,
              metrics: Sequence[str] = (), progress: Progress | None = None) -> tuple[list[Row], dict[str, Path]]:
    """Run the grid of ``spec`` and write the table; returns the rows (grid order) and the paths of
    ``sweep.csv``, ``sweep.md`` and ``sweep.png``."""
    points = grid(spec)
    prog = progress if progress is not None else Progress()
    with prog:
        rows = map_tasks(run_point, points, jobs=jobs, scheduler=scheduler, progress=prog, description="sweep")
    return rows, write_outputs(spec.out_dir, rows, [varied_column(k) for k in spec.vary], metrics)


# --------------------------------------------------------------------------------------------
# Command line (``python -m pipeline sweep``; the subparser is built in pipeline/cli.py)
# --------------------------------------------------------------------------------------------
def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``python -m pipeline sweep``."""
    p.add_argument("--config", metavar="FILE", help="YAML run configuration (e.g. configs/quick.yaml)")
    p.add_argument("--seeds", default="0", metavar="LIST", help="seeds: 0-19 or 1,4,7 (default 0)")
    p.add_argument("--robots", metavar="A,B", help="robot names or folders (default: the config's robot)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a setting in every run (repeatable)")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=[V1,V2]",
                   help="a setting taking each value in turn (repeatable; the grid is their product)")
    p.add_argument("--stages", metavar="A,B", help="stages to run (their upstream stages are added)")
    p.add_argument("--out", metavar="DIR", help="sweep directory (default data/sweeps/<name>)")
    p.add_argument("--name", default="sweep", help="sweep name (default 'sweep')")
    p.add_argument("--jobs", type=int, default=1, help="local worker processes (joblib; default 1)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler address (tcp://host:8786)")
    p.add_argument("--metric", dest="metrics", action="append", default=[], metavar="STAGE.KEY",
                   help="figure shown in the markdown and the plot (repeatable; default: headline figures)")


def main(ns: argparse.Namespace, say: Callable[[str], None] = print) -> int:
    """Run the sweep described by the parsed options ``ns``."""
    if ns.jobs < 1:
        raise ConfigError("--jobs", str(ns.jobs), "must be >= 1")
    out_dir = Path(ns.out) if ns.out else REPO_ROOT / "data" / "sweeps" / ns.name
    robots: list[str | None] = [r.strip() for r in ns.robots.split(",") if r.strip()] if ns.robots else [None]
    spec = SweepSpec(seeds=parse_seeds(ns.seeds), robots=robots, out_dir=out_dir, config_path=ns.config,
                     overrides=list(ns.overrides), vary=parse_vary(ns.vary), stages=ns.stages, name=ns.name)
    rows, paths = run_sweep(spec, jobs=ns.jobs, scheduler=ns.scheduler, metrics=ns.metrics)
    failed = [r for r in rows if r.get("status") != "ok"]
    say(f"{len(rows)} runs, {len(failed)} failed; table {paths['csv']}, {paths['markdown']}, plot {paths['plot']}")
    return 1 if failed else 0
