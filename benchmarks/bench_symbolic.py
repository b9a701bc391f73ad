"""Evaluation time of the symbolic bridge: SX virtual machine vs gcc-compiled (JIT) functions.

Run: ``.venv/bin/python benchmarks/bench_symbolic.py [robot] [N]``. Prints compile time,
per-call times for rnea / regressor / mass matrix / fk, and for ``rnea.map(N)``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_help import exit_on_help

from pipeline.robot.model import RobotModel
from pipeline.robot.symbolic import SymbolicRobot


def _time(call, repeat: int) -> float:
    call()
    start = time.perf_counter()
    for _ in range(repeat):
        call()
    return (time.perf_counter() - start) / repeat


def main(robot_name: str = "rx130l", n_map: int = 400) -> None:
    robot = RobotModel.load(robot_name)
    rng = np.random.default_rng(0)
    nq = robot.nq
    q, v, a = rng.normal(0, 1, (3, nq))
    qm, vm, am = rng.normal(0, 1, (3, nq, n_map))
    with tempfile.TemporaryDirectory() as tmp:
        sx = SymbolicRobot(robot)
        start = time.perf_counter()
        jit = SymbolicRobot(robot, jit=True, cache_dir=Path(tmp))
        p = sx.nominal_dynamic_parameters()
        z = np.zeros(sx.n_kin)
        names = {
            "rnea": lambda s: s.rnea(q, v, a, p),
            "regressor": lambda s: s.regressor(q, v, a),
            "mass_matrix": lambda s: s.mass_matrix(q, p),
            "fk tcp": lambda s: s.fk("tcp")(q, z),
            "fk_position_jacobian": lambda s: s.fk_position_jacobian("tcp")(q, z),
        }
        for call in names.values():
            call(jit)  # compile
        rnea_map_sx = sx.rnea.map(n_map)
        rnea_map_jit = jit.rnea.map(n_map)
        compile_s = time.perf_counter() - start
        print(f"{robot_name}: compile of {len(names)} functions with gcc -O2: {compile_s:.1f} s")
        for name, call in names.items():
            t_sx = _time(lambda c=call: c(sx), 2000)
            t_jit = _time(lambda c=call: c(jit), 2000)
            print(f"  {name:22s} SX {t_sx * 1e6:8.1f} us   JIT {t_jit * 1e6:8.1f} us   "
                  f"ratio {t_sx / t_jit:5.1f}")
        t_sx = _time(lambda: rnea_map_sx(qm, vm, am, p), 50)
        t_jit = _time(lambda: rnea_map_jit(qm, vm, am, p), 50)
        print(f"  rnea.map({n_map})          SX {t_sx * 1e3:8.3f} ms   JIT {t_jit * 1e3:8.3f} ms   "
              f"ratio {t_sx / t_jit:5.1f}")
        print(f"  instructions: rnea {sx.rnea.n_instructions()}, regressor {sx.regressor.n_instructions()}, "
              f"M {sx.mass_matrix.n_instructions()}")


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(*(sys.argv[1:2] or ["rx130l"]), *(int(x) for x in sys.argv[2:3]))
