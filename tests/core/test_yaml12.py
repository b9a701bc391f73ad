"""The package's YAML reader and writer: YAML 1.2 numbers in config files, --set and robot.yaml,
duplicate keys refused naming the file, the key and both lines, unknown keys answered with the
closest known key; what is written reads back exactly (digests that look like numbers quoted, old
unquoted digests read as text); nesting and alias expansion bounded."""

from __future__ import annotations

import math
import shutil
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline import cli
from pipeline.core.config import REPO_ROOT, load_config
from pipeline.core.errors import ConfigError, RobotFileError
from pipeline.core.yaml12 import MAX_DEPTH, MAX_NODES, DuplicateKeyError, YAMLError, dump_yaml, load_yaml, yaml_problem
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


@pytest.mark.parametrize("key", ["? [{name: base}]\n", "? {a: 1}\n", "? [1, 2]\n"])
def test_a_collection_as_a_mapping_key_names_its_line(robot_yaml, key):
    """``? `` before a collection makes it a key (here the capsule list of robot.yaml): refused in the
    file's own terms, with the line, not a TypeError from the YAML reader."""
    lines = robot_yaml.read_text().splitlines()
    robot_yaml.write_text("\n".join([*lines, key + ": 1"]) + "\n")
    with pytest.raises(RobotFileError, match=rf"a mapping key that is a collection \(line {len(lines) + 1}\)"):
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


# ------------------------------------------------------------------ written as it is read
#: strings a YAML 1.2 reader resolves to another type unless quoted: digests that look like numbers,
#: booleans, null, special floats, octal and hex ints
LOOK_ALIKES = ["30425e4453996520", "3042544539965201", "0123456789012345", "1e5", "1E-5", ".5", "+1", "-0",
               "0o17", "0x1F", "true", "False", "null", "~", "", ".inf", "-.Inf", ".nan", "1_000", "yes", "0.",
               " lead", "trail ", "a: b", "- x", "#c", "'q'", '"d"', "{x}", "[1]", "&a", "*a", "!t", "%p", "@x",
               "\ufeffbom", "tab\there", "line\nbreak", "é ü 中", "\x85", "\u2028", "?0", "? x", "?", ":0", ": x"]

digests = st.text("0123456789abcdef", min_size=16, max_size=16)
scalars = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=False), digests, st.text(),
                    st.sampled_from(LOOK_ALIKES))
documents = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                          st.dictionaries(st.text(max_size=6) | digests, inner,
                                                                          max_size=4)),
                         max_leaves=16)


@settings(max_examples=60, deadline=None)
@given(value=documents)
def test_what_is_written_reads_back_exactly(value):
    for flow in (False, None):
        again = load_yaml(dump_yaml(value, flow=flow))
        assert again == value and _types(again) == _types(value)


def _types(value):
    if isinstance(value, dict):
        return {k: _types(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_types(v) for v in value]
    return type(value).__name__


@pytest.mark.parametrize("text", LOOK_ALIKES)
def test_a_string_that_looks_like_another_type_is_quoted(text):
    assert load_yaml(dump_yaml({"v": text})) == {"v": text}
    assert load_yaml(dump_yaml([text], flow=True)) == [text]


def test_nan_and_infinities_read_back():
    again = load_yaml(dump_yaml({"a": float("nan"), "b": float("inf"), "c": -float("inf")}))
    assert math.isnan(again["a"]) and again["b"] == float("inf") and again["c"] == -float("inf")


@pytest.mark.parametrize("digest", ["30425e4453996520", "3042544539965201", "0123456789012345", "1e10", "null"])
def test_an_unquoted_digest_written_by_earlier_versions_is_text(digest):
    data = load_yaml(f"assumed:\n  tracker: {{rule: r, sha256: {digest}}}\n  other:\n    sha256: {digest}\n")
    assert data["assumed"]["tracker"]["sha256"] == digest and data["assumed"]["other"]["sha256"] == digest
    assert load_yaml("sha256: '12'\nn: 12\nsha256s: 12\n") == {"sha256": "12", "n": 12, "sha256s": 12}


# ------------------------------------------------------------------ hostile texts refused fast
def _alias_bomb(levels: int = 10, width: int = 9) -> str:
    lines = [f"a0: &a0 [{', '.join(['lol'] * width)}]"]
    lines += [f"a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * width)}]" for k in range(1, levels)]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(("text", "problem"), [
    (_alias_bomb(), f"aliases expand to more than {MAX_NODES} values"),
    ("[" * 20_000 + "]" * 20_000, f"nested deeper than {MAX_DEPTH} levels"),
    ("{a: " * 20_000 + "1" + "}" * 20_000, f"nested deeper than {MAX_DEPTH} levels"),
    ("- " * 20_000 + "x\n", f"nested deeper than {MAX_DEPTH} levels"),
    ("".join(f"{' ' * k}k:\n" for k in range(200)) + " " * 200 + "v\n", f"nested deeper than {MAX_DEPTH} levels"),
    ("a: &a [*a]\n", "refers to the node that holds it"),
])
def test_hostile_texts_are_refused_in_one_line_within_a_second(text, problem):
    start = time.perf_counter()
    with pytest.raises(YAMLError) as info:
        load_yaml(text)
    assert time.perf_counter() - start < 1.0
    where, message = yaml_problem(info.value)
    assert problem in message and "\n" not in message and where is not None and where.startswith("line ")


def test_a_deep_but_allowed_nesting_and_many_aliases_still_load():
    assert load_yaml("[" * MAX_DEPTH + "]" * MAX_DEPTH) is not None
    assert len(load_yaml(_alias_bomb(levels=4, width=9))["a3"]) == 9


@pytest.mark.parametrize("text", [_alias_bomb(), "[" * 20_000 + "]" * 20_000])
def test_a_hostile_config_file_is_one_line_exit_2_and_nothing_written(tmp_path, capsys, text):
    path = tmp_path / "hostile.yaml"
    path.write_text(text)
    start = time.perf_counter()
    assert cli.main(["check", "--config", str(path), "--out", str(tmp_path / "runs")]) == 2
    assert time.perf_counter() - start < 1.0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {path}: line ") and "refused" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hostile.yaml"]


def test_a_long_double_quoted_string_is_not_folded_after_an_escape():
    """A long string of escapes and spaces, in block and flow style, reads back without a space added
    where ruamel's emitter would have broken the line after an escape."""
    value = [[None, 1.1207088533414202e+16, "000000000000\x1f\x1f\x1f\x1f", '000000"\x1f\x7f0 0']]
    long_text = "".join("0 a\x1f\x7f\"\\é\n\t"[(7 * k) % 10] for k in range(300))
    for flow in (False, None, True):
        assert load_yaml(dump_yaml(value, flow=flow)) == value
        assert load_yaml(dump_yaml({"k": [long_text]}, flow=flow, width=40)) == {"k": [long_text]}
