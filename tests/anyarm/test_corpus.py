"""The arm corpus (:mod:`pipeline.robot.public_arms`): every arm through ``robot init`` with no
options, ``check`` and a run of every stage as shipped (corpus profile), each writing its row of
the table in ``docs/robots.md`` (``tools/corpus_table.py`` renders it).

Fast: the corpus's breadth (sources, axes, formats), an MJCF model through ``robot init`` and an
industrial URDF with placeholder dynamics through ``robot init`` and ``check`` (its first stages).
Slow: every arm through every stage, exit 0, and no failure that ``check`` did not report first.
"""

from __future__ import annotations

from collections import Counter

import pytest

from pipeline.robot.model import RobotModel
from pipeline.robot.public_arms import CORPUS, arm_file, corpus_arm
from tests.anyarm.corpus_run import run_arm, run_cli


def _installed(name: str):
    arm = corpus_arm(name)
    if arm_file(arm) is None:
        pytest.skip(f"{arm.source} not installed (the dev extra)")
    return arm


def test_corpus_spans_sources_axes_and_formats():
    assert len(CORPUS) >= 25
    assert len(Counter(a.source for a in CORPUS)) >= 5
    assert {a.axes for a in CORPUS} >= {6, 7}
    assert sum(a.fmt == "MJCF" for a in CORPUS) >= 3
    assert len({a.name for a in CORPUS}) == len(CORPUS)


def test_mjcf_arm_through_robot_init(tmp_path):
    """An MJCF arm whose last joint moves a ``gripper_link``: 6 axes, converted beside robot.yaml."""
    arm = _installed("rs_vx300s")
    code, lines = run_cli(["robot", "init", str(arm_file(arm)), "--out", str(tmp_path / "robot.yaml")])
    assert code == 0, lines
    assert (tmp_path / "robot.urdf").is_file()
    assert RobotModel.load(tmp_path).nq == arm.axes


def test_industrial_urdf_with_placeholders_through_robot_init_and_check(tmp_path):
    arm = _installed("kuka_kr16_2")
    row = run_arm(arm, tmp_path, run=False, stages=["calibration", "identification"])
    assert row["init_exit"] == 0, row["init_lines"]
    assert row["axes"] == arm.axes
    assert row["check_exit"] == 0, row["check_lines"]
    placeholder = [line for line in row["check_lines"] if "placeholder effort limits" in line]
    assert len(placeholder) == 1 and "identification depend on them" in placeholder[0]


#: arms whose whole run fits the slow suite's budget (about 1.5 CPU-min each); the rest of the corpus
#: runs in the paper-scale ``study`` set (``pytest -m study``)
SLOW_SUITE_ARMS = frozenset({"tiago_arm", "pb_kuka_iiwa", "abb_irb140", "kuka_kr16_2", "kuka_kr210", "rs_arx5"})


@pytest.mark.slow
@pytest.mark.parametrize("name", [a.name if a.name in SLOW_SUITE_ARMS else pytest.param(a.name, marks=pytest.mark.study)
                                  for a in CORPUS])
def test_corpus_arm_through_every_stage(name, tmp_path):
    arm = _installed(name)
    row = run_arm(arm, tmp_path)
    assert row["init_exit"] == 0, row["init_lines"]
    assert row["axes"] == arm.axes
    if row["run_exit"] == 2:                # bad input: check must have said so first
        assert row["check_exit"] == 2, (row["check_lines"], row["run_lines"])
    assert row["check_exit"] == 0, row["check_lines"]
    assert row["run_exit"] == 0, row["run_lines"]
