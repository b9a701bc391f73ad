"""Fuzzing the user inputs: any config file, ``--set`` value or ``robot.yaml`` edit ends either in
a valid configuration or in one :class:`PipelineError` line, never in another exception."""

from __future__ import annotations

import copy
import shutil
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.core.config import CONFIGS_DIR, load_config, section_names
from pipeline.core.errors import ConfigError, PipelineError, RobotFileError
from pipeline.robot.model import RobotModel
from pipeline.robot.spec import load_robot_spec

FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True),
                    st.text(max_size=12))
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                      max_leaves=12)
#: real keys (top level, sections and their fields) mixed with junk
QUICK = yaml.safe_load((CONFIGS_DIR / "quick.yaml").read_text())
FIELDS = [f"{s}.{k}" for s in section_names() if isinstance(QUICK.get(s), dict) for k in QUICK[s]]
keys = st.sampled_from(["name", "seed", "robot", "profile", "stages", *section_names(), *FIELDS, "bogus", "x.y"])


def _one_line(exc: PipelineError) -> bool:
    return "\n" not in exc.one_line() and bool(exc.one_line())


@FUZZ
@given(data=st.dictionaries(keys, values, max_size=4))
def test_any_config_mapping_is_valid_or_one_config_error(tmp_path, data):
    nested: dict = {}
    for key, value in data.items():
        head, _, rest = key.partition(".")
        if rest:
            if not isinstance(nested.get(head), dict):
                nested[head] = {}
            nested[head][rest] = value
        else:
            nested[head] = value
    path = tmp_path / "fuzz.yaml"
    path.write_text(yaml.safe_dump(nested) if nested else "profile: full\n")
    try:
        load_config(path)
    except ConfigError as exc:
        assert _one_line(exc)


@FUZZ
@given(key=keys, text=st.text(max_size=20))
def test_any_set_override_is_valid_or_one_config_error(key, text):
    try:
        load_config(None, [f"{key}={text}"])
    except ConfigError as exc:
        assert _one_line(exc)


@FUZZ
@given(raw=st.binary(max_size=64))
def test_any_bytes_as_config_file_is_valid_or_one_config_error(tmp_path, raw):
    path = tmp_path / "raw.yaml"
    path.write_bytes(raw)
    try:
        load_config(path)
    except ConfigError as exc:
        assert _one_line(exc) and str(path) in exc.one_line()


ROBOT_YAML = Path(__file__).resolve().parents[2] / "robots" / "rx130l" / "robot.yaml"
ROBOT_DATA = yaml.safe_load(ROBOT_YAML.read_text())
ROBOT_FIELDS = [(s, k) for s, sub in ROBOT_DATA.items() if isinstance(sub, dict) for k in sub]


@FUZZ
@given(field=st.sampled_from(ROBOT_FIELDS), value=values)
def test_any_robot_yaml_edit_is_valid_or_one_robot_file_error(tmp_path, field, value):
    folder = tmp_path / "robot"
    if not folder.exists():
        shutil.copytree(ROBOT_YAML.parent, folder)
    data = copy.deepcopy(ROBOT_DATA)            # the file parsed once (pure-Python YAML: 30 ms a parse)
    data[field[0]][field[1]] = value
    (folder / "robot.yaml").write_text(yaml.safe_dump(data))
    try:
        load_robot_spec(folder / "robot.yaml", nq=6)
    except RobotFileError as exc:
        assert _one_line(exc) and "robot.yaml" in exc.one_line()


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


@pytest.mark.parametrize("field", ["gear_ratio", "rotor_inertia_kgm2", "viscous_Nms_rad", "coulomb_Nm"])
def test_per_joint_list_of_wrong_length_is_reported_under_its_own_field(tmp_path, field):
    folder = tmp_path / "robot"
    shutil.copytree(ROBOT_YAML.parent, folder)
    data = yaml.safe_load(ROBOT_YAML.read_text())
    data["actuation"][field] = data["actuation"][field][:-1]
    (folder / "robot.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(RobotFileError, match=rf"robot.yaml: actuation.{field}: expected 6 numbers, got 5"):
        RobotModel.load(folder)
