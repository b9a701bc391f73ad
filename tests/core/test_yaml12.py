"""The package's YAML loader: YAML 1.2 numbers in config files, --set and robot.yaml, duplicate keys
refused naming the file, the key and both lines, unknown keys answered with the closest known key."""

from __future__ import annotations

import shutil

import pytest

from pipeline import cli
from pipeline.core.config import REPO_ROOT, load_config
from pipeline.core.errors import ConfigError, RobotFileError
from pipeline.core.yaml12 import DuplicateKeyError, load_yaml
from pipeline.robot.spec import load_robot_spec


@pytest.mark.parametrize("text, value", [("1.0e6", 1.0e6), ("1e-3", 1e-3), (".5", 0.5), ("-2E+3", -2000.0),
                                         ("010", 10), ("0x1F", 31), ("0o17", 15), (".inf", float("inf")),
                                         ("yes", "yes"), ("off", "off"), ("true", True), ("1_000", "1_000")])
def test_scalars_follow_the_yaml_1_2_core_schema(text, value):
    loaded = load_yaml(f"v: {text}\n")["v"]
    assert loaded == value and type(loaded) is type(value)


def test_duplicate_key_names_the_key_and_both_lines():
    with pytest.raises(DuplicateKeyError) as info:
        load_yaml("a:\n  x: 1\n  y: 2\n  x: 3\n")
    assert (info.value.key, info.value.first_line, info.value.second_line) == ("x", 2, 4)
    assert load_yaml("b: &b {x: 1}\nc:\n  <<: *b\n  x: 2\n")["c"] == {"x": 2}    # a merge key may override


def test_config_file_and_set_read_floats(fake_stages, tmp_path):
    path = tmp_path / "run.yaml"
    path.write_text("a: {gain: 1e-3}\nb: {gain: .5}\n")
    cfg = load_config(path, ["c.gain=-2E+3"])
    assert (cfg.sections["a"].gain, cfg.sections["b"].gain, cfg.sections["c"].gain) == (1e-3, 0.5, -2000.0)


def test_duplicate_key_in_a_config_is_one_line_exit_2(fake_stages, tmp_path, capsys):
    path = tmp_path / "run.yaml"
    path.write_text("seed: 1\nname: r\nseed: 7\n")
    with pytest.raises(ConfigError, match=r"run\.yaml: seed: duplicate key \(lines 1 and 3\)"):
        load_config(path)
    assert cli.main(["check", "--config", str(path), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {path}: seed: duplicate key (lines 1 and 3)")


def test_unknown_key_suggests_the_closest_known_key(fake_stages):
    with pytest.raises(ConfigError, match=r"a\.gian: unknown key; did you mean 'gain'\?$"):
        load_config(None, ["a.gian=2"])
    with pytest.raises(ConfigError, match=r"^--set: sede: unknown key; did you mean 'seed'\?$"):
        load_config(None, ["sede=2"])
    with pytest.raises(ConfigError, match=r"zzzz: unknown key \(known keys: "):     # nothing close: the list
        load_config(None, ["a.zzzz=2"])


@pytest.fixture
def robot_yaml(tmp_path):
    folder = tmp_path / "arm"
    shutil.copytree(REPO_ROOT / "robots" / "rx130l", folder)
    return folder / "robot.yaml"


def test_robot_yaml_duplicate_key_names_both_lines(robot_yaml):
    lines = robot_yaml.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("tool:")) + 1
    robot_yaml.write_text("\n".join([*lines, "tool: {}"]) + "\n")
    pattern = rf"robot\.yaml: tool: duplicate key \(lines {first} and {len(lines) + 1}\)"
    with pytest.raises(RobotFileError, match=pattern):
        load_robot_spec(robot_yaml)


def test_robot_yaml_exponent_floats_are_numbers(robot_yaml):
    text = robot_yaml.read_text()
    old = "viscous_Nms_rad: [20.0, 20.0, 10.0, 3.0, 3.0, 1.5]"
    assert old in text
    robot_yaml.write_text(text.replace(old, "viscous_Nms_rad: [2.0e1, 2e+1, 1E1, 3e0, 30e-1, .15e1]"))
    assert load_robot_spec(robot_yaml).actuation.viscous_Nms_rad.tolist() == [20.0, 20.0, 10.0, 3.0, 3.0, 1.5]


def test_a_text_parsed_again_gives_equal_data_that_is_not_shared():
    text = "base: &b {x: [1, 2]}\nother: *b\nn: 1e-3\n"
    first = load_yaml(text)
    first["base"]["x"].append(3)                       # a caller edits what it was given
    again = load_yaml(text)
    assert again == {"base": {"x": [1, 2]}, "other": {"x": [1, 2]}, "n": 1e-3}
    assert again["base"] is again["other"]             # an alias is one object, as when parsed
