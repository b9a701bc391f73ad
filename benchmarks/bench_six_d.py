"""What a small 6-D (motion-capture) record can give: held-out position and orientation gains.

Run: ``.venv/bin/python benchmarks/bench_six_d.py [--quick]`` (about 40 s; ``--quick``: two seeds).

For each seed of the default hidden robot (joint elasticity, masses, gear error; RX130L seeds
8-12 and one TX40 seed) a random 6-D record (:func:`pipeline.papers.calib_six_d.simulate_six_d_record`)
is calibrated with ``all`` parameters through the stage, read as a user file
(:func:`pipeline.papers.calib_six_d.six_d_trial`), and validated on 200 exact poses. Settings:

* ``23 @ 1 mrad``: 23 poses, 0.1 mm / 1 mrad per axis (mocap-like);
* ``23 @ 0.3 mrad``: the same poses' count with a 0.3 mrad orientation noise;
* ``92 @ 1 mrad``: four times the poses at 1 mrad.

Printed per run: RMS of the held-out position and orientation errors of the nominal model
(registered) and of the calibrated one, their ratios (gains), and for the orientation

* ``pred``: the covariance-predicted RMS of the calibrated model's orientation error
  (:func:`pipeline.calibration.validate.predicted_orientation_covariance`, model part: the poses
  are exact; with the gravity-model term), i.e. the expected value of ``after``;
* ``CRB``: the Cramer-Rao bound of the same figure: parameter covariance
  ``(sum J_p^T J_p / sigma_p^2 + J_w^T J_w / sigma_rot^2)^-1`` of the six independent equations of
  each pose (position; orientation ``J_w`` = :func:`pipeline.calibration.validate.orientation_jacobian`),
  exact gravity model. No unbiased estimator of these parameters from this record does better in
  expectation (the stage's three-point fit, which weights the virtual points as independent and so
  counts the rotation about the marker z axis twice, comes within a few per cent of it);
* ``N(5x)`` and ``sig(5x)``: the pose count (at this noise) and the orientation noise (at this pose
  count) at which the bound reaches a 5x gain, by its exact ``sigma_rot / sqrt(N)`` scaling
  (``N (CRB / (before / 5))^2`` and ``sigma_rot (before / 5) / CRB``; the position rows carry little
  of the orientation).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_help import exit_on_help

from pipeline.calibration import validate as va
from pipeline.calibration.elastostatic import measurement_model
from pipeline.papers.calib_six_d import SixDTrial, six_d_trial
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot

SETTINGS = (("23 @ 1 mrad", 23, 1e-3), ("23 @ 0.3 mrad", 23, 3e-4), ("92 @ 1 mrad", 92, 1e-3))
POSITION_SIGMA_M = 1e-4
TARGET_GAIN = 5.0


def cramer_rao_orientation_rms(robot: RobotModel, trial: SixDTrial, orientation_sigma_rad: float) -> float:
    """RMS over the validation poses of the orientation error's Cramer-Rao bound (module docstring)."""
    est = trial.outcome.estimate
    mm = measurement_model(robot, trial.config, marker_points=True)
    Q = trial.fit.Q
    _, Jp = mm.jacobian(Q, est.x, est.registration, est.basis)
    Jw = va.orientation_jacobian(mm, est, Q)
    info = (np.einsum("nip,niq->pq", Jp, Jp) / POSITION_SIGMA_M ** 2
            + np.einsum("nip,niq->pq", Jw, Jw) / orientation_sigma_rad ** 2)
    Jv = va.orientation_jacobian(mm, est, trial.validation.Q)
    return float(np.sqrt(np.mean(np.einsum("nip,pq,niq->n", Jv, np.linalg.inv(info), Jv))))


def main(argv: list[str]) -> None:
    quick = "--quick" in argv
    cases = [("rx130l", s) for s in ((8, 9) if quick else (8, 9, 10, 11, 12))] + [("staubli_tx40", 3)]
    t0 = time.perf_counter()
    print(f"6-D calibration, 'all' parameters, default hidden robot, position noise {1e3 * POSITION_SIGMA_M:.1f} mm;"
          " validation on 200 exact poses. Position in mm, orientation in mrad.")
    print("N(5x), sig(5x): poses at this noise, noise (mrad) at this pose count for a 5x orientation gain at the "
          "Cramer-Rao bound.")
    head = (f"{'robot':>12} {'seed':>4} {'setting':>13} | {'pos nom':>7} {'after':>6} {'gain':>5} | {'ori nom':>7} "
            f"{'after':>6} {'gain':>5} | {'pred':>6} {'gain':>5} | {'CRB':>6} {'gain':>5} {'N(5x)':>5} {'sig(5x)':>7}")
    print(head)
    print("-" * len(head))
    gains: dict[str, list[tuple[float, float, float]]] = {s[0]: [] for s in SETTINGS}
    with tempfile.TemporaryDirectory() as tmp:
        for name, seed in cases:
            robot = RobotModel.load(name)
            real = RealRobot.create(robot, seed)
            for label, n, sigma_rad in SETTINGS:
                trial = six_d_trial(robot, real, n, np.random.default_rng(seed), Path(tmp) / f"{name}_{seed}_{n}",
                                    POSITION_SIGMA_M, sigma_rad)
                g = trial.gains
                crb = cramer_rao_orientation_rms(robot, trial, sigma_rad)
                before, pred = g["orientation_before_rad"], g["orientation_predicted_rad"]
                n5 = n * (crb / (before / TARGET_GAIN)) ** 2
                sigma5 = sigma_rad * (before / TARGET_GAIN) / crb
                if name == "rx130l":
                    gains[label].append((g["orientation_gain"], before / pred, before / crb))
                print(f"{name:>12} {seed:>4} {label:>13} | {1e3 * g['position_before_m']:7.3f} "
                      f"{1e3 * g['position_after_m']:6.3f} {g['position_gain']:5.1f} | {1e3 * before:7.3f} "
                      f"{1e3 * g['orientation_after_rad']:6.3f} {g['orientation_gain']:5.1f} | {1e3 * pred:6.3f} "
                      f"{before / pred:5.1f} | {1e3 * crb:6.3f} {before / crb:5.1f} {n5:5.0f} {1e3 * sigma5:7.2f}",
                      flush=True)
    print("\nRX130L, mean over seeds of the orientation gain (actual / predicted / Cramer-Rao bound), "
          f"seeds reaching {TARGET_GAIN:.0f}x (actual):")
    for label, rows in gains.items():
        a = np.asarray(rows)
        print(f"  {label:>13}: {a[:, 0].mean():4.1f} / {a[:, 1].mean():4.1f} / {a[:, 2].mean():4.1f}   "
              f"{int(np.sum(a[:, 0] >= TARGET_GAIN))} of {len(a)}")
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(sys.argv[1:])
