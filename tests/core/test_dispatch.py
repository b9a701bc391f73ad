"""Task dispatch (pipeline/core/dispatch.py): results in input order whatever order the tasks finish in."""

from __future__ import annotations

import time

import pytest

from pipeline.core.dispatch import map_tasks
from pipeline.core.errors import ConfigError


def _slow_square(x: int) -> int:
    time.sleep(0.05 * (3 - x))     # the first items finish last
    return x * x


def test_map_tasks_keeps_input_order_locally_and_on_workers() -> None:
    items = [0, 1, 2, 3]
    expected = [x * x for x in items]
    assert map_tasks(_slow_square, items) == expected
    assert map_tasks(_slow_square, items, jobs=2) == expected
    assert map_tasks(_slow_square, []) == []


def test_map_tasks_rejects_a_worker_count_below_one() -> None:
    with pytest.raises(ConfigError):
        map_tasks(_slow_square, [1], jobs=0)
