"""Shared fixtures (reuse them instead of building the same thing again in a test file).

* ``quick_config``: the quick profile (``configs/quick.yaml``) as a fresh :class:`RunConfig`.
* ``rx130l``: the built-in robot, loaded once per session (do not mutate it; use ``.copy()``).
* ``shipped_configs``: (config, robot) pairs every shipped setting must pass.
* ``fake_stages``: replaces the stage registry with small fake stages (runner tests).
* ``fuzz_inputs``: ``fuzz_inputs[reader] += 1`` per generated input of a property test; the counts per
  reader are printed after the run (tests/reliability/test_fuzz_*.py).
* ``execute_notebook(name, workdir, parameters=None) -> ExecutedNotebook``: every code cell of
  ``notebooks/<name>`` run top to bottom in an IPython shell inside the test process (no kernel start, no
  second import of the package), returning the text the cells printed and the objects they showed
  (``.images``: the figures shown inline); ``parameters`` set its ``# parameter`` lines.
* ``tests/trajectory/conftest.py``: the RX130L planning model, the quick ISO line, ONE compiled PtP
  problem and ONE quick-profile PtP plan of the big move (``big_move_plan``).

Sharing a costly result (a stage run, a solved problem) between test files: put a session-scoped
fixture here or in the package's conftest; it is built once per pytest-xdist worker (at most twice
per ``make test``), see ``big_move_plan``.

Compiled CasADi code is cached on disk by content (``$PIPELINE_CACHE_DIR``, see
:mod:`pipeline.core.codegen`), so a compiled function is built once per machine, not per worker.
Durations: ``--durations=15`` (pyproject ``addopts``) prints the slowest tests of every run.
"""

from __future__ import annotations

import builtins
import collections
import contextlib
import io
import os
import re
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import nbformat  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from IPython.core.interactiveshell import InteractiveShell
from IPython.core.pylabtools import select_figure_formats  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from traitlets.config import Config  # noqa: E402

from pipeline.core import config as config_module  # noqa: E402
from pipeline.core.config import CONFIGS_DIR, load_config  # noqa: E402
from pipeline.robot.model import RobotModel  # noqa: E402
from pipeline.run import stages as stage_registry  # noqa: E402
from pipeline.stage_api import StageResult  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture
def quick_config():
    return load_config(CONFIGS_DIR / "quick.yaml")


@pytest.fixture(scope="session")
def rx130l():
    return RobotModel.load("rx130l")


@pytest.fixture(scope="session")
def rx130l_generic_stiffness():
    """The RX130L with the generic joint stiffness of :mod:`pipeline.robot.stiffness` (torque limit /
    2 mrad) instead of the one its robot.yaml states, 33x softer: gravity deflections of tenths of a
    millimetre and a low first mode, for the tests of the elastic models (nominal and hidden robot)."""
    robot = RobotModel.load("rx130l")
    robot.spec.actuation.joint_stiffness_Nm_rad = None
    return robot


@pytest.fixture(scope="session")
def rx130l_generic_stiffness_dir(tmp_path_factory) -> Path:
    """A robot folder, for runs by ``robot=<folder>``: robots/rx130l/ without its stated joint stiffness
    (the generic rule applies: an arm whose own weight deflects it by tenths of a millimetre)."""
    source = Path(__file__).resolve().parents[1] / "robots" / "rx130l"
    target = tmp_path_factory.mktemp("rx130l_generic_stiffness") / "rx130l"
    shutil.copytree(source, target)
    text = (target / "robot.yaml").read_text(encoding="utf-8")
    kept = [line for line in text.splitlines() if not line.strip().startswith("joint_stiffness_Nm_rad:")]
    assert len(kept) == len(text.splitlines()) - 1
    (target / "robot.yaml").write_text("\n".join(kept) + "\n", encoding="utf-8")
    return target


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
    tx40 = RobotModel.load("staubli_tx40")
    return [(load_config(path, values={"robot": name} if name != "rx130l" else None), robot)
            for name, robot in (("rx130l", rx130l), ("staubli_tx40", tx40))
            for path in (None, CONFIGS_DIR / "quick.yaml")]


@pytest.fixture
def fake_stages(monkeypatch):
    fakes = FakeStages()
    registry = {"a": fakes.make("a"), "b": fakes.make("b", ("a",)), "c": fakes.make("c", ("b",))}
    monkeypatch.setattr(stage_registry, "STAGES", registry)
    # the built-in robots' run_defaults name the real stages' sections, which the fakes replace
    monkeypatch.setattr(config_module, "robot_run_defaults", lambda cfg: None)
    return fakes


# ---------------------------------------------------------------------------- notebooks
NOTEBOOKS = REPO / "notebooks"


@contextlib.contextmanager
def _ipython_shell(workdir: Path):
    """A fresh IPython shell working in ``workdir``; afterwards the process is as before: the shell
    instance cleared, ``__main__``, the builtins it adds (``__IPYTHON__``, ``display``), the sys hooks,
    the working directory, the open figures and the pyplot backend and rcParams (a notebook's
    ``%matplotlib inline`` switches them) restored."""
    saved_main, saved_cwd = sys.modules.get("__main__"), Path.cwd()
    saved_hooks = (sys.excepthook, sys.displayhook)
    saved_builtins = {k: builtins.__dict__[k] for k in ("__IPYTHON__", "display", "get_ipython")
                      if k in builtins.__dict__}
    settings = Config()
    settings.HistoryManager.enabled = False        # no history database shared by the workers
    InteractiveShell.clear_instance()
    shell = InteractiveShell.instance(config=settings)
    shell.enable_gui = lambda gui=None: None       # as a kernel's shell: no event loop (%matplotlib inline)
    # figures shown as PNG, as in a fresh kernel after %matplotlib inline: matplotlib-inline configures only
    # the first shell of a process, and a test worker runs several notebooks
    select_figure_formats(shell, {"png"})
    saved_backend = matplotlib.get_backend()
    try:
        with matplotlib.rc_context():              # %matplotlib inline sets rcParams of its own
            os.chdir(workdir)
            yield shell
    finally:
        plt.switch_backend(saved_backend)          # %matplotlib inline switched pyplot to its backend
        os.chdir(saved_cwd)
        shell.reset(new_session=False)
        InteractiveShell.clear_instance()
        if saved_main is not None:
            sys.modules["__main__"] = saved_main
        sys.excepthook, sys.displayhook = saved_hooks
        for k in ("__IPYTHON__", "display", "get_ipython"):
            builtins.__dict__.pop(k, None)
        builtins.__dict__.update(saved_builtins)
        plt.close("all")


