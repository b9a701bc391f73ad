"""The authors' model on the UR10 record's held-out samples (``data/unisa_ur10_bag/README.md``).

Run: ``.venv/bin/python tools/unisa_ur10_reference.py CHECKOUT`` with ``CHECKOUT`` a clone of
unisa-acg/inverse-dynamics-solver (commit 41e196d). Needs ``g++``.

Petrone, Ferrentino & Chiacchio 2025 (IEEE TII, doi 10.1109/TII.2025.3534415) as UNISA ships it,
``InverseDynamicsSolverUR10::getTorques``: ``tau = K (i_rb(q, v, a) + i_f(v))`` with the generated
``getCurrents`` (compiled here from the checkout, not vendored), the drive gains ``K1..K6`` of its header and
the sigmoid friction currents ``i_f = f_v v + f_o + f_c / (1 + exp(-alpha (v + ni)))`` whose constants are
read from its source. Evaluated on the bag's messages :func:`held_out_messages` (the last 30 % as the identification
stage splits the record, 20 samples dropped at each end): positions and velocities as logged,
accelerations the central difference of the logged velocities after a zero-phase 10 Hz low-pass.
Prints the held-out torque RMS per joint and over all joints (N·m).
"""

from __future__ import annotations

import ctypes
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from pipeline.core.config import REPO_ROOT
from pipeline.exchange.ros2_bag import read_joint_states
from pipeline.identification.config import DATA_BORDER_SAMPLES, Config
from pipeline.identification.signals import differentiate, lowpass

BAG = REPO_ROOT / "data" / "unisa_ur10_bag" / "ur10_exciting_trajectory.db3"
PACKAGE = "ur10_inverse_dynamics_solver"

def held_out_messages(n_messages: int) -> slice:
    """The bag's messages of the identification stage's held-out tail: after ``DATA_BORDER_SAMPLES`` dropped
    at each end (no decimation at 125 Hz), the samples from ``int(data_train_fraction x N)`` on."""
    n = n_messages - 2 * DATA_BORDER_SAMPLES
    return slice(DATA_BORDER_SAMPLES + int(Config().data_train_fraction * n), n_messages - DATA_BORDER_SAMPLES)

ACCELERATION_CUTOFF_HZ = 10.0
WRAPPER = """#include "ur10_inverse_dynamics_solver/getCurrents.h"
extern "C" void get_currents(const double* q, const double* v, const double* a, double* out) {
  ur10_inverse_dynamics_solver::getCurrents(q, v, a, out);
}
"""


def constants(checkout: Path) -> dict[str, np.ndarray]:
    """``K`` (the drive gains) and the sigmoid's ``f_v, f_o, f_c, alpha, ni``, each per joint, from the source."""
    header = (checkout / PACKAGE / "include" / PACKAGE / f"{PACKAGE}.h").read_text()
    source = (checkout / PACKAGE / "src" / f"{PACKAGE}.cpp").read_text()
    out = {"K": np.array([float(re.search(rf"K{j}\s*=\s*([-0-9.eE+]+)", header).group(1)) for j in range(1, 7)])}
    for name in ("f_v", "f_o", "f_c", "alpha", "ni"):
        out[name] = np.array([float(re.search(rf"\b{name}\({j}\)\s*=\s*([-0-9.eE+]+);", source).group(1))
                              for j in range(6)])
    return out


def compiled_currents(checkout: Path, folder: Path) -> ctypes.CDLL:
    """``getCurrents`` of the checkout as a shared library."""
    (folder / "wrap.cpp").write_text(WRAPPER)
    library = folder / "libur10.so"
    subprocess.run(["g++", "-O1", "-shared", "-fPIC", f"-I{checkout / PACKAGE / 'include'}", str(folder / "wrap.cpp"),
                    str(checkout / PACKAGE / "src" / "getCurrents.cpp"), "-o", str(library)], check=True)
    return ctypes.CDLL(str(library))


def torques(lib: ctypes.CDLL, c: dict[str, np.ndarray], q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The authors' joint torques (N·m), one row per sample."""
    vector = ctypes.c_double * 6
    rigid = np.zeros_like(q)
    for k in range(len(q)):
        current = vector()
        lib.get_currents(vector(*q[k]), vector(*v[k]), vector(*a[k]), current)
        rigid[k] = current[:]
    friction = c["f_v"] * v + c["f_o"] + c["f_c"] / (1.0 + np.exp(-c["alpha"] * (v + c["ni"])))
    return c["K"] * (rigid + friction)


def main() -> None:
    if len(sys.argv) != 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0 if len(sys.argv) == 2 else 2)
    checkout = Path(sys.argv[1])
    states = read_joint_states(BAG)
    dt = float(np.median(np.diff(states.t_s)))
    a = lowpass(differentiate(states.qd_rad_s, dt), ACCELERATION_CUTOFF_HZ, 1.0 / dt)
    held_out = held_out_messages(len(states.t_s))
    with tempfile.TemporaryDirectory() as folder:
        lib = compiled_currents(checkout, Path(folder))
        tau = torques(lib, constants(checkout), states.q_rad[held_out], states.qd_rad_s[held_out], a[held_out])
    error = tau - states.effort_Nm[held_out]
    per_joint = np.sqrt(np.mean(error ** 2, axis=0))
    print(f"held-out messages {held_out.start}-{held_out.stop - 1} of {len(states.t_s)}")
    print("torque RMS per joint (N m): " + " ".join(f"{x:.3f}" for x in per_joint))
    print(f"over all joints (N m): {np.sqrt(np.mean(error ** 2)):.3f}")


if __name__ == "__main__":
    main()
