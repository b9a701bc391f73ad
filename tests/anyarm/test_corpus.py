"""The arm corpus (:mod:`pipeline.robot.public_arms`): every arm through ``robot init`` with no
options, ``check`` and a run of every stage as shipped (corpus profile, every quality gate, no
``--accept-poor``), each writing its row of the table in ``docs/robots.md`` (``tools/corpus_table.py``
renders it).

Fast: the corpus's breadth (sources, axes, formats), the docs table holding a row of every arm, an
MJCF model through ``robot init`` and an industrial URDF with placeholder dynamics through ``robot
init`` and ``check`` (its first stages).
Slow: a handful of arms (one per source and format, 6 and 7 axes, placeholder dynamics) through every
stage, exit 0, and no failure that ``check`` did not report first; the paper-scale ``study`` set runs
the rest (``pytest -m "slow or study" tests/anyarm/test_corpus.py`` runs all and writes the table's rows).
"""

from __future__ import annotations

from collections import Counter

import pytest

from pipeline.core.config import REPO_ROOT
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


def test_docs_table_has_a_row_of_every_arm():
    """The table in docs/robots.md is rendered from a run of the whole corpus (tools/corpus_table.py)."""
    text = (REPO_ROOT / "docs" / "robots.md").read_text()
    table = text.split("<!-- corpus table -->")[1].split("<!-- /corpus table -->")[0]
    rows = {line.split("|")[1].strip().strip("`") for line in table.splitlines() if line.startswith("| `")}
    assert rows == {a.name for a in CORPUS}


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


#: the slow suite's arms (``make test-slow``): one of each kind, about 40-60 CPU-s each in the corpus
#: profile on 2 cores (a few minutes of the CI budget with 2 workers): a gripper's knuckle and
#: finger joints locked (xArm6 + gripper), 7 axes with real inertials and a hand (Panda), a pybullet
#: URDF with placeholder limits (iiwa), ROS-Industrial URDFs with placeholder inertials and efforts
#: (IRB 140, KR 16-2), an MJCF model (ARX5). The paper-scale ``study`` set runs the rest of the corpus.
SLOW_SUITE_ARMS = frozenset({"pb_xarm6_gripper", "panda", "pb_kuka_iiwa", "abb_irb140", "kuka_kr16_2", "rs_arx5"})


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
