"""The calibration stage's design table on several seeds: the chosen design against every (N/n)-th.

Run: ``PIPELINE_CACHE_DIR=... .venv/bin/python benchmarks/bench_design_seeds.py [--seeds 1 2 3 4 5]
[--repeats 8] [--set calibration_field=value ...]`` (the default run's calibration stage and the
repeats, about 40-60 s per seed on one core).

Per seed the stage runs as ``python -m pipeline run --set seed=N --set "stages=[model,calibration]"``
does (the stage's random stream, the hidden robot of the seed, the robot's ISO 9283 cube) and its
design table (:mod:`pipeline.calibration.design_table`) gives, for the chosen design and the every
(N/n)-th baseline of the same size:

- the *actual* model RMS (held-out RMS with the tracker noise removed) and their ratio, the
  acceptance figure: one calibration per design, one draw of each design's estimation error;
- the same over ``--repeats`` further calibrations of each design (``calibration.design_table_repeats``:
  fresh tracker noise, weighted least squares), the design's expected figure, and its ratio;
- the *verified prediction* ``sqrt(trace(W_h M^-1))`` at the same held-out poses from the
  configurations each design had measured (same noise model for both), and the certified bound of
  :mod:`pipeline.calibration.design_bound` on it over the whole candidate pool: ``bound / spread``
  is the largest expected ratio gain that any design of that size has on that seed;
- the *remainder* the calibrated model cannot reach, read from the truth (a benchmark may open it):
  the RMS change of the noise-free reflector readings at visible working poses when the hidden arm's
  cyclic transmission error is switched off. It adds to every design's actual figure alike, so it
  pulls every ratio towards 1: ``sqrt((pred_chosen^2 + r^2) / (pred_spread^2 + r^2))`` is the ratio
  the predictions expect.

and the selection's own criterion (the ``V`` of ``calibration.design_figure`` at the nominal
tracker pose, the figure the selector minimises) against its certified bound ``V*/n`` over the
candidate pool (:class:`pipeline.calibration.design.SelectionResult` ``bound_value``, from the
approximate design the selection starts from, equivalence-theorem gap
:data:`pipeline.calibration.design_rounding.START_TOL`): the rounded start, the chosen design, and
the configurations measured (``V`` of those the moved tracker saw, against ``V*/n`` of their number).
A chosen design near its own bound whose verified prediction is far from the verified bound is
limited by what it is designed for (the criterion), not by the search.

Printed per seed, then the means; a seed whose ratio is above 1 is flagged with its bound.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import fields

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import stage as st
from pipeline.calibration import task_space as ts
from pipeline.core.yaml12 import load_yaml
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot, TruthConfig
from pipeline.stage_api import stage_rng

SPREAD = "every (N/n)-th feasible candidate"
TARGET_MEAN_RATIO = 0.75


def remainder_rms_m(robot: RobotModel, real: RealRobot, seed: int, region: ts.WorkingRegion, n: int = 300) -> float:
    """RMS of the hidden arm's transmission error in the noise-free reflector readings at ``n``
    visible working poses (module docstring)."""
    rigid = RealRobot.create(robot, seed, TruthConfig(transmission_error_amplitude_rad=0.0))
    chain = cd.chain_from_robot(robot, real.transform_tracker_to_base)
    Q = ts.sample_region(robot, region, n, np.random.default_rng([seed, 3]), chain=chain, visibility=True)

    def readings(r: RealRobot) -> np.ndarray:
        return r.truth.positions(r.link_angles(Q), robot.frame_reflector)

    return float(math.sqrt(np.mean(np.sum((readings(real) - readings(rigid)) ** 2, axis=1))))


def seed_row(robot: RobotModel, seed: int, cfg: st.Config) -> dict:
    """The design table's figures of one seed (module docstring)."""
    real = RealRobot.create(robot, seed, TruthConfig())
    region = ts.default_region(robot)
    t0 = time.perf_counter()
    out = st.calibrate(robot, real, cfg, stage_rng(seed, "calibration"), None, region)
    table = out.design_table
    rows = {r["design"]: r for r in table["rows"]}
    chosen = next(r for label, r in rows.items() if label.startswith("chosen"))
    spread = rows[SPREAD]
    rem = remainder_rms_m(robot, real, seed, region)
    bound = (table.get("bound") or {}).get("bound_verified_rms_m", math.nan)
    pc, ps = chosen["predicted_verified_rms_m"], spread["predicted_verified_rms_m"]
    rc, rs = chosen.get("repeated_model_rms_m"), spread.get("repeated_model_rms_m")
    sel = out.selection
    v_bound = sel.bound_value if sel is not None and sel.bound_value else math.nan
    v_start = sel.start_value if sel is not None and sel.start_value is not None else math.nan
    n_meas = out.measured_design["n_configurations"] if out.measured_design else 0
    v_meas = out.measured_design["index_value"] if out.measured_design else math.nan
    return {"seed": seed, "n": chosen["n_configurations"], "n_spread": spread["n_measured"],
            "actual_chosen": chosen["actual_model_rms_m"], "actual_spread": spread["actual_model_rms_m"],
            "ratio": chosen["actual_model_rms_m"] / spread["actual_model_rms_m"],
            "repeated_chosen": rc, "repeated_spread": rs,
            "repeated_ratio": rc / rs if rc is not None and rs else math.nan,
            "pred_chosen": pc, "pred_spread": ps, "bound": bound, "remainder": rem,
            "expected_ratio": math.sqrt((pc**2 + rem**2) / (ps**2 + rem**2)),
            "bound_ratio": math.sqrt((bound**2 + rem**2) / (ps**2 + rem**2)),
            "tcp_chosen": chosen["predicted_tcp_rms_m"], "tcp_spread": spread["predicted_tcp_rms_m"],
            "heldout_after": out.validation["after"]["rms"] if out.validation else math.nan,
            "criterion_start": v_start / v_bound, "criterion_chosen": sel.index_value / v_bound if sel else math.nan,
            "criterion_measured": v_meas / (v_bound * len(sel.selected) / n_meas) if sel and n_meas else math.nan,
            "time_s": time.perf_counter() - t0}


