"""Write tiago_identification.csv (``t, q1..q7, tau1..tau7``, joint side, time stamps as logged)
from FIGAROH's TIAGo record (``tiago_position.csv``, ``tiago_effort.csv``; README.md).

Joint torque = reduction ratio x motor constant x logged current, as FIGAROH's
``examples/tiago/identification.py`` converts them; samples 921..6790 (FIGAROH's choice: the arm
is at rest after about 68 s); the prismatic torso column is dropped (it is locked in the model).
Usage: ``python data/figaroh_tiago/make_csv.py FOLDER_OF_THE_FIGAROH_FILES``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

#: reduction ratios and motor constants (N·m/A) of arm_1..arm_7 (FIGAROH examples/tiago)
REDUCTION_RATIO = np.array([100.0, 100.0, 100.0, 100.0, 336.0, 336.0, 336.0])
MOTOR_CONSTANT_NM_A = np.array([0.136, 0.136, -0.087, -0.087, -0.0613, -0.0613, -0.0613])
KEEP = slice(921, 6791)


def convert(folder: Path) -> np.ndarray:
    pos = np.loadtxt(folder / "tiago_position.csv", delimiter=",", skiprows=1)
    eff = np.loadtxt(folder / "tiago_effort.csv", delimiter=",", skiprows=1)
    t = pos[KEEP, 0] - pos[KEEP.start, 0]
    q = pos[KEEP, 2:9]
    tau = eff[KEEP, 2:9] * REDUCTION_RATIO * MOTOR_CONSTANT_NM_A
    return np.column_stack([t, q, tau])


if __name__ == "__main__":
    table = convert(Path(sys.argv[1]))
    header = "t," + ",".join(f"q{i}" for i in range(1, 8)) + "," + ",".join(f"tau{i}" for i in range(1, 8))
    np.savetxt(Path(__file__).with_name("tiago_identification.csv"), table, delimiter=",", header=header,
               comments="", fmt="%.7g")
