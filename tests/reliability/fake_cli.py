"""The pipeline's command line with three fake stages ``a -> b -> c``, for the fault tests.

Run as a script (``python fake_cli.py run --out DIR --set ...``) it is a real process to signal, kill
or run beside another; imported, :func:`registry` gives the same stages to run in the test's own
process (same code, same inputs hashes: a run started in a child resumes in the parent).

Each stage writes ``part.txt`` into its staging folder first (a half-written stage to find if it
were ever committed). ``<stage>.sleep_s``: then mark ``<run>/<stage>.started`` and wait that long in
a Python loop, like a stage's work. ``<stage>.values_per_seed_squared``: store ``seed**2`` times that
many random values (to fill a small disk) instead of three numbers.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from pipeline import cli
from pipeline.core import config
from pipeline.core.config import RunConfig
from pipeline.run import stages as stage_registry
from pipeline.stage_api import StageContext, StageResult


@dataclass
class Config:
    sleep_s: float = 0.0
    values_per_seed_squared: int = 0


def make(name: str, depends: tuple[str, ...]) -> SimpleNamespace:
    def run(ctx: StageContext) -> StageResult:
        (ctx.out_dir / "part.txt").write_text("half")
        if ctx.config.sleep_s:
            marker = ctx.out_dir.parent / f"{name}.started"
            marker.write_text("x")
            deadline = time.monotonic() + ctx.config.sleep_s
            while time.monotonic() < deadline:
                time.sleep(0.01)
        n = ctx.config.values_per_seed_squared
        x = np.random.default_rng(1).random(ctx.run.seed ** 2 * n) if n else np.arange(3.0)
        return StageResult(summary={"seed": ctx.run.seed}, arrays={"x": x})

    return SimpleNamespace(NAME=name, DEPENDS=depends, Config=Config, run=run, __file__=None)


def registry() -> dict[str, SimpleNamespace]:
    return {"a": make("a", ()), "b": make("b", ("a",)), "c": make("c", ("b",))}


def no_run_defaults(cfg: RunConfig) -> None:
    """The built-in robots' run_defaults name the real stages' sections, which the fakes replace."""
    return None


if __name__ == "__main__":
    stage_registry.STAGES = registry()
    config.robot_run_defaults = no_run_defaults
    sys.exit(cli.main(sys.argv[1:]))