def parse_set(items: list[str]) -> dict:
    """``field=value`` (YAML value) pairs of the calibration Config."""
    names = {f.name for f in fields(st.Config)}
    out = {}
    for item in items:
        key, _, value = item.partition("=")
        key = key.removeprefix("calibration.")
        if key not in names:
            raise SystemExit(f"unknown calibration field {key!r}")
        out[key] = load_yaml(value)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    ap.add_argument("--robot", default="rx130l")
    ap.add_argument("--repeats", type=int, default=8, help="calibration.design_table_repeats")
    ap.add_argument("--set", dest="sets", action="append", default=[], help="calibration field=value")
    args = ap.parse_args()
    robot = RobotModel.load(args.robot)
    cfg = st.Config(**({"design_table_repeats": args.repeats} | parse_set(args.sets)))
    um = 1e6
    print(f"{args.robot}, calibration {cfg.selection_method} on {cfg.index_name} ({cfg.design_figure}), "
          f"{cfg.n_configurations} configurations; µm")
    print("seed | measured | actual chosen / spread = ratio | repeated chosen / spread = ratio | verified prediction "
          "chosen / spread / bound | remainder | expected ratio (chosen, at the bound) | predicted TCP chosen / spread "
          "| criterion / its bound V*/n: rounded start, chosen, measured")
    rows = []
    for seed in args.seeds:
        r = seed_row(robot, seed, cfg)
        rows.append(r)
        flag = (f"  <- above 1: a design at the bound would expect {r['bound_ratio']:.2f}"
                if r["ratio"] > 1 else "")
        print(f"{seed:4d} | {r['n']:2d} / {r['n_spread']:2d} | {um * r['actual_chosen']:5.1f} / "
              f"{um * r['actual_spread']:5.1f} = {r['ratio']:.3f} | {um * (r['repeated_chosen'] or math.nan):5.1f} / "
              f"{um * (r['repeated_spread'] or math.nan):5.1f} = {r['repeated_ratio']:.3f} | "
              f"{um * r['pred_chosen']:5.2f} / "
              f"{um * r['pred_spread']:5.2f} / {um * r['bound']:5.2f} | {um * r['remainder']:4.1f} | "
              f"{r['expected_ratio']:.3f}, {r['bound_ratio']:.3f} | {um * r['tcp_chosen']:5.1f} / "
              f"{um * r['tcp_spread']:5.1f} | {r['criterion_start']:.3f}, {r['criterion_chosen']:.3f}, "
              f"{r['criterion_measured']:.3f}  ({r['time_s']:.0f} s){flag}", flush=True)

    def mean(key: str) -> float:
        return float(np.mean([r[key] for r in rows]))

    print(f"mean | ratio {mean('ratio'):.3f} (target <= {TARGET_MEAN_RATIO}) | repeated {mean('repeated_ratio'):.3f} "
          f"| expected {mean('expected_ratio'):.3f} "
          f"| a design at the bound {mean('bound_ratio'):.3f} | verified prediction chosen / bound "
          f"{mean('pred_chosen') / mean('bound'):.3f} | criterion / its bound: chosen {mean('criterion_chosen'):.3f}, "
          f"measured {mean('criterion_measured'):.3f} | held-out RMS after {um * mean('heldout_after'):.2f}")


if __name__ == "__main__":
    main()
