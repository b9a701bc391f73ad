"""Background warm-up of the stages' compiled code (pipeline/run/warm_up.py) and the build lock that keeps a
stage from compiling a library the warm-up is building (pipeline/core/codegen.py)."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import casadi as ca

from pipeline.core import codegen
from pipeline.core.config import load_config
from pipeline.run import runner as runner_module
from pipeline.run import stages as stage_registry
from pipeline.run.runner import run_pipeline
from pipeline.run.warm_up import warmed_up


def _wait_for(path: Path, timeout_s: float = 20.0) -> bool:
    t0 = time.monotonic()
    while not path.exists() and time.monotonic() - t0 < timeout_s:
        time.sleep(0.02)
    return path.exists()


def test_tasks_run_in_turn_in_another_process_and_a_failure_does_not_stop_the_next(tmp_path):
    marker = tmp_path / "pid.txt"

    def fails() -> None:
        raise RuntimeError("a build that fails is the stage's to report")

    def writes() -> None:        # renamed into place: the marker never exists empty
        partial = marker.with_name("pid.partial")
        partial.write_text(str(os.getpid()))
        os.replace(partial, marker)

    with warmed_up([("a", fails), ("b", writes)]) as process:
        assert process is not None and _wait_for(marker)
    assert int(marker.read_text()) != os.getpid()
    assert not process.is_alive()


def test_the_process_is_stopped_when_the_run_ends():
    with warmed_up([("slow", lambda: time.sleep(60.0))]) as process:
        assert process is not None and process.is_alive()
    assert not process.is_alive()
    with warmed_up([]) as nothing:
        assert nothing is None


def test_a_library_being_built_elsewhere_is_waited_for_not_built_twice(tmp_path, monkeypatch):
    """While the lock is held (another process compiling), a second builder blocks; when the library
    appears it loads it without compiling."""
    x = ca.SX.sym("x")
    functions = [ca.Function("square", [x], [x * x])]
    library, _ = codegen._library_path("square", functions, "casadi", codegen.DEFAULT_FLAGS, None, tmp_path)
    compiled: list[str] = []
    monkeypatch.setattr(codegen, "_build", lambda sources, name, *args: compiled.append(name))
    result: list[Path] = []
    with codegen._build_lock(library):
        waiter = threading.Thread(target=lambda: result.append(
            codegen.build_library("square", functions, cache_dir=tmp_path)))
        waiter.start()
        waiter.join(0.5)
        assert waiter.is_alive() and not result          # blocked on the lock
        library.write_bytes(b"built by the other process")
        library.with_name(library.name + ".sha256").write_text(codegen._sha256(library) + "\n")
    waiter.join(10.0)
    assert result == [library] and compiled == []


def test_runner_warms_up_only_the_stages_that_will_run(fake_stages, tmp_path, monkeypatch):
    started: list[list[str]] = []
    real = runner_module.warmed_up

    def recording(tasks):
        started.append([name for name, _ in tasks])
        return real([])

    monkeypatch.setattr(runner_module, "warmed_up", recording)
    for name in ("b", "c"):         # stage a has no warm-up
        monkeypatch.setattr(stage_registry.STAGES[name], "warm_up", lambda config, robot: None, raising=False)
    quiet = {"out_root": tmp_path, "log": lambda m: None, "warm_up": True}
    run_pipeline(load_config(None, ["name=r"]), **quiet)
    run_pipeline(load_config(None, ["name=r", "c.n=4"]), **quiet)
    assert started == [["b", "c"], ["c"]]      # the second run reuses a and b
