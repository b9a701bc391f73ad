"""Sweeps: grid parsing, table flattening, and the same table from joblib and a Dask LocalCluster."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pytest

from pipeline import cli
from pipeline.core.config import REPO_ROOT
from pipeline.core.errors import ConfigError
from pipeline.run.sweep import SweepSpec, grid, parse_seeds, parse_vary, run_sweep
from pipeline.run.sweep_table import flatten_summary, is_timing_column, spread

QUICK = str(REPO_ROOT / "configs" / "quick.yaml")
#: a calibration small enough for a few seconds per run
# small designs on the rigid robot: the sweep machinery is under test here, not the elastostatic model
TINY = ["calibration.n_random_candidates=100", "calibration.n_configurations=20", "calibration.n_heldout=30",
        "truth.joint_compliance_scale=0", "truth.transmission_error_amplitude_rad=0",
        "calibration.second_pass=never",   # one pass: the sweep machinery is under test, not the second pass
        "calibration.figures=false", "model.views_deg=[[25, -60]]", "model.picture_size_in=2",
        "calibration.design_table=false"]  # the stage's design table: tests/calibration/test_calibration.py


def test_parse_seeds_ranges_lists_and_errors() -> None:
    assert parse_seeds("0-3,10,2") == [0, 1, 2, 3, 10]
    assert parse_seeds("7") == [7]
    for bad in ("3-1", "a", "", "1,,2", "-4"):
        with pytest.raises(ConfigError):
            parse_seeds(bad)


def test_parse_vary_lists_and_scalars() -> None:
    assert parse_vary(["calibration.n_configurations=[20, 40]", "seedless=3"]) == {
        "calibration.n_configurations": [20, 40], "seedless": [3]}
    with pytest.raises(ConfigError):
        parse_vary(["a=[]"])


def test_flatten_summary_keeps_scalars_short_numeric_lists_and_nested_dicts() -> None:
    row: dict = {}
    flatten_summary("s", {"a": 1.5, "b": {"c": "x", "d": None}, "e": [1, 2], "names": ["j1", "j2"],
                          "long": list(range(50)), "flag": True}, row)
    assert row == {"s.a": 1.5, "s.b.c": "x", "s.b.d": None, "s.e[0]": 1.0, "s.e[1]": 2.0, "s.flag": True}
    assert is_timing_column("calibration.timings_s.measure_s")
    assert is_timing_column("calibration.stage_time_s")
    assert not is_timing_column("calibration.heldout_rms_position_error_after_m")


def test_spread_median_and_95th_percentile_bound_the_values() -> None:
    values = np.random.default_rng(0).lognormal(size=200)
    s = spread(values)
    assert values.min() <= s["median"] <= s["p95"] <= s["max"] == values.max()
    assert np.mean(values <= s["p95"]) >= 0.95
    assert np.isnan(spread(np.zeros(0))["median"])


def test_grid_is_validated_before_anything_is_written(tmp_path: Path) -> None:
    spec = SweepSpec(seeds=[0, 1], robots=["rx130l", "staubli_tx40"], out_dir=tmp_path / "s", config_path=QUICK,
                     overrides=list(TINY), vary={"calibration.n_configurations": [20, 30]}, stages="calibration")
    points = grid(spec)
    assert len(points) == 8 and len({p.name for p in points}) == 8
    assert {p.robot for p in points} == {"rx130l", "staubli_tx40"}
    assert sorted({p.varied for p in points}) == [(("calibration.n_configurations", 20),),
                                                  (("calibration.n_configurations", 30),)]
    bad = SweepSpec(seeds=[0], robots=["rx130l"], out_dir=tmp_path / "bad", config_path=QUICK,
                    overrides=["calibration.n_configurations=oops"], stages="calibration")
    with pytest.raises(ConfigError):
        run_sweep(bad)
    assert not (tmp_path / "bad").exists()


def _table(path: Path) -> list[dict[str, str]]:
    """The sweep table without timings, and with the output folder left out of file paths (the second
    calibration pass's gravity model lives under each sweep's own runs folder)."""
    rows = list(csv.DictReader(io.StringIO(path.read_text())))
    root = str(path.parent)
    return [{k: v.replace(root, "<out>") for k, v in r.items() if not is_timing_column(k)} for r in rows]


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory) -> tuple[Path, list[dict]]:
    """``sweep`` through the CLI over two seeds, run in this process."""
    out = tmp_path_factory.mktemp("sweep") / "local"
    args = ["sweep", "--config", QUICK, "--seeds", "0-1", "--stages", "calibration", "--out", str(out)]
    for item in TINY:
        args += ["--set", item]
    assert cli.main(args) == 0
    return out, _table(out / "sweep.csv")


def test_local_sweep_writes_one_row_per_seed(local_sweep) -> None:
    out, local = local_sweep
    assert [r["seed"] for r in local] == ["0", "1"] and all(r["status"] == "ok" for r in local)
    figure = "calibration.heldout_rms_position_error_after_m"
    assert len({r[figure] for r in local}) == 2          # two hidden robots, two results
    assert (out / "sweep.png").stat().st_size > 0
    assert figure in (out / "sweep.md").read_text()


@pytest.mark.slow
def test_local_and_dask_sweeps_give_the_same_table(local_sweep, tmp_path: Path) -> None:
    distributed = pytest.importorskip("distributed")
    _, local = local_sweep
    spec = SweepSpec(seeds=[0, 1], robots=[None], out_dir=tmp_path / "dask", config_path=QUICK,
                     overrides=list(TINY), stages="calibration")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        rows, paths = run_sweep(spec, scheduler=client)
    assert (tmp_path / "dask" / "runs" / "rx130l-seed0" / "calibration" / "summary.json").exists()
    assert _table(paths["csv"]) == local
    assert [r["run"] for r in rows] == [r["run"] for r in local]
