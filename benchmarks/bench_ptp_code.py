"""Size, gcc time and speed of the PtP NLP's compiled code: derivatives in one call vs in batches.

Run: ``.venv/bin/python benchmarks/bench_ptp_code.py [robot] [gcc flag] [N]`` (defaults: rx130l, -O1,
the default profile's 50 intervals). Builds the NLP twice into a temporary cache, with all directional
derivatives of the RNEA propagated in one call (CasADi's default ``max_num_dir`` 64) and in batches of
:data:`pipeline.trajectory.ptp.DERIVATIVE_DIRECTIONS`, one gcc at a time. Prints the library size,
gcc's CPU time, the best time of the Lagrangian Hessian, the constraint Jacobian and the gradient
over interleaved repeats, the ratios batches / one call, and whether the three give the same bits.
"""

from __future__ import annotations

import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np
from bench_help import exit_on_help

from pipeline.robot.model import RobotModel
from pipeline.robot.symbolic import SymbolicRobot
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.ptp import DERIVATIVE_DIRECTIONS, PtpProblem

FUNCTIONS = ("nlp_hess_l", "nlp_jac_g", "nlp_grad")
REPEATS = 15


def _gcc_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main(robot_name: str = "rx130l", flag: str = "-O1", n_intervals: int = 50) -> None:
    os.environ["PIPELINE_JOBS"] = "1"       # one gcc at a time, as a run's background warm-up builds it
    robot = RobotModel.load(robot_name)
    pm, sym = PlanningModel.from_robot(robot), SymbolicRobot(robot)
    variants = {"one call": 64, f"batches of {DERIVATIVE_DIRECTIONS}": DERIVATIVE_DIRECTIONS}
    built: dict[str, tuple[dict[str, ca.Function], float, int]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, directions in variants.items():
            before = _gcc_cpu_s()
            problem = PtpProblem(pm, sym, n_intervals, cache_dir=Path(tmp), jit_flags=(flag, "-shared", "-fPIC"),
                                 derivative_directions=directions)
            library = str(problem.library)
            built[label] = ({name: ca.external(name, library) for name in FUNCTIONS}, _gcc_cpu_s() - before,
                            problem.library.stat().st_size)
        rng = np.random.default_rng(0)
        x = rng.standard_normal(problem.n_x)
        x[0] = 1.0
        p = np.abs(rng.standard_normal(problem.n_p))
        lam_g = rng.standard_normal(problem.n_g)
        args = {"nlp_hess_l": (x, p, 1.0, lam_g), "nlp_jac_g": (x, p), "nlp_grad": (x, p, 1.0, lam_g)}
        best = {label: dict.fromkeys(FUNCTIONS, np.inf) for label in built}
        for _ in range(REPEATS):
            for label, (functions, _, _) in built.items():
                for name in FUNCTIONS:
                    start = time.perf_counter()
                    functions[name].call([ca.DM(a) for a in args[name]])
                    best[label][name] = min(best[label][name], time.perf_counter() - start)
        outputs = {label: [[out.full() for out in functions[name].call([ca.DM(a) for a in args[name]])]
                           for name in FUNCTIONS] for label, (functions, _, _) in built.items()}
    print(f"PtP NLP of {robot_name}, {n_intervals} intervals, gcc {flag}")
    for label, (_, gcc_s, size) in built.items():
        times = ", ".join(f"{name} {best[label][name] * 1e3:.2f} ms" for name in FUNCTIONS)
        print(f"  {label:>14}: library {size / 1e6:.2f} MB, gcc {gcc_s:.1f} s CPU; {times}")
    base, new = built
    print(f"  ratio batches / one call: gcc CPU {built[new][1] / built[base][1]:.2f}, library "
          f"{built[new][2] / built[base][2]:.2f}, " + ", ".join(f"{name} {best[new][name] / best[base][name]:.2f}"
                                                    for name in FUNCTIONS))
    same = all(np.array_equal(a, b) for fa, fb in zip(outputs[base], outputs[new], strict=True)
               for a, b in zip(fa, fb, strict=True))
    print(f"  same bits: {'yes' if same else 'NO'}")


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(*(sys.argv[1:2] or ["rx130l"]), *(sys.argv[2:3] or ["-O1"]), *(int(a) for a in sys.argv[3:4]))
