"""Run configuration: defaults, YAML, --set, validation messages naming file and field."""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Literal

import pytest

from pipeline.core import config
from pipeline.core.config import RunConfig, load_config, parse_set
from pipeline.core.errors import ConfigError
from pipeline.core.typed_config import check_choices
from pipeline.robot.iso9283 import IsoPathConfig
from pipeline.run import stages as stage_registry


def write(tmp_path, text: str, name: str = "run.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_defaults_follow_registry(fake_stages):
    cfg = load_config()
    assert cfg.stages == ["a", "b", "c"]
    assert cfg.a.n == 3 and cfg.section("b").gain == 1.0
    assert isinstance(cfg, RunConfig) and cfg.seed == 0


def test_yaml_then_set_overrides(fake_stages, tmp_path):
    p = write(tmp_path, "name: r1\nseed: 4\na: {n: 7, label: hello}\nb: {gain: 2}\n")
    cfg = load_config(p, ["a.n=9", "b.label=world", "seed=5"])
    assert (cfg.name, cfg.seed) == ("r1", 5)
    assert cfg.a.n == 9 and cfg.a.label == "hello"       # untouched key kept from the file
    assert cfg.b.gain == 2.0 and isinstance(cfg.b.gain, float)   # int accepted for float
    assert cfg.b.label == "world"
    assert cfg.c.n == 3                                   # defaults elsewhere


def test_set_values_are_yaml(fake_stages):
    assert parse_set("a.n=40") == (["a", "n"], 40)
    assert parse_set("x=[1, 2.5]") == (["x"], [1, 2.5])
    assert parse_set("x=true") == (["x"], True)
    assert parse_set("x=abc") == (["x"], "abc")
    assert parse_set("x=") == (["x"], "")
    with pytest.raises(ConfigError, match="--set"):
        parse_set("novalue")


def test_stages_key_and_argument(fake_stages, tmp_path):
    assert load_config(stages="c,a").stages == ["a", "c"]        # registry order
    assert load_config(write(tmp_path, "stages: [b]\n")).stages == ["b"]


@pytest.mark.parametrize(
    ("text", "field_name", "problem"),
    [
        ("bogus: 1\n", "bogus", "unknown key"),
        ("a: {bogus: 1}\n", "a.bogus", "unknown key"),
        ("stages: [a, nope]\n", "stages", "unknown stage 'nope'"),
        ("a: {n: abc}\n", "a.n", "expected int"),
        ("a: {n: 1.5}\n", "a.n", "expected int"),
        ("a: {n: true}\n", "a.n", "expected int"),
        ("a: {fail: 1}\n", "a.fail", "expected true/false"),
        ("a: [1, 2]\n", "a", "expected a mapping"),
        ("seed: -1\n", "seed", "non-negative"),
        ("profile: slow\n", "profile", "expected one of"),
        ("name: ../x\n", "name", "plain directory name"),
        ("- just\n- a list\n", None, "top level must be a mapping"),
        ("a: {n: [1\n", "line", "invalid YAML"),
    ],
)
def test_file_errors_name_file_and_field(fake_stages, tmp_path, text, field_name, problem):
    p = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_config(p)
    msg = str(info.value)
    assert msg.startswith(str(p) + ": ")
    if field_name:
        assert f": {field_name}" in msg
    assert problem in msg
    assert "\n" not in msg


def test_set_errors_name_set_and_field(fake_stages, tmp_path):
    p = write(tmp_path, "a: {n: 2}\n")
    with pytest.raises(ConfigError, match=r"^--set: a\.n: expected int"):
        load_config(p, ["a.n=two"])
    with pytest.raises(ConfigError, match=r"^--set: zz: unknown key"):
        load_config(p, ["zz=1"])
    with pytest.raises(ConfigError, match=r"^--stages: stages: unknown stage"):
        load_config(p, stages="a,zz")


def test_missing_config_file(tmp_path):
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(tmp_path / "nope.yaml")


@dataclass
class Inner:
    width_m: float = 0.1
    names: tuple[str, ...] = ("x",)


@dataclass
class Rich:
    inner: Inner = field(default_factory=Inner)
    pair: tuple[float, float] = (0.0, 1.0)
    maybe: int | None = None
    weights: dict[str, float] = field(default_factory=dict)
    mode: str = "a"


def test_nested_dataclasses_and_containers(monkeypatch):
    stage = SimpleNamespace(NAME="r", DEPENDS=(), Config=Rich, run=None)
    monkeypatch.setattr(stage_registry, "STAGES", {"r": stage})
    monkeypatch.setattr(config, "robot_run_defaults", lambda cfg: None)   # rx130l's name the real sections
    cfg = load_config(None, ["r.inner.width_m=2", "r.pair=[3, 4]", "r.maybe=5", "r.weights={a: 1}"])
    assert cfg.r.inner == Inner(width_m=2.0, names=("x",))
    assert cfg.r.pair == (3.0, 4.0) and cfg.r.maybe == 5 and cfg.r.weights == {"a": 1.0}
    with pytest.raises(ConfigError, match=r"r\.inner\.bogus: unknown key"):
        load_config(None, ["r.inner.bogus=1"])
    with pytest.raises(ConfigError, match=r"r\.pair: expected a list of 2 items"):
        load_config(None, ["r.pair=[1, 2, 3]"])
    with pytest.raises(ConfigError, match=r"r\.inner\.names\[1\]: expected string"):
        load_config(None, ["r.inner.names=[a, 3]"])


def test_round_trip_through_yaml(fake_stages, tmp_path):
    cfg = load_config(None, ["a.n=11", "name=rt", "b.label=z"])
    p = write(tmp_path, cfg.to_yaml())
    again = load_config(p)
    assert again.to_dict() == cfg.to_dict()


def test_missing_stage_module_is_reported(monkeypatch, tmp_path):
    monkeypatch.setattr(stage_registry, "STAGES", {"ghost": "pipeline.ghost_stage_that_does_not_exist.stage"})
    monkeypatch.setattr(config, "robot_run_defaults", lambda cfg: None)   # rx130l's name the real sections
    load_config()                              # empty section: fine, nothing to check
    with pytest.raises(ConfigError, match=r"ghost: cannot check these settings: .*does not exist"):
        load_config(write(tmp_path, "ghost: {n: 1}\n"))
    with pytest.raises(config.StageUnavailableError, match="stage 'ghost' is not available"):
        stage_registry.load_stage_module("ghost")


def test_quick_profile_loads(quick_config):
    assert quick_config.profile == "quick"
    assert quick_config.stages == [s for s in stage_registry.STAGES if s in quick_config.stages]
    assert set(quick_config.sections) >= {"truth", *stage_registry.STAGES}


# ---------------------------------------------------------------- robot run_defaults layer
def test_robot_run_defaults_sit_between_defaults_and_file(tmp_path):
    builtin = IsoPathConfig().centre_m
    tx40 = load_config(values={"robot": "staubli_tx40"})
    assert tx40.control.iso.centre_m == [0.35, 0.0, 0.2] != builtin
    assert tx40.trajectory.cp_edge_m == 0.2
    assert tx40.control.iso.segments == IsoPathConfig().segments        # untouched fields keep theirs
    # the run config file and --set still win; another robot keeps the built-in defaults
    p = write(tmp_path, "robot: staubli_tx40\ncontrol: {iso: {edge_m: 0.25}}\n")
    cfg = load_config(p, ["trajectory.cp_edge_m=0.15"])
    assert cfg.control.iso.edge_m == 0.25 and cfg.control.iso.centre_m == [0.35, 0.0, 0.2]
    assert cfg.trajectory.cp_edge_m == 0.15
    assert builtin is None and load_config().control.iso.centre_m == [1.0, 0.0, 0.6]   # rx130l run_defaults


@pytest.mark.parametrize("block, field_name", [("run_defaults:\n  nonsense: {a: 1}\n", "run_defaults.nonsense"),
                                                ("run_defaults:\n  control: 3\n", "run_defaults.control"),
                                                ("run_defaults:\n  control: {iso: {edge_m: abc}}\n",
                                                 "control.iso.edge_m")])
def test_bad_robot_run_defaults_name_robot_yaml(tmp_path, block, field_name):
    robot = tmp_path / "myrobot"
    shutil.copytree(config.REPO_ROOT / "robots" / "staubli_tx40", robot)
    text = (robot / "robot.yaml").read_text()
    (robot / "robot.yaml").write_text(text[: text.index("run_defaults:")] + block)
    with pytest.raises(ConfigError) as err:
        load_config(values={"robot": str(robot)})
    assert str(robot / "robot.yaml") in str(err.value) and field_name in str(err.value)


@pytest.mark.parametrize(
    ("bad", "field_name", "problem"),
    [
        ("control:\n    iso: {centre: [0.35, 0.0, 0.2]}\n", "control.iso.centre", "unknown key"),
        ("trajectory:\n    cp_edge_m: abc\n", "trajectory.cp_edge_m", "got 'abc'"),
        ("control:\n    iso: {centre_m: [0.35, 0]}\n", "control.iso.centre_m", "3 numbers"),
    ],
)
def test_bad_run_defaults_blamed_when_a_later_layer_touches_the_section(tmp_path, bad, field_name, problem):
    robot = tmp_path / "myrobot"
    shutil.copytree(config.REPO_ROOT / "robots" / "staubli_tx40", robot)
    text = (robot / "robot.yaml").read_text()
    (robot / "robot.yaml").write_text(text[: text.index("run_defaults:")] + "run_defaults:\n  " + bad)
    # the config file and --set touch other fields of the same sections
    p = write(tmp_path, f"robot: {robot}\ncontrol: {{iso: {{edge_m: 0.25}}}}\ntrajectory: {{cp_segment: line}}\n")
    for overrides in ([], ["control.iso.segments=[line]", "trajectory.cp_ik_points=80"]):
        with pytest.raises(ConfigError) as err:
            load_config(p, overrides)
        assert err.value.file == f"{robot / 'robot.yaml'} (run_defaults)", (overrides, str(err.value))
        assert err.value.field == field_name and problem in err.value.problem
    # a later layer that replaces the bad value repairs it; a bad value of its own is its own
    fixed = {"control.iso.centre": None, "trajectory.cp_edge_m": "0.2", "control.iso.centre_m": "[0.35, 0, 0.2]"}
    if field_name != "control.iso.centre":
        load_config(p, [f"{field_name}={fixed[field_name]}"])
    section = field_name.split(".")[0]
    other = "control.iso.speed_m_s=fast" if section == "control" else "trajectory.fine_dt_s=fast"
    with pytest.raises(ConfigError) as err:
        load_config(p, [other])
    assert err.value.file in ("--set", f"{robot / 'robot.yaml'} (run_defaults)")
    assert (err.value.file == "--set") == (err.value.field == other.split("=")[0]), str(err.value)


def test_field_origins_record_the_layer_of_each_field(tmp_path):
    p = write(tmp_path, "robot: staubli_tx40\nmodel: {pose_deg: [0, 0, 0, 0, 0, 0]}\ncontrol: {iso: {edge_m: 0.25}}\n")
    cfg = load_config(p, ["model.picture_size_in=4", "control.iso.edge_m=0.3"])
    run_defaults = str(config.REPO_ROOT / "robots" / "staubli_tx40" / "robot.yaml") + " (run_defaults)"
    assert cfg.field_origins["model.pose_deg"] == str(p)
    assert cfg.field_origins["model.picture_size_in"] == "--set"
    assert cfg.field_origins["control.iso.edge_m"] == "--set"
    assert cfg.field_origins["control.iso.centre_m"] == run_defaults
    assert cfg.origins["model"] == "--set"                          # the section's last layer
    assert cfg.source_of("model.pose_deg") == str(p) and cfg.source_of("model.pose_deg[3]") == str(p)
    assert cfg.source_of("control.iso.centre_m") == run_defaults
    assert cfg.source_of("model.views_deg") == "--set"              # not set: the section's last layer
    assert cfg.source_of("calibration.n_configurations") == str(p)  # untouched section: the file
    assert "field_origins" not in cfg.to_dict() and "field_origins" not in cfg.to_yaml()


@pytest.mark.parametrize(("setting", "field"), [
    ("control.engine=fast", "control.engine"),
    ("control.variants=[none, bogus]", r"control.variants\[1\]"),
    ("control.iso.tool_orientation=up", "control.iso.tool_orientation"),
    ("calibration.second_pass=sometimes", "calibration.second_pass"),
    ("identification.excitation.criterion=x", "identification.excitation.criterion"),
    ("trajectory.ptp_energy=joules", "trajectory.ptp_energy"),
])
def test_a_choice_outside_its_literal_is_one_line_naming_the_field(setting, field):
    with pytest.raises(ConfigError, match=rf"^--set: {field}: expected one of [a-z_, ]+, got '\w+'$"):
        load_config(None, [setting])


def test_choices_of_a_config_built_in_python_are_checked_too():
    @dataclass
    class Section:
        mode: Literal["a", "b"] = "a"
        modes: list[Literal["a", "b"]] = field(default_factory=list)
        maybe: Literal["a"] | None = None

    check_choices(Section("b", ["a", "b"], None), "s")
    for bad, where in ((Section("c"), r"s\.mode"), (Section(modes=["a", "c"]), r"s\.modes\[1\]"),
                       (Section(maybe="b"), r"s\.maybe")):
        with pytest.raises(ConfigError, match=rf"{where}: expected one of"):
            check_choices(bad, "s")
