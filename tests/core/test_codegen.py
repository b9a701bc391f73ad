"""Compiled CasADi code: several functions compiled side by side into one library."""

from __future__ import annotations

import fcntl
import threading
import time

import casadi as ca
import numpy as np
import pytest

from pipeline.core import codegen, progress


def _functions() -> list[ca.Function]:
    x = ca.SX.sym("x", 3)
    return [ca.Function("side_a", [x], [ca.sin(x) * 2.0]),
            ca.Function("side_b", [x], [ca.dot(x, x)]),
            ca.Function("side_c", [x], [ca.jacobian(ca.exp(x) * x[0], x)])]


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_functions_compiled_side_by_side_evaluate_like_casadi(tmp_path, monkeypatch, jobs):
    monkeypatch.setenv("PIPELINE_JOBS", jobs)
    library = codegen.build_library("side", _functions(), cache_dir=tmp_path)
    x = np.array([0.3, -1.2, 2.0])
    for f in _functions():
        compiled = ca.external(f.name(), str(library))
        np.testing.assert_allclose(np.asarray(compiled(x)), np.asarray(f(x)), rtol=1e-14, atol=0)


def test_library_key_does_not_depend_on_the_cores(tmp_path, monkeypatch):
    monkeypatch.setenv("PIPELINE_JOBS", "2")
    first = codegen.build_library("side", _functions(), cache_dir=tmp_path)
    stamp = first.stat().st_mtime_ns
    monkeypatch.setenv("PIPELINE_JOBS", "1")
    again = codegen.build_library("side", _functions(), cache_dir=tmp_path)
    assert again == first and again.stat().st_mtime_ns == stamp     # found in the cache, not rebuilt


def test_gcc_failure_names_the_library(tmp_path, monkeypatch):
    monkeypatch.setenv("PIPELINE_JOBS", "2")
    with pytest.raises(codegen.SolverError, match="gcc failed"):
        codegen.build_library("side", _functions(), cache_dir=tmp_path, flags=("-fno-such-flag-anywhere",))
    assert not list(tmp_path.rglob("*.so"))


def _opened_tasks(monkeypatch) -> list[str]:
    """Descriptions of the progress tasks opened from now on (on any :class:`Progress`)."""
    opened: list[str] = []
    task = progress.Progress.task

    def recording(self, description, total=None):
        opened.append(description)
        return task(self, description, total)

    monkeypatch.setattr(progress.Progress, "task", recording)
    return opened


def test_a_build_shows_a_compiling_line_and_a_cached_library_none(tmp_path, monkeypatch):
    opened = _opened_tasks(monkeypatch)
    x = ca.SX.sym("x")
    f = ca.Function("progress_probe", [x], [x * x])
    codegen.build_library("progress_probe", [f], cache_dir=tmp_path)
    assert [d for d in opened if d.startswith("compiling progress_probe")] == opened and len(opened) == 1
    opened.clear()
    codegen.build_library("progress_probe", [f], cache_dir=tmp_path)      # in the cache: nothing built
    assert opened == []


def test_waiting_for_another_process_build_shows_a_line(tmp_path, monkeypatch):
    """The library's lock held elsewhere (as by the run's background warm-up): the build waits for it
    under a progress line saying so, then compiles (the holder left no library)."""
    opened = _opened_tasks(monkeypatch)
    x = ca.SX.sym("x")
    f = ca.Function("lock_probe", [x], [x + 1.0])
    library, _ = codegen._library_path("lock_probe", [f], "casadi", codegen.DEFAULT_FLAGS, None, tmp_path)
    with open(library.with_name(f".{library.name}.lock"), "a") as holder:
        fcntl.flock(holder, fcntl.LOCK_EX)
        builder = threading.Thread(target=codegen.build_library, args=("lock_probe", [f]),
                                   kwargs={"cache_dir": tmp_path})
        builder.start()
        deadline = time.monotonic() + 30.0
        while not opened and time.monotonic() < deadline:
            time.sleep(0.01)
        assert opened and "waiting" in opened[0] and not library.exists()
        fcntl.flock(holder, fcntl.LOCK_UN)
    builder.join(30.0)
    assert library.is_file() and [d.startswith("compiling lock_probe") for d in opened] == [True, True]