def _with_parameters(cells: list[str], parameters: dict[str, Any]) -> list[str]:
    """The cells with each parameter line ``NAME = ...  # parameter: ...`` of ``parameters`` set to its value."""
    for key, value in parameters.items():
        line = re.compile(rf"^{key} = .*# parameter.*$", re.MULTILINE)
        assert sum(len(line.findall(c)) for c in cells) == 1, f"no parameter line {key} = ...  # parameter"
        cells = [line.sub(lambda _m, k=key, v=value: f"{k} = {v!r}  # parameter (set by the test)", c) for c in cells]
    return cells


@dataclass
class ExecutedNotebook:
    """What the code cells of a notebook showed: the text they printed (displayed objects and cell
    results as their plain text), and every displayed object and cell result as its MIME bundle
    (``{"text/plain": ..., "image/png": ...}``), as a notebook front end receives them."""

    text: str
    outputs: list[dict[str, Any]]

    @property
    def images(self) -> list[dict[str, Any]]:
        """The outputs holding a PNG image (a figure shown inline)."""
        return [o for o in self.outputs if "image/png" in o]


def _execute_notebook(name: str, workdir: Path, parameters: dict[str, Any] | None = None) -> ExecutedNotebook:
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    cells = _with_parameters([c.source for c in nb.cells if c.cell_type == "code"], parameters or {})
    text, outputs = io.StringIO(), []
    with _ipython_shell(workdir) as shell, contextlib.redirect_stdout(text):
        printed = shell.display_pub.publish

        def publish(data: dict[str, Any], *args: Any, **kwargs: Any) -> None:
            outputs.append(dict(data))                 # display(...) and the figures shown inline
            printed(data, *args, **kwargs)

        shell.display_pub.publish = publish
        for i, source in enumerate(cells):
            result = shell.run_cell(source, store_history=False)
            if not result.success:
                error = result.error_in_exec or result.error_before_exec
                raise AssertionError(f"{name}: code cell {i + 1} failed: {error!r}\n{source}") from error
            if result.result is not None:              # the cell's value, shown as its result
                outputs.append(shell.display_formatter.format(result.result)[0])
    return ExecutedNotebook(text.getvalue(), outputs)


@pytest.fixture
def execute_notebook():
    """``execute_notebook(name, workdir, parameters=None) -> ExecutedNotebook``: run every code cell of
    ``notebooks/<name>`` top to bottom in ``workdir``; the text of all its outputs and their MIME bundles
    (figures shown inline: ``.images``). ``parameters`` ``{NAME: value}`` replace the notebook's
    ``NAME = ...  # parameter`` lines."""
    return _execute_notebook



# ---------------------------------------------------------------------------- test order
def _uses_shared_costly_fixture(item: pytest.Item) -> bool:
    """The test uses a fixture that the module defining it (a test file or a folder's conftest.py)
    lists in its ``SHARED_COSTLY_FIXTURES``: a session fixture that takes seconds and serves several tests."""
    info = getattr(item, "_fixtureinfo", None)
    for name, definitions in (info.name2fixturedefs.items() if info is not None else ()):
        module = sys.modules.get(getattr(definitions[-1].func, "__module__", ""))
        if name in getattr(module, "SHARED_COSTLY_FIXTURES", ()):
            return True
    return False


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The tests of the shared costly fixtures first, file by file: pytest-xdist's ``worksteal`` hands the
    first half of the list to one worker and an idle worker takes tests from the END of the other's queue,
    so these stay on one worker and each fixture is built once per ``make test`` instead of once per worker."""
    items.sort(key=lambda item: not _uses_shared_costly_fixture(item))


# ---------------------------------------------------------------------------- property tests
#: generated inputs per reader of the property tests in this process (tests/reliability/test_fuzz_*.py)
FUZZ_INPUTS: collections.Counter[str] = collections.Counter()


@pytest.fixture(scope="session")
def fuzz_inputs() -> collections.Counter[str]:
    """``fuzz_inputs[reader] += 1`` per generated input of a property test; printed after the run."""
    return FUZZ_INPUTS


def pytest_sessionfinish(session: pytest.Session) -> None:
    if FUZZ_INPUTS and hasattr(session.config, "workeroutput"):     # a pytest-xdist worker: to the controller
        session.config.workeroutput["fuzz_inputs"] = dict(FUZZ_INPUTS)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node: Any, error: object) -> None:
    """The controller of pytest-xdist adds up the counts of its workers."""
    FUZZ_INPUTS.update(getattr(node, "workeroutput", {}).get("fuzz_inputs") or {})


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int, config: pytest.Config) -> None:
    if FUZZ_INPUTS:
        terminalreporter.write_sep("-", "property-test inputs per reader")
        for reader, count in sorted(FUZZ_INPUTS.items()):
            terminalreporter.write_line(f"{reader}: {count}")
