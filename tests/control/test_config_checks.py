"""Bad values of the ``control`` section are ConfigErrors naming the dotted field (and the file or
``--set``) at load time or in ``stage.check`` before anything runs; good configs still pass."""

from __future__ import annotations

import dataclasses

import pytest

from pipeline.control import stage
from pipeline.control.config import ControlConfig
from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.core.errors import ConfigError
from pipeline.robot import iso9283
from pipeline.robot.iso9283 import ISO_PLANES, ISO_SEGMENTS, IsoPathConfig

BAD = [
    # (dotted key, bad value, field named by the error)
    ("control.sample_time_s", 0.0, "control.sample_time_s"),
    ("control.sample_time_s", -4e-4, "control.sample_time_s"),
    ("control.sample_time_s", float("nan"), "control.sample_time_s"),
    ("control.velocity_samples_per_position_sample", 0, "control.velocity_samples_per_position_sample"),
    ("control.setpoint_delay_samples", -1, "control.setpoint_delay_samples"),
    ("control.measurement_delay_samples", -1, "control.measurement_delay_samples"),
    ("control.position_bandwidth_hz", 0.0, "control.position_bandwidth_hz"),
    ("control.position_bandwidth_hz", 40.0, "control.position_bandwidth_hz"),     # not below the velocity loop
    ("control.velocity_bandwidth_hz", -30.0, "control.velocity_bandwidth_hz"),
    ("control.velocity_bandwidth_hz", 3000.0, "control.velocity_bandwidth_hz"),   # above Nyquist (2500 Hz)
    ("control.velocity_filter_hz", 0.0, "control.velocity_filter_hz"),
    ("control.velocity_filter_hz", float("inf"), "control.velocity_filter_hz"),
    ("control.pi_zero_ratio", 0.0, "control.pi_zero_ratio"),
    ("control.settle_time_s", -1.0, "control.settle_time_s"),
    ("control.engine", "fortran", "control.engine"),
    ("control.chunk_samples", 0, "control.chunk_samples"),
    ("control.on_saturation", "ignore", "control.on_saturation"),
    ("control.saturation_ratio", 0.0, "control.saturation_ratio"),
    ("control.variants", [], "control.variants"),
    ("control.variants", ["magic"], "control.variants[0]"),
    ("control.variants", ["none", "full_friction", "none"], "control.variants"),
    ("control.ik_tolerance_m", 0.0, "control.ik_tolerance_m"),
    ("control.ik_tolerance_m", 0.01, "control.ik_tolerance_m"),
    ("control.ik_seeds_deg", [], "control.ik_seeds_deg"),
    ("control.ik_seeds_deg", [[]], "control.ik_seeds_deg[0]"),
    ("control.ik_seeds_deg", [[0, 17, 86, 0, 75, 0], [0, float("nan"), 0, 0, 0, 0]], "control.ik_seeds_deg[1][1]"),
    ("control.path_frame", "flange", "control.path_frame"),
    ("control.benchmark_python_seconds", -0.5, "control.benchmark_python_seconds"),
    ("control.iso.edge_m", 0.0, "control.iso.edge_m"),
    ("control.iso.centre_m", [0.9, 0.0], "control.iso.centre_m"),
    ("control.iso.centre_m", [0.9, 0.0, float("nan")], "control.iso.centre_m[2]"),
    ("control.iso.plane", "vertical", "control.iso.plane"),
    ("control.iso.speed_m_s", 0.0, "control.iso.speed_m_s"),
    ("control.iso.acceleration_m_s2", -5.0, "control.iso.acceleration_m_s2"),
    ("control.iso.jerk_m_s3", 0.0, "control.iso.jerk_m_s3"),
    ("control.iso.corner_fraction", 0.5, "control.iso.corner_fraction"),
    ("control.iso.corner_fraction", 0.0, "control.iso.corner_fraction"),
    ("control.iso.large_circle_fraction", 2.0, "control.iso.large_circle_fraction"),
    ("control.iso.large_circle_fraction", 0.0, "control.iso.large_circle_fraction"),
    ("control.iso.small_circle_fraction", 1.5, "control.iso.small_circle_fraction"),
    ("control.iso.small_circle_fraction", -0.1, "control.iso.small_circle_fraction"),
    ("control.iso.segments", [], "control.iso.segments"),
    ("control.iso.segments", ["line", "zigzag"], "control.iso.segments[1]"),
    ("control.iso.segments", ["line", "line"], "control.iso.segments"),
]


@pytest.mark.parametrize(("key", "value", "field_name"), BAD, ids=[f"{k}={v!r}" for k, v, _ in BAD])
def test_bad_value_is_a_config_error_naming_the_field(key, value, field_name):
    with pytest.raises(ConfigError) as err:
        load_config(CONFIGS_DIR / "quick.yaml", values={key: value})
    assert err.value.field == field_name
    assert err.value.file == "--set"


def test_good_configs_pass(rx130l, shipped_configs):
    for cfg, robot in shipped_configs:
        stage.check(cfg.control, robot)
    # allowed edge values
    ok = load_config(values={"control.settle_time_s": 0.0, "control.benchmark_python_seconds": 0.0,
                             "control.variants": ["none"],
                             "control.iso.large_circle_fraction": 1.0, "control.iso.segments": ["circle_small"],
                             "control.setpoint_delay_samples": 0, "control.measurement_delay_samples": 0})
    stage.check(ok.control, rx130l)


@pytest.mark.parametrize("seeds", [[[0.0, 17.0, 86.0]], [[0.0] * 6, [0.0] * 7]])
def test_ik_seed_length_is_checked_against_the_robot(rx130l, seeds):
    cfg = load_config(values={"control.ik_seeds_deg": seeds}).control      # robot-independent: accepted
    with pytest.raises(ConfigError, match="6 joint angles") as err:
        stage.check(cfg, rx130l)
    assert err.value.field == f"control.ik_seeds_deg[{len(seeds) - 1}]"


def test_check_also_validates_configs_changed_in_python(rx130l):
    cfg = load_config().control
    cfg.chunk_samples = 0
    with pytest.raises(ConfigError) as err:
        stage.check(cfg, rx130l)
    assert err.value.field == "control.chunk_samples"


def test_direct_construction_is_checked():
    with pytest.raises(ConfigError) as err:
        ControlConfig(settle_time_s=-1.0)
    assert err.value.field == "control.settle_time_s"
    with pytest.raises(ConfigError) as err:
        ControlConfig(iso={"large_circle_fraction": 2.0})
    assert err.value.field == "control.iso.large_circle_fraction"
    with pytest.raises(ConfigError):
        dataclasses.replace(IsoPathConfig(), small_circle_fraction=0.0)


def test_allowed_sets_match_the_path_builder():
    assert set(ISO_PLANES) == set(iso9283.PLANES)
    # the builder knows every segment the config allows
    path = iso9283.iso9283_path(None, 0.2, (0.9, 0.0, 0.5), segments=ISO_SEGMENTS)
    assert {p.label for p in path.pieces} >= {"line P2-P4", "rectangle", "circle_large", "circle_small"}
