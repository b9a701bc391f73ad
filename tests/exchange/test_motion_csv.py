"""Motion and joint-state CSV: written and read back bit for bit; a wrong header is refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.core.errors import DataFileError
from pipeline.exchange.motion import JointStates, SampledMotion
from pipeline.exchange.motion_csv import (
    read_joint_states_csv,
    read_motion_csv,
    write_joint_states_csv,
    write_motion_csv,
)


def test_motion_csv_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    motion = SampledMotion(("joint_1", "joint_2"), 1e-3 * np.arange(7), *(rng.normal(size=(7, 2)) for _ in range(4)))
    path = write_motion_csv(tmp_path / "m.csv", motion)
    header = path.read_text().splitlines()[0]
    assert header == ("t_s,q_joint_1_rad,q_joint_2_rad,qd_joint_1_rad_s,qd_joint_2_rad_s,qdd_joint_1_rad_s2,"
                      "qdd_joint_2_rad_s2,tau_ff_joint_1_Nm,tau_ff_joint_2_Nm")
    back = read_motion_csv(path)
    assert back.joint_names == motion.joint_names
    for field in ("t_s", "q_rad", "qd_rad_s", "qdd_rad_s2", "tau_ff_Nm"):
        np.testing.assert_array_equal(getattr(back, field), getattr(motion, field))


def test_joint_states_csv_round_trip_and_bad_header(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    states = JointStates(("a",), np.arange(4.0), *(rng.normal(size=(4, 1)) for _ in range(3)))
    back = read_joint_states_csv(write_joint_states_csv(tmp_path / "s.csv", states))
    np.testing.assert_array_equal(back.effort_Nm, states.effort_Nm)
    bad = tmp_path / "bad.csv"
    bad.write_text("t_s,q_a_rad,qd_a_deg_s,effort_a_Nm\n0,0,0,0\n")
    with pytest.raises(DataFileError, match="qd_a_deg_s"):
        read_joint_states_csv(bad)
