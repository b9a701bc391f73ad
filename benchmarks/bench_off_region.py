"""A recorded calibration judged off its training region: a laser record of an arm from the
public corpus, its training poses inside the middle of every joint range and its test poses over
the whole range, each run through the runner with the defaults as a user makes it.

Run: ``.venv/bin/python benchmarks/bench_off_region.py [--arms xarm7,ur10] [--amplitudes 0,3e-4,1e-3]
[--seed 1] [--poses 215] [--tests 20] [--inner 0.8]`` (about 20 s per run). An arm is a corpus name
(:mod:`pipeline.robot.public_arms`) or the path of a URDF of one's own (its meshes found beside it
or through ``ROS_PACKAGE_PATH``).

Per arm (``robot init`` on its URDF, no options) and per amplitude of the hidden arm's cyclic gear
transmission error (rad, joint side; the joints 5 times as compliant as stated when it is not 0,
:class:`pipeline.sim.truth.TruthConfig`): ``--poses`` training readings at random feasible
configurations whose every joint lies in the middle ``--inner`` of the range the feasible
configurations span, ``--tests`` readings at random feasible configurations over the whole range
(so most test poses lie where no training pose was measured), the tracker's noise from
``robot.yaml``. ``python -m pipeline run --stages calibration`` with the training file as
``calibration.measurements_csv`` and the test file as ``calibration.validation_csv``, in a fresh
interpreter. Printed: the exit code, the model chosen, the held-out RMS position error before and
after calibration, the held-out actual/predicted RMS against the range [0.67, 1.5] a user may expect
and the gate's upper bound for that many poses.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
from pathlib import Path

import numpy as np
from bench_heldout_protocols import run_split, summary_of
from bench_help import exit_on_help

from pipeline.calibration import candidates as cd
from pipeline.calibration import measure as ms
from pipeline.robot.model import RobotModel
from pipeline.robot.public_arms import arm_file, corpus_arm
from pipeline.robot.yaml_init import write_robot_yaml
from pipeline.sim.truth import RealRobot, TruthConfig

#: the range a user may expect of the held-out actual/predicted RMS
EXPECTED_RATIO = (0.67, 1.5)
#: joint compliance factor of the hidden arm when it has a transmission error (a soft, cable-like drive)
SOFT_COMPLIANCE_SCALE = 5.0


def write_records(robot: RobotModel, real: RealRobot, n_train: int, n_test: int, inner: float,
                  rng: np.random.Generator, folder: Path) -> tuple[Path, Path]:
    """Training readings inside the middle ``inner`` of every joint's sampled range, test readings
    anywhere (module docstring), as the stage's CSV files."""
    chain = cd.chain_from_robot(robot)
    wanted = int(np.ceil(2.0 * n_train / inner ** robot.nq)) + n_test
    Q, _ = cd.random_candidates(chain, wanted, rng)
    lo, hi = Q.min(axis=0), Q.max(axis=0)
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    inside = np.flatnonzero(np.all(np.abs(Q - centre) <= inner * half, axis=1))
    if len(inside) < n_train:
        raise SystemExit(f"only {len(inside)} of {len(Q)} feasible configurations lie in the middle {inner:g} of "
                         f"the ranges; lower --poses or raise --inner")
    return ms.write_simulated_record(real, Q[inside[:n_train]], Q[rng.choice(len(Q), n_test, replace=False)],
                                     folder, rng)


def bench_arm(name: str, amplitude_rad: float, seed: int, n_train: int, n_test: int, inner: float,
              work: Path) -> str:
    """One arm and amplitude through the runner; its printed line."""
    given = Path(name)
    if given.suffix in (".urdf", ".xml"):           # an arm of one's own, not in the corpus
        if not given.is_file():
            return f"{name}: no such file"
        source: Path | None = given
        name = given.stem
    else:
        source = arm_file(corpus_arm(name))
        if source is None:
            return f"{name}: its package is not installed"
    robot_dir = work / f"{name}_{amplitude_rad:g}"
    robot_dir.mkdir()
    shutil.copy(source, robot_dir / "robot.urdf")
    write_robot_yaml(robot_dir / "robot.urdf")
    robot = RobotModel.load(robot_dir)
    truth = TruthConfig(transmission_error_amplitude_rad=amplitude_rad, joint_compliance_scale=SOFT_COMPLIANCE_SCALE
                        ) if amplitude_rad > 0 else TruthConfig()
    real = RealRobot.create(robot, seed, truth)
    train, test = write_records(robot, real, n_train, n_test, inner, np.random.default_rng(seed), robot_dir)
    run = run_split(robot_dir, train, test, robot_dir / "run")
    s = summary_of(robot_dir / "run") or {}
    before = s.get("heldout_rms_position_error_before_m")
    line = (f"{name:>10} {robot.nq} axes, transmission error {amplitude_rad:.0e} rad: exit {run.code}, chose "
            f"{run.parameters}")
    if run.rms_position_m is not None and before is not None:
        line += f"; held-out RMS {1e3 * before:.3f} -> {1e3 * run.rms_position_m:.3f} mm"
    if run.ratio is not None:
        lo, hi = EXPECTED_RATIO
        line += (f"; actual/predicted {run.ratio:.2f} ({'within' if lo <= run.ratio <= hi else 'outside'} "
                 f"[{lo}, {hi}]; the gate's bound {run.ratio_bound or float('nan'):.2f})")
    return line


def main() -> None:
    exit_on_help(__doc__)
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--arms", default="xarm7,ur10")
    parser.add_argument("--amplitudes", default="0,3e-4,1e-3")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--poses", type=int, default=215)
    parser.add_argument("--tests", type=int, default=20)
    parser.add_argument("--inner", type=float, default=0.8)
    args = parser.parse_args()
    print(f"training poses {args.poses} in the middle {args.inner:g} of every joint range, {args.tests} test poses "
          f"over the whole range, hidden arm seed {args.seed}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.arms.split(","):
            for amplitude in (float(a) for a in args.amplitudes.split(",")):
                print(bench_arm(name, amplitude, args.seed, args.poses, args.tests, args.inner, Path(tmp)), flush=True)


if __name__ == "__main__":
    main()
