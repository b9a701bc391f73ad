"""Independent tasks on forked workers: same results, in order, as running them here."""

from __future__ import annotations

import os
import pickle
import threading

import numpy as np
import pytest

from pipeline.core.errors import InfeasibleError, QualityGateError
from pipeline.core.forks import available_cores, fork_map, in_background


def _task_with_unpicklable_state():
    lock = threading.Lock()                          # cannot be pickled: a child must inherit it
    rng_seeds = [11, 12, 13, 14, 15]

    def task(k: int) -> tuple[int, float]:
        with lock:
            return os.getpid(), float(np.random.default_rng(rng_seeds[k]).normal())
    return task, lock


def test_state_that_cannot_be_pickled_reaches_the_workers():
    task, lock = _task_with_unpicklable_state()
    with pytest.raises(TypeError):
        pickle.dumps(lock)
    forked = list(fork_map(task, 5, jobs=2))
    here = [task(k) for k in range(5)]
    assert [value for _, value in forked] == [value for _, value in here]


@pytest.mark.skipif(available_cores() < 2, reason="one core: the tasks run in this process")
def test_tasks_run_in_child_processes_with_two_jobs():
    task, _ = _task_with_unpicklable_state()
    pids = {pid for pid, _ in fork_map(task, 4, jobs=2)}
    assert os.getpid() not in pids


def test_one_job_runs_here():
    task, _ = _task_with_unpicklable_state()
    assert {pid for pid, _ in fork_map(task, 3, jobs=1)} == {os.getpid()}


def test_an_error_in_a_task_reaches_the_caller():
    def task(k: int) -> int:
        if k == 2:
            raise ValueError("task 2 failed")
        return k
    with pytest.raises(ValueError, match="task 2 failed"):
        list(fork_map(task, 4, jobs=2))


def test_pipeline_errors_cross_a_process_boundary_as_themselves():
    errors = (InfeasibleError("robot.yaml", "limits", "too tight"), QualityGateError(None, "gate", "failed", {"a": 1}))
    for error in errors:
        copy = pickle.loads(pickle.dumps(error))
        assert type(copy) is type(error) and str(copy) == str(error)
        assert (copy.file, copy.field, copy.problem) == (error.file, error.field, error.problem)
    assert pickle.loads(pickle.dumps(QualityGateError(None, "gate", "failed", {"a": 1}))).result == {"a": 1}


@pytest.mark.skipif(available_cores() < 2, reason="one core: the task runs in this process")
def test_background_task_runs_in_a_child_beside_this_process():
    lock = threading.Lock()                          # inherited, not pickled

    def task() -> tuple[int, float]:
        with lock:
            return os.getpid(), float(np.random.default_rng(7).normal())
    with in_background(task) as result:
        here = float(np.random.default_rng(7).normal())
        pid, value = result()
    assert pid != os.getpid() and value == here


def test_background_error_reaches_the_caller_with_its_fields():
    def task() -> int:
        raise InfeasibleError(None, "ptp duration joint 2", "below the bound")
    with pytest.raises(InfeasibleError, match="below the bound") as caught, in_background(task) as result:
        result()
    assert caught.value.field == "ptp duration joint 2"


def test_background_task_runs_here_with_one_job(monkeypatch):
    monkeypatch.setenv("PIPELINE_JOBS", "1")
    with in_background(os.getpid) as result:
        assert result() == os.getpid()
