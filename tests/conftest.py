"""Shared fixtures.

* ``quick_config``: the quick profile (``configs/quick.yaml``) as a fresh :class:`RunConfig`.
* ``rx130l``: the built-in robot, loaded once per session (do not mutate it; use ``.copy()``).
* ``fake_stages``: replaces the stage registry with small fake stages (runner tests).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture
def quick_config():
    from pipeline.config import CONFIGS_DIR, load_config

    return load_config(CONFIGS_DIR / "quick.yaml")


@pytest.fixture(scope="session")
def rx130l():
    from pipeline.robot.model import RobotModel

    return RobotModel.load("rx130l")


# ---------------------------------------------------------------------------- fake stages
@dataclass
class FakeConfig:
    n: int = 3
    gain: float = 1.0
    label: str = "x"
    fail: bool = False              # raise halfway through run()


class FakeStages:
    """Registry of fake stages ``a -> b -> c`` recording their calls."""

    def __init__(self) -> None:
        self.calls: list[str] = []
        self.contexts: dict[str, Any] = {}
        self.hand_robot: set[str] = set()

    def make(self, name: str, depends: tuple[str, ...] = ()) -> SimpleNamespace:
        def run(ctx: Any) -> Any:
            from matplotlib.figure import Figure

            from pipeline.stage_api import StageResult

            self.calls.append(name)
            self.contexts[name] = ctx
            (ctx.out_dir / "extra.txt").write_text(f"{name} started\n")
            if ctx.config.fail:
                raise RuntimeError(f"stage {name} failed halfway")
            fig = Figure(figsize=(2, 2))
            fig.add_subplot(111).plot([0, 1], [0, ctx.config.gain])
            robot = None
            if name in self.hand_robot:
                robot = ctx.robot.copy()
                robot.model.armature = robot.model.armature * 2.0
            return StageResult(
                summary={"n": ctx.config.n, "draw": float(ctx.rng.random()), "nested": {"gain": ctx.config.gain}},
                arrays={"x": np.arange(ctx.config.n, dtype=float), "configurations_test": np.zeros((2, 6)),
                        "trajectory_move_t": np.linspace(0, 1, 5), "trajectory_move_q": np.zeros((5, 6))},
                data={"label": ctx.config.label, "upstream": sorted(ctx.upstream)},
                figures={"plot": fig},
                robot=robot,
                report_md=f"stage **{name}** says hello",
            )

        return SimpleNamespace(NAME=name, DEPENDS=depends, Config=FakeConfig, run=run, __file__=None)


@pytest.fixture(scope="session")
def shipped_configs(rx130l):
    """(config, robot) pairs every shipped setting must pass: the defaults and configs/quick.yaml
    on the RX130L, and both on the TX40 with its robot.yaml run_defaults."""
    from pipeline.config import CONFIGS_DIR, load_config
    from pipeline.robot.model import RobotModel

    tx40 = RobotModel.load("staubli_tx40")
    return [(load_config(path, values={"robot": name} if name != "rx130l" else None), robot)
            for name, robot in (("rx130l", rx130l), ("staubli_tx40", tx40))
            for path in (None, CONFIGS_DIR / "quick.yaml")]


@pytest.fixture
def fake_stages(monkeypatch):
    from pipeline import config

    fakes = FakeStages()
    registry = {"a": fakes.make("a"), "b": fakes.make("b", ("a",)), "c": fakes.make("c", ("b",))}
    monkeypatch.setattr(config, "STAGES", registry)
    # the built-in robots' run_defaults name the real stages' sections, which the fakes replace
    monkeypatch.setattr(config, "robot_run_defaults", lambda cfg: None)
    return fakes


# ---------------------------------------------------------------------------- notebooks
NOTEBOOKS = REPO / "notebooks"


def _execute_notebook(name: str, workdir: Path) -> str:
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(workdir)}}).execute()
    return "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))


@pytest.fixture
def execute_notebook():
    """``execute_notebook(name, workdir) -> str``: run ``notebooks/<name>`` top to bottom in
    ``workdir`` and return the text of all its outputs."""
    return _execute_notebook
