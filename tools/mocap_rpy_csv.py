"""Convert a motion-capture calibration record with roll-pitch-yaw orientations to the stage's CSV.

Layout only, no value is changed beyond the orientation's parametrisation: the input has the marker
position ``x1,y1,z1`` (m), its orientation as roll-pitch-yaw ``phix1,phiy1,phiz1`` (rad; pinocchio
``rpy.matrixToRpy``, ``R = Rz(yaw) Ry(pitch) Rx(roll)``) and the joint angles (rad) in columns
named by joint (FIGAROH's ``calibration.csv``, ``data/figaroh_ur10_mocap``). The output has the
columns ``q1..qn,x,y,z,rx,ry,rz`` of :mod:`pipeline.calibration.measure`, ``r`` the rotation
vector of the same ``R``.

    python tools/mocap_rpy_csv.py IN.csv OUT.csv JOINT1 JOINT2 ...
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

POSITION = ("x1", "y1", "z1")
RPY = ("phix1", "phiy1", "phiz1")


def convert(src: str | Path, dst: str | Path, joints: list[str]) -> Path:
    """Write ``dst`` in the stage's layout from the roll-pitch-yaw record ``src`` (module docstring)."""
    with Path(src).open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    rpy = np.array([[float(r[k]) for k in RPY] for r in rows])
    rotvec = Rotation.from_euler("xyz", rpy).as_rotvec()   # extrinsic x, y, z = Rz Ry Rx
    dst = Path(dst)
    with dst.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([f"q{i}" for i in range(1, len(joints) + 1)] + ["x", "y", "z", "rx", "ry", "rz"])
        for r, rv in zip(rows, rotvec, strict=True):
            w.writerow([r[j] for j in joints] + [r[k] for k in POSITION] + [repr(float(v)) for v in rv])
    return dst


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    print(convert(sys.argv[1], sys.argv[2], sys.argv[3:]))
