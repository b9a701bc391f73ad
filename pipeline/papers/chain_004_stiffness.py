"""Paper 004 Fig. 2(b) against the hidden RX130L's joint stiffness (study ``paper-004
--compliance-scales``).

Paper ``004_abbe750b8bbcc3aa.txt`` §2.3.3 / Fig. 2(b): on the EN ISO 9283 path at 1 m/s and 5 m/s²
the model-based (rigid-body) feedforward "drastically reduce[s] the TCP and joint errors". Its Table 2
calibrates the same arm with a purely geometric model to 0.27 / 0.31 / 0.41 mm. With the generic
joint stiffness of :mod:`pipeline.robot.stiffness` (``k = torque limit / 2 mrad``, 30 % spread;
:mod:`pipeline.sim.truth`) neither holds: the joints' gravity deflection, which the motor-side servo
does not see, dominates the TCP error whatever the feedforward. This experiment, with the one of
``calib-004``, set the RX130L's stated stiffness (``robots/rx130l/robot.yaml``: 60 µrad at the torque
limit, the rule's stiffness x 33); ``S = 33`` gives the rule back. It runs the chain up to the control stage (quick
sizes, the paper's settings of :data:`pipeline.papers.chain_004.PAPER_SETTINGS`) on hidden robots
whose joint compliance is scaled by ``S`` (``truth.joint_compliance_scale``: stiffness ``k / S``) and
reads the control stage's maximum TCP error along the ISO path without feedforward and with the
identified rigid-body feedforward (``full_friction``): the reduction ``none / full_friction`` against
the "drastic" threshold :data:`pipeline.papers.chain_004_rows.CLEAR_REDUCTION`. The Table 2 side of
the same stiffnesses is ``calib-004 --compliance-scale S``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from pipeline.core.config import RunConfig, load_config
from pipeline.papers.chain_004_rows import CLEAR_REDUCTION, Run

#: stages up to the one that reads Fig. 2(b)
STIFFNESS_STAGES = ("model", "calibration", "identification", "control")


def stiffness_config(seed: int, compliance_scale: float, config_path: Path, settings: dict) -> RunConfig:
    """The quick chain up to control on the default hidden robot with joint compliance × ``S``."""
    values = {"seed": seed, **settings, "truth.joint_compliance_scale": float(compliance_scale),
              "name": f"p004q_stiffness_{compliance_scale:g}_s{seed}"}
    return load_config(config_path, stages=list(STIFFNESS_STAGES), values=values)


def fig2b_point(run: Run) -> dict[str, float]:
    """Maximum TCP error (m) without and with the rigid-body feedforward, and their ratio."""
    s = run["control"].summary
    none, ff = s["tcp_error_max_m"]["none"], s["tcp_error_max_m"]["full_friction"]
    lag = np.asarray(s["lag_error_max_rad"]["none"]) / np.asarray(s["lag_error_max_rad"]["full_friction"])
    return {"tcp_error_max_none_m": float(none), "tcp_error_max_feedforward_m": float(ff),
            "tcp_reduction": float(none / ff), "lag_reduction_min_axes_1_3": float(lag.min())}


def run_stiffness(scales: Sequence[float], seeds: Sequence[int], run: Callable[[RunConfig], Run],
                  config: Callable[[int, float], RunConfig], say: Callable[[str], object] = print) -> list[dict]:
    """One point per (scale, seed): the Fig. 2(b) figures and the run time."""
    points = []
    for scale in scales:
        for seed in seeds:
            t0 = time.perf_counter()
            out = run(config(seed, scale))
            points.append({"compliance_scale": float(scale), "seed": seed, **fig2b_point(out),
                           "time_s": time.perf_counter() - t0})
            say(markdown(points[-1:]).splitlines()[-1])
    return points


def markdown(points: Sequence[dict]) -> str:
    """The table: stiffness factor, TCP max without / with feedforward, the reduction and whether it
    is "drastic" (at least :data:`CLEAR_REDUCTION`)."""
    lines = ["| joint compliance × S (stiffness × 1/S) | seed | max TCP error, no feedforward [mm] | "
             "with rigid-body feedforward [mm] | reduction | lag reduction, worst of axes 1-3 | "
             f"drastic (≥ {CLEAR_REDUCTION:g}×) |",
             "|---|---|---|---|---|---|---|"]
    for p in points:
        lines.append(f"| {p['compliance_scale']:g} | {p['seed']} | {p['tcp_error_max_none_m'] * 1e3:.3f} | "
                     f"{p['tcp_error_max_feedforward_m'] * 1e3:.3f} | {p['tcp_reduction']:.2f}× | "
                     f"{p['lag_reduction_min_axes_1_3']:.1f}× | "
                     f"{'yes' if p['tcp_reduction'] >= CLEAR_REDUCTION else 'no'} |")
    return "\n".join(lines)


def largest_drastic_scale(points: Sequence[dict]) -> float | None:
    """The largest compliance scale at which every seed's reduction is "drastic" (None: none is)."""
    ok = [s for s in {p["compliance_scale"] for p in points}
          if all(p["tcp_reduction"] >= CLEAR_REDUCTION for p in points if p["compliance_scale"] == s)]
    return max(ok) if ok else None
