"""Independent tasks on forked workers: same results, in order, as running them here."""

from __future__ import annotations

import os
import pickle
import threading

import numpy as np
import pytest

from pipeline.forks import available_cores, fork_map


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
