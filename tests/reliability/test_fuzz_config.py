"""Fuzzing the user's settings: any config file (as a mapping, as YAML text built from hostile
pieces, as raw bytes), ``--set`` value or ``robot.yaml`` edit ends either in a valid configuration
or in one :class:`PipelineError` line (the CLI prints it and exits 2), never in another exception,
and nothing is written. Each property runs a bounded number of inputs in the fast suite (profile
``fuzz``) and more in its slow-marked variant (``fuzz-slow``, ``make test-slow``); the run log
counts the inputs per reader ("fuzz inputs per reader")."""

from __future__ import annotations

import copy
import shutil
from pathlib import Path

import pytest
from hypothesis import strategies as st

import pipeline.run  # noqa: F401 - registers the stages whose sections the configs hold
from pipeline.core.config import CONFIGS_DIR, load_config, section_names
from pipeline.core.errors import ConfigError, PipelineError, RobotFileError
from pipeline.core.yaml12 import MAX_DEPTH, dump_yaml, load_yaml
from pipeline.robot.model import RobotModel
from pipeline.robot.spec import load_robot_spec
from tests.reliability.fuzzing import fast_and_slow


def _one_line(exc: PipelineError) -> bool:
    return "\n" not in exc.one_line() and bool(exc.one_line())


def _files(folder: Path) -> set[Path]:
    return set(folder.rglob("*"))


scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True),
                    st.text(max_size=12), st.sampled_from(["1e-3", ".inf", "-.nan", "yes", "0x1F", "~", "[", "{a"]))
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                      max_leaves=12)
#: real keys (top level, sections and their fields) mixed with junk
QUICK = load_yaml((CONFIGS_DIR / "quick.yaml").read_text())
FIELDS = [f"{s}.{k}" for s in section_names() if isinstance(QUICK.get(s), dict) for k in QUICK[s]]
keys = st.sampled_from(["name", "seed", "robot", "profile", "stages", *section_names(), *FIELDS, "bogus", "x.y"])

#: pieces of YAML text: structure, anchors and aliases, tags, deep nesting, odd scalars
PIECES = ["a: 1\n", "seed: 7\n", "calibration:\n", "  n_configurations: 20\n", "- x\n", "[", "]", "{", "}",
          ", ", ": ", "&a ", "*a ", "<<: *a\n", "!!python/object:os.system ", "!!str ", "? ", "---\n", "...\n",
          "%YAML 1.1\n", "\t", "  ", "\n", "#c\n", "'", '"', "|\n  x\n", ">\n", "\ufeff", "\x00", "1e999",
          ".nan", "seed: 1\nseed: 2\n", "[" * (MAX_DEPTH + 5), "- " * (MAX_DEPTH + 5) + "1\n",
          "b: &b [1, 2, 3, 4, 5, 6, 7, 8]\nc: &c [*b, *b, *b, *b, *b, *b, *b, *b]\n"]
yaml_texts = st.lists(st.sampled_from(PIECES), max_size=12).map("".join)


def _nested(data: dict) -> dict:
    nested: dict = {}
    for key, value in data.items():
        head, _, rest = key.partition(".")
        if rest:
            if not isinstance(nested.get(head), dict):
                nested[head] = {}
            nested[head][rest] = value
        else:
            nested[head] = value
    return nested


def _load_config_file(path: Path) -> None:
    before = _files(path.parent)
    try:
        load_config(path)
    except ConfigError as exc:
        assert _one_line(exc) and str(path) in exc.one_line()
    assert _files(path.parent) == before


@fast_and_slow(data=st.dictionaries(keys, values, max_size=4))
def _config_mapping(tmp_path, fuzz_inputs, data):
    fuzz_inputs["config file"] += 1
    nested = _nested(data)
    path = tmp_path / "fuzz.yaml"
    path.write_text(dump_yaml(nested) if nested else "profile: full\n")
    _load_config_file(path)


test_any_config_mapping_is_valid_or_one_config_error, test_many_config_mappings = _config_mapping


@fast_and_slow(text=yaml_texts)
def _config_text(tmp_path, fuzz_inputs, text):
    fuzz_inputs["config file"] += 1
    path = tmp_path / "text.yaml"
    path.write_text(text, encoding="utf-8")
    _load_config_file(path)


test_any_yaml_text_as_config_is_valid_or_one_config_error, test_many_yaml_texts_as_config = _config_text


@fast_and_slow(raw=st.binary(max_size=64))
def _config_bytes(tmp_path, fuzz_inputs, raw):
    fuzz_inputs["config file"] += 1
    path = tmp_path / "raw.yaml"
    path.write_bytes(raw)
    _load_config_file(path)


test_any_bytes_as_config_file_is_valid_or_one_config_error, test_many_bytes_as_config_file = _config_bytes


