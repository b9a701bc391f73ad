"""The reused candidate grid is the filter's result bit for bit, keyed by content only."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.calibration import candidates as cd
from pipeline.calibration import grid_cache
from pipeline.robot.model import RobotModel

PER_AXIS = 4
MARGINS = cd.FilterMargins(0.01, np.radians(3.0), 0.02)


@pytest.fixture(scope="session")
def chain(rx130l):
    return cd.chain_from_robot(rx130l)


@pytest.fixture(scope="session")
def fresh(chain):
    return cd.filter_grid(chain, PER_AXIS, MARGINS)


def _assert_same(result, fresh):
    Q, index, counts = result
    assert Q.dtype == fresh[0].dtype and Q.tobytes() == fresh[0].tobytes()
    assert index.dtype == fresh[1].dtype and np.array_equal(index, fresh[1])
    assert {k: v for k, v in counts.items() if k != "time_s"} == {k: v for k, v in fresh[2].items() if k != "time_s"}


def test_memory_and_disk_reuse_give_the_filter_result(chain, fresh, tmp_path, monkeypatch):
    monkeypatch.setattr(grid_cache, "_MEMORY", type(grid_cache._MEMORY)())
    first = grid_cache.filter_grid(chain, PER_AXIS, MARGINS, cache_dir=tmp_path)
    _assert_same(first, fresh)
    first[0][:] = np.nan                       # the caller's copy: the kept grid is not touched
    _assert_same(grid_cache.filter_grid(chain, PER_AXIS, MARGINS, cache_dir=tmp_path), fresh)
    grid_cache._MEMORY.clear()                 # another process: from the file
    assert len(list((tmp_path / "grids").glob("*.npz"))) == 1
    _assert_same(grid_cache.filter_grid(chain, PER_AXIS, MARGINS, cache_dir=tmp_path), fresh)


def test_damaged_file_is_computed_again(chain, fresh, tmp_path, monkeypatch):
    monkeypatch.setattr(grid_cache, "_MEMORY", type(grid_cache._MEMORY)())
    grid_cache.filter_grid(chain, PER_AXIS, MARGINS, cache_dir=tmp_path)
    (path,) = (tmp_path / "grids").glob("*.npz")
    path.write_bytes(path.read_bytes()[:100])
    grid_cache._MEMORY.clear()
    _assert_same(grid_cache.filter_grid(chain, PER_AXIS, MARGINS, cache_dir=tmp_path), fresh)


def test_key_follows_every_input_and_no_path(chain):
    key = grid_cache.grid_key(chain, PER_AXIS, MARGINS, 20_000)
    assert key == grid_cache.grid_key(dataclasses.replace(chain), PER_AXIS, MARGINS, 20_000)
    moved = dataclasses.replace(chain, tracker_t=chain.tracker_t + np.array([0.0, 0.0, 1e-9]))
    others = [
        grid_cache.grid_key(moved, PER_AXIS, MARGINS, 20_000),
        grid_cache.grid_key(chain, PER_AXIS + 1, MARGINS, 20_000),
        grid_cache.grid_key(chain, PER_AXIS, dataclasses.replace(MARGINS, beam_m=0.03), 20_000),
        grid_cache.grid_key(chain, PER_AXIS, MARGINS, 10_000),
    ]
    assert len({key, *others}) == 5


def test_chunks_filtered_side_by_side_give_the_serial_result(chain, fresh, monkeypatch):
    monkeypatch.setenv("PIPELINE_JOBS", "1")
    serial = cd.filter_grid(chain, 5, MARGINS, chunk=64)
    monkeypatch.setenv("PIPELINE_JOBS", "2")
    _assert_same(cd.filter_grid(chain, 5, MARGINS, chunk=64), serial)


@pytest.mark.parametrize("name", ["rx130l", "staubli_tx40"])
def test_coarse_first_grid_is_the_whole_grid_filtered_row_by_row(name):
    """Prefix frames computed once and expanded along the last axis: the configurations, in grid
    order, that the plain batched filter accepts from the whole grid, bit for bit."""
    chain = cd.chain_from_robot(RobotModel.load(name))
    Q, index, counts = cd.filter_grid(chain, 5, MARGINS, chunk=50)
    axes = np.meshgrid(*cd.grid_values(chain, 5), indexing="ij")
    grid = np.stack([a.ravel() for a in axes], axis=1)
    mask, plain = cd.filter_configurations(chain, grid, MARGINS)
    assert Q.tobytes() == grid[mask].tobytes() and np.array_equal(index, np.flatnonzero(mask))
    assert counts["feasible"] == plain["feasible"] > 0