@fast_and_slow(key=keys, text=st.one_of(st.text(max_size=20), yaml_texts))
def _set_override(fuzz_inputs, key, text):
    fuzz_inputs["--set"] += 1
    try:
        load_config(None, [f"{key}={text}"])
    except ConfigError as exc:
        assert _one_line(exc)


test_any_set_override_is_valid_or_one_config_error, test_many_set_overrides = _set_override


ROBOT_YAML = Path(__file__).resolve().parents[2] / "robots" / "rx130l" / "robot.yaml"
ROBOT_TEXT = ROBOT_YAML.read_text()
ROBOT_DATA = load_yaml(ROBOT_TEXT)
ROBOT_FIELDS = [(s, k) for s, sub in ROBOT_DATA.items() if isinstance(sub, dict) for k in sub]


def _robot_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "robot"
    if not folder.exists():
        shutil.copytree(ROBOT_YAML.parent, folder)
    return folder


def _load_robot_yaml(folder: Path) -> None:
    before = _files(folder)
    try:
        load_robot_spec(folder / "robot.yaml", nq=6)
    except RobotFileError as exc:
        assert _one_line(exc) and "robot.yaml" in exc.one_line()
    assert _files(folder) == before


@fast_and_slow(share=0.5, field=st.sampled_from(ROBOT_FIELDS), value=values)
def _robot_yaml_edit(tmp_path, fuzz_inputs, field, value):
    fuzz_inputs["robot.yaml"] += 1
    folder = _robot_folder(tmp_path)
    data = copy.deepcopy(ROBOT_DATA)            # the file parsed once (pure-Python YAML: 30 ms a parse)
    data[field[0]][field[1]] = value
    (folder / "robot.yaml").write_text(dump_yaml(data))
    _load_robot_yaml(folder)


test_any_robot_yaml_edit_is_valid_or_one_robot_file_error, test_many_robot_yaml_edits = _robot_yaml_edit


@fast_and_slow(share=0.5, line=st.integers(0, ROBOT_TEXT.count("\n")), piece=st.sampled_from(PIECES),
               how=st.sampled_from(["insert", "replace", "delete", "duplicate"]))
def _robot_yaml_text(tmp_path, fuzz_inputs, line, piece, how):
    fuzz_inputs["robot.yaml"] += 1
    folder = _robot_folder(tmp_path)
    lines = ROBOT_TEXT.split("\n")
    line = min(line, len(lines) - 1)
    edits = {"insert": [piece, lines[line]], "replace": [piece], "delete": [], "duplicate": [lines[line]] * 2}
    (folder / "robot.yaml").write_text("\n".join([*lines[:line], *edits[how], *lines[line + 1:]]))
    _load_robot_yaml(folder)


test_any_robot_yaml_text_edit_is_valid_or_one_robot_file_error, test_many_robot_yaml_text_edits = _robot_yaml_text


@pytest.mark.parametrize("text", ["", "# only a comment\n", "\n\n"])
def test_empty_config_file_is_an_error_not_the_full_profile(tmp_path, text):
    path = tmp_path / "empty.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match="the config file is empty; leave out --config"):
        load_config(path)


def test_binary_config_file_is_one_line(tmp_path):
    path = tmp_path / "bin.yaml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")
    with pytest.raises(ConfigError, match="not a UTF-8 text file"):
        load_config(path)


def test_a_set_value_nested_deeper_than_the_limit_is_one_line():
    with pytest.raises(ConfigError, match=rf"--set: .*nested deeper than {MAX_DEPTH} levels") as info:
        load_config(None, ["calibration.n_configurations=" + "[" * 20_000 + "]" * 20_000])
    assert _one_line(info.value)


@pytest.mark.parametrize("field", ["gear_ratio", "rotor_inertia_kgm2", "viscous_Nms_rad", "coulomb_Nm"])
def test_per_joint_list_of_wrong_length_is_reported_under_its_own_field(tmp_path, field):
    folder = tmp_path / "robot"
    shutil.copytree(ROBOT_YAML.parent, folder)
    data = copy.deepcopy(ROBOT_DATA)
    data["actuation"][field] = data["actuation"][field][:-1]
    (folder / "robot.yaml").write_text(dump_yaml(data))
    with pytest.raises(RobotFileError, match=rf"robot.yaml: actuation.{field}: expected 6 numbers, got 5"):
        RobotModel.load(folder)


@pytest.mark.parametrize("text", ["? |\n  x\n", "\"a\\nb\": 1\n", "? \"\\u2028\"\n"])
def test_a_key_holding_a_line_break_is_named_in_one_line(tmp_path, text):
    path = tmp_path / "key.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match="unknown key") as info:
        load_config(path)
    assert _one_line(info.value) and len(info.value.one_line().splitlines()) == 1
