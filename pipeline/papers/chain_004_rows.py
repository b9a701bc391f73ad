"""The headline results of paper 004 §2.3.3, §4.3 and §5 beside ours (study ``paper-004``).

Paper ``004_abbe750b8bbcc3aa.txt``: its figures' values were lost in the extraction; what the
text states is quoted in each row's ``paper`` column. Every number of ours is read from what the
pipeline's stages stored (``summary.json``, ``results.npz``) of one or more seeds: a single seed
prints the value, several print mean ± standard error (n = number of seeds). A verdict names the
property the paper states and, where ours differ, the experiment of the study that shows why.

Thresholds (stated once, here):
- "clearly observable" lag reduction (Fig. 2a) and "drastically reduce" TCP errors (Fig. 2b):
  feedforward divides the maximum error by at least :data:`CLEAR_REDUCTION` (2).
- "good parameter identification" (Fig. 5b): validation torque RMS within
  :data:`TORQUE_MATCH_OVER_NOISE` (2) times the torque noise on every joint (the identification
  stage's own quality gate).
- "at least one constraint is always active" (Fig. 8): a limit at >= 98 % on at least
  :data:`ACTIVE_GRID_FRACTION` (99 %) of the CP grid points.
- "velocities up to 5 m/s and accelerations up to 12 m/s^2" (§4.3): the excitation reaches at
  least :data:`REACHED_FRACTION` (80 %) of them without exceeding them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from pipeline.stage_api import StageOutput

CLEAR_REDUCTION = 2.0
TORQUE_MATCH_OVER_NOISE = 2.0
ACTIVE_GRID_FRACTION = 0.99
REACHED_FRACTION = 0.8
#: the paper's excitation figures (§4.3) and ISO 9283 settings (§2.3.3)
PAPER_TCP_SPEED_M_S = 5.0
PAPER_TCP_ACCELERATION_M_S2 = 12.0
PAPER_ISO_SPEED_M_S = 1.0
PAPER_ISO_ACCELERATION_M_S2 = 5.0
PAPER_SAMPLE_TIME_S = 4e-4

Run = dict[str, StageOutput]


@dataclass
class Row:
    """One headline of the paper: what it states, ours, the verdict."""

    key: str
    item: str
    paper: str
    ours: str
    verdict: str
    values: dict[str, list[float]] = field(default_factory=dict)   # per seed

    def to_dict(self) -> dict:
        return {"key": self.key, "item": self.item, "paper": self.paper, "ours": self.ours,
                "verdict": self.verdict, "values": self.values}


def stat(xs: Sequence[float], scale: float = 1.0, digits: int = 3) -> str:
    """``mean`` (one seed) or ``mean ± standard error (n)``, scaled."""
    x = np.asarray(xs, float) * scale
    if x.size == 1:
        return f"{x[0]:.{digits}g}"
    se = x.std(ddof=1) / np.sqrt(x.size)
    return f"{x.mean():.{digits}g} ± {se:.2g} (n={x.size})"


def _mean(xs: Sequence[float]) -> float:
    return float(np.mean(xs))


def _col(summaries: Sequence[dict], key: str) -> list:
    return [s[key] for s in summaries]


def _ctl(runs: Sequence[Run]) -> list[dict]:
    return [r["control"].summary for r in runs]


# ---------------------------------------------------------------------------------- settings
def settings_rows(runs: Sequence[Run]) -> list[Row]:
    """§2.3.2/§2.3.3: 400 µs loop, ISO 9283 at 1 m/s and 5 m/s^2."""
    ctl = _ctl(runs)
    peak = []
    for r in runs:
        s, t = r["control"].arrays["iso_path_s_m"], r["control"].arrays["iso_t_s"]
        peak.append(float(np.max(np.diff(s) / np.diff(t))))
    dt = [c["sample_time_s"] for c in ctl]
    return [Row("iso_settings", "§2.3.3 control loop and ISO 9283 path",
                f"{PAPER_SAMPLE_TIME_S * 1e6:.0f} µs loop; TCP {PAPER_ISO_SPEED_M_S:g} m/s, "
                f"{PAPER_ISO_ACCELERATION_M_S2:g} m/s²",
                f"{stat(dt, 1e6)} µs loop; TCP {stat([c['tcp_speed_m_s'] for c in ctl])} m/s "
                f"(peak along the path {stat(peak)} m/s), {stat([c['tcp_acceleration_m_s2'] for c in ctl])} m/s²",
                "same setting" if abs(_mean(dt) - PAPER_SAMPLE_TIME_S) < 1e-9
                and abs(_mean(peak) - PAPER_ISO_SPEED_M_S) < 0.02 else "differs: settings",
                {"sample_time_s": dt, "iso_peak_speed_m_s": peak})]


# ---------------------------------------------------------------------------------- §4.3
#: limits of the excitation's fine-grid check (results.json excitation.feasibility, ratio <= 1)
EXCITATION_LIMITS = {"position_ratio": "joint range", "velocity_ratio": "joint speed",
                     "acceleration_ratio": "joint acceleration", "torque_ratio": "nominal torque"}


def binding_limits(run: Run, level: float = 0.95) -> str:
    """The excitation's limits at >= ``level`` of their bound (what holds its amplitude)."""
    feas = run["identification"].data.get("excitation", {}).get("feasibility", {})
    hits = [f"{name} {feas[k]:.2f}" for k, name in EXCITATION_LIMITS.items() if feas.get(k, 0.0) >= level]
    return ", ".join(hits) or "none (the criterion sets the amplitude)"


def excitation_row(runs: Sequence[Run], full_torque: Sequence[Run]) -> Row:
    """§4.3: the excitation reached 5 m/s and 12 m/s^2 at the TCP (bounds of the NLP here)."""
    ids = [r["identification"].summary for r in runs]
    v = [s.get("excitation_tcp_speed_max_m_s") for s in ids]
    a = [s.get("excitation_tcp_acceleration_max_m_s2") for s in ids]
    paper = f"up to {PAPER_TCP_SPEED_M_S:g} m/s and {PAPER_TCP_ACCELERATION_M_S2:g} m/s²"
    if None in v or None in a:
        return Row("excitation_tcp", "§4.3 excitation at the TCP", paper, "not reported (user data)", "not compared")
    vb = ids[0].get("excitation_tcp_speed_bound_m_s")
    ab = ids[0].get("excitation_tcp_acceleration_bound_m_s2")
    cond = stat([s["cond_optimized"] for s in ids])
    cond_random = stat([s["cond_random_median"] for s in ids])
    ours = (f"{stat(v)} m/s and {stat(a)} m/s² (bounds {vb} m/s, {ab} m/s²); cond {cond} vs random median "
            f"{cond_random}; limits at ≥ 95 % (seed 1): {binding_limits(runs[0])}")
    values: dict[str, list[float]] = {"tcp_speed_max_m_s": v, "tcp_acceleration_max_m_s2": a}
    reached = _mean(v) >= REACHED_FRACTION * PAPER_TCP_SPEED_M_S and \
        _mean(a) >= REACHED_FRACTION * PAPER_TCP_ACCELERATION_M_S2
    within = max(v) <= PAPER_TCP_SPEED_M_S * 1.001 and max(a) <= PAPER_TCP_ACCELERATION_M_S2 * 1.001
    if full_torque:
        ft = [r["identification"].summary for r in full_torque]
        values["tcp_speed_max_full_torque_m_s"] = _col(ft, "excitation_tcp_speed_max_m_s")
        values["tcp_acceleration_max_full_torque_m_s2"] = _col(ft, "excitation_tcp_acceleration_max_m_s2")
        ours += (f"; with the whole torque limit (experiment 'full torque'): "
                 f"{stat(values['tcp_speed_max_full_torque_m_s'])} m/s and "
                 f"{stat(values['tcp_acceleration_max_full_torque_m_s2'])} m/s², "
                 f"cond {stat(_col(ft, 'cond_optimized'))}"
                 f"; limits at ≥ 95 %: {binding_limits(full_torque[0])}")
    if reached and within:
        verdict = "reproduced (the TCP bounds are reached)"
    elif not within:
        verdict = "differs: the excitation exceeds the paper's figures (no TCP bound set)"
    else:
        verdict = (f"differs: the condition-number optimum stays at {_mean(v) / PAPER_TCP_SPEED_M_S:.0%} of the "
                   f"paper's speed and {_mean(a) / PAPER_TCP_ACCELERATION_M_S2:.0%} of its acceleration")
        if full_torque and _mean(values["tcp_speed_max_full_torque_m_s"]) <= 1.05 * _mean(v):
            verdict += (": the torque bound is active, yet the whole torque limit does not raise the speed "
                        "(experiment 'full torque'): the criterion cond(W) spends the torque elsewhere; the "
                        "paper's trajectory parameters (period, harmonics) that gave 5 m/s were lost in extraction")
        elif full_torque:
            verdict += ": held by the torque limits (estimates); the whole limit raises it (experiment 'full torque')"
        else:
            verdict += ", held by the limits listed"
    return Row("excitation_tcp", "§4.3 excitation at the TCP", paper, ours, verdict, values)


# ---------------------------------------------------------------------------------- Fig. 2
def _ratio(ctl: Sequence[dict], key: str, a: str, b: str) -> list[float]:
    return [c[key][a] / c[key][b] for c in ctl]


def fig2_rows(runs: Sequence[Run], rigid: Sequence[Run]) -> list[Row]:
    """Fig. 2(a) lag errors of axes 1-3, Fig. 2(b) TCP errors, with and without feedforward."""
    ctl = _ctl(runs)
    lag_none = np.array([c["lag_error_max_rad"]["none"] for c in ctl])          # (seeds, 3)
    lag_ff = np.array([c["lag_error_max_rad"]["full_friction"] for c in ctl])
    red = lag_none / lag_ff
    ours = "; ".join(f"axis {j + 1}: {stat(lag_none[:, j], 1e3)} → {stat(lag_ff[:, j], 1e3)} mrad "
                     f"({stat(red[:, j])}×)" for j in range(3))
    nominal = [c["lag_error_max_rad"].get("full_friction_nominal") for c in ctl]
    if all(n is not None for n in nominal):
        nom = np.array(nominal)
        ours += (f"; nominal-model feedforward: {stat(lag_none.max(1) / nom.max(1))}× (identified "
                 f"{stat(lag_none.max(1) / lag_ff.max(1))}×, worst axis)")
    lag_values = {f"lag_reduction_axis{j + 1}": red[:, j].tolist() for j in range(3)}
    if rigid:
        rc_lag = _ctl(rigid)
        red_rigid = (np.array([c["lag_error_max_rad"]["none"] for c in rc_lag])
                     / np.array([c["lag_error_max_rad"]["full_friction"] for c in rc_lag]))
        ours += "; rigid hidden robot: " + ", ".join(f"axis {j + 1} {stat(red_rigid[:, j])}×" for j in range(3))
        lag_values |= {f"lag_reduction_rigid_axis{j + 1}": red_rigid[:, j].tolist() for j in range(3)}
    verdict = ("reproduced" if red.mean(0).min() >= CLEAR_REDUCTION else
               f"differs: feedforward reduces the lag by less than {CLEAR_REDUCTION:g}× on some axis")
    rows = [Row("fig2a_lag", "Fig. 2(a) lag errors, axes 1-3, ISO path (max)",
                "feedforward: \"positive influence clearly observable\" (values lost in extraction)",
                ours, verdict, lag_values)]

    tcp = _ratio(ctl, "tcp_error_max_m", "none", "full_friction")
    trk = _ratio(ctl, "tcp_tracking_error_max_m", "none", "full_friction")
    ours = (f"max TCP error {stat([c['tcp_error_max_m']['none'] for c in ctl], 1e3)} → "
            f"{stat([c['tcp_error_max_m']['full_friction'] for c in ctl], 1e3)} mm ({stat(tcp)}×); "
            f"control's part (vs the static pose at the reference) {stat(trk)}×")
    values: dict[str, list[float]] = {"tcp_reduction": tcp, "tcp_tracking_reduction": trk}
    elastic = [c["tcp_tracking_error_max_m"].get("elastic_static") for c in ctl]
    if all(e is not None for e in elastic):
        el = [c["tcp_tracking_error_max_m"]["none"] / e for c, e in zip(ctl, elastic, strict=True)]
        ours += f"; elastic_static feedforward (gravity deflection compensated) {stat(el)}×"
        values["tcp_tracking_reduction_elastic_static"] = el
    rig = None
    if rigid:
        rc = _ctl(rigid)
        rig = _ratio(rc, "tcp_error_max_m", "none", "full_friction")
        ours += (f"; rigid hidden robot (TruthConfig.ideal()): {stat([c['tcp_error_max_m']['none'] for c in rc], 1e3)}"
                 f" → {stat([c['tcp_error_max_m']['full_friction'] for c in rc], 1e3)} mm ({stat(rig)}×)")
        values["tcp_reduction_rigid"] = rig
    if _mean(tcp) >= CLEAR_REDUCTION:
        verdict = ("matched by construction: the RX130L's joint stiffness (robots/rx130l/robot.yaml) is the one the "
                   "stiffness experiment (paper-004 --compliance-scales, calib-004 --compliance-scale) found to fit "
                   "this figure and Table 2")
    elif rig is not None and _mean(rig) >= CLEAR_REDUCTION:
        verdict = (f"differs on the elastic hidden robot ({_mean(tcp):.2f}×): the joints' gravity deflection, "
                   "which the motor-side servo cannot see and a rigid-body feedforward does not compensate, "
                   f"dominates the TCP error; on the rigid hidden robot (experiment 'rigid') feedforward reduces "
                   f"it {_mean(rig):.1f}× as the paper states")
    else:
        verdict = (f"differs: feedforward reduces the max TCP error only {_mean(tcp):.2f}× "
                   + ("" if rig is None else f"(rigid hidden robot {_mean(rig):.2f}×)"))
    rows.append(Row("fig2b_tcp", "Fig. 2(b) TCP errors along the ISO path (max)",
                    "feedforward \"drastically reduce[s] the TCP and joint errors\" (values lost)", ours, verdict,
                    values))
    return rows


# ---------------------------------------------------------------------------------- Fig. 5
def fig5_row(runs: Sequence[Run]) -> Row:
    """Fig. 5(b): measured vs model-predicted motor torques on the ISO 9283 reference."""
    ids = [r["identification"].summary for r in runs]
    rel = np.array([s["validation_relative_error"] for s in ids])      # (seeds, nq)
    over = np.array([s["validation_rms_over_noise"] for s in ids])
    rms = np.array([s["validation_torque_rms_Nm"] for s in ids])
    nq = rel.shape[1]
    ours = "; ".join(f"j{j + 1} {stat(rms[:, j], digits=2)} N·m ({stat(rel[:, j], 100, 2)} %, "
                     f"{stat(over[:, j], digits=3)}× noise)" for j in range(nq))
    ours = f"on '{ids[0]['validation_trajectory']}': torque RMS error " + ours
    ok = over.mean(0).max() <= TORQUE_MATCH_OVER_NOISE
    verdict = ("reproduced: the identified model predicts the measured torques to within the noise on every "
               "joint (4-6 included)" if ok else
               f"differs: validation RMS above {TORQUE_MATCH_OVER_NOISE:g}× the noise on some joint")
    return Row("fig5_torques", "Fig. 5(b) measured vs predicted motor torques (validation on ISO 9283)",
               "\"good parameter identification\"; joints 4-6 \"equivalent quality\" (values lost)", ours, verdict,
               {"rms_over_noise_worst": over.max(1).tolist(), "relative_error_worst": rel.max(1).tolist()})


# ---------------------------------------------------------------------------------- Fig. 8
def _constraining_axes(run: Run) -> str:
    """Axes whose torque or speed is at >= 98 % of its limit for >= 5 % of the CP's duration."""
    tr, vr = run["trajectory"].arrays["cp_torque_ratio"], run["trajectory"].arrays["cp_velocity_ratio"]
    parts = []
    for j in range(tr.shape[1]):
        t, v = float(np.mean(tr[:, j] >= 0.98)), float(np.mean(vr[:, j] >= 0.98))
        if max(t, v) >= 0.05:
            parts.append(f"j{j + 1} " + ", ".join(x for x, f in (("torque", t), ("speed", v)) if f >= 0.05))
    return "; ".join(parts) or "none"


def torque_scale(run: Run) -> np.ndarray:
    """Per-joint factor on the torque limits the time-optimal CP was last solved with (< 1: the
    trajectory stage tightened a limit after its fine-grid torque check)."""
    info = run["trajectory"].data.get("cp_info", {}).get("refined", {}) or {}
    scale = info.get("torque_scale")
    return np.ones(run["trajectory"].arrays["cp_torque_ratio"].shape[1]) if scale is None else np.asarray(scale)


def _scale_text(runs: Sequence[Run]) -> tuple[str, float]:
    scales = np.array([torque_scale(r) for r in runs])          # (seeds, nq)
    low = scales.min(0)
    parts = [f"j{j + 1} {stat(scales[:, j], 100, 2)} %" for j in np.flatnonzero(low < 0.99)]
    return ("torque limits as solved: " + (", ".join(parts) if parts else "all 100 %")), float(low.min())


def fig8_rows(runs: Sequence[Run], acc: Sequence[Run]) -> list[Row]:
    """Fig. 8: time-optimal CP, normalised torques/velocities, one limit active at every instant."""
    tj = [r["trajectory"].summary for r in runs]
    frac = _col(tj, "cp_grid_active_fraction")
    low = _col(tj, "cp_grid_min_activity")
    fine = _col(tj, "cp_active_fraction")
    scale_text, scale_min = _scale_text(runs)
    ours = (f"{tj[0]['cp_segment']} ({tj[0]['cp_path_length_m']:.3f} m) in {stat(_col(tj, 'cp_duration_s'))} s "
            f"(toppra {stat(_col(tj, 'cp_toppra_duration_s'))} s); grid points with a torque or speed limit "
            f"≥ 98 %: {stat(frac, 100)} %, lowest level {stat(low)} ({scale_text}); share of the fine time grid "
            f"at ≥ 98 % of the real limits {stat(fine, 100)} %; constraining (seed 1): {_constraining_axes(runs[0])}")
    values = {"grid_active_fraction": frac, "grid_min_activity": low, "fine_active_fraction": fine,
              "torque_scale_min": [float(torque_scale(r).min()) for r in runs]}
    if acc:
        ta = [r["trajectory"].summary for r in acc]
        values["grid_active_fraction_with_acceleration_limits"] = _col(ta, "cp_grid_active_fraction")
        ours += (f"; with joint acceleration limits as well (the pipeline's default): "
                 f"{stat(values['grid_active_fraction_with_acceleration_limits'], 100)} % of grid points at a torque "
                 f"or speed limit (the others held by an acceleration limit), duration "
                 f"{stat(_col(ta, 'cp_duration_s'))} s, {_scale_text(acc)[0]}")
    if _mean(frac) < ACTIVE_GRID_FRACTION:
        verdict = (f"differs: a torque or speed limit is active at only {_mean(frac):.1%} of the grid points"
                   + (" (acceleration limits on)" if tj[0].get("cp_acceleration_limits") else ""))
    elif scale_min >= 0.99:
        verdict = "reproduced"
    else:
        costs = [s.get("cp_smooth_time_cost") for s in tj]
        known = [float(c) for c in costs if c is not None]
        faster = len(known) == len(costs) > 0 and _mean(known) < 0
        verdict = (f"differs: holds on the solver's grid against the tightened limits only; the trajectory stage's "
                   f"fine-grid check found torque "
                   f"peaks between grid points and re-solved with a joint's whole torque limit scaled down (to "
                   f"{scale_min:.0%}), so against the real limits a limit is active {_mean(fine):.0%} of the time "
                   + ("and the profile is not time-optimal (the jerk-limited plan is faster, next row)" if faster else
                      "(the jerk-limited plan is still slower, next row)")
                   + "; a limitation of the stage's tightening without acceleration limits, not of the paper's method")
    rows = [Row("fig8_cp_active", "Fig. 8 time-optimal CP: normalised torques and speeds",
                "\"at least one constraint is always active\" (necessary for time optimality)", ours, verdict,
                values)]
    sm = [s.get("cp_smooth_time_cost") for s in tj]
    if all(x is not None for x in sm):
        cost = _mean(sm)
        rows.append(Row("cp_smooth", "§5 continuous velocities, accelerations and jerks (CP)",
                        "needed \"so that the gear elasticities are not overly excited\"",
                        f"jerk-limited CP duration {stat(sm, 100)} % against the time-optimal one",
                        "implemented (a cost, the paper gives no figure)" if cost >= 0 else
                        "differs: the jerk-limited CP is faster than the 'time-optimal' one, which was re-solved "
                        "with a tightened torque limit (Fig. 8 row)", {"cp_smooth_time_cost": sm}))
    return rows


# ---------------------------------------------------------------------------------- PtP
def _front(points: list[dict]) -> list[dict]:
    return sorted((p for p in points if not p["dominated"]), key=lambda p: p["k2"])


def ptp_rows(runs: Sequence[Run]) -> list[Row]:
    """§5.4/5.5, eq. (40): min k1 T + k2 E; the time/energy trade-off and the smooth variant."""
    tj = [r["trajectory"].summary for r in runs]
    fronts = [_front(s["ptp_pareto"]) for s in tj]
    f0 = fronts[0]
    pts = ", ".join(f"k2={p['k2']:g}: {p['duration_s']:.3f} s / E {p['energy']:.3f}" for p in f0)
    span_t = [f[-1]["duration_s"] / f[0]["duration_s"] - 1 for f in fronts]
    span_e = [1 - f[-1]["energy"] / f[0]["energy"] for f in fronts]
    monotone = all(len(f) >= 2 and all(b["duration_s"] >= a["duration_s"] and b["energy"] <= a["energy"]
                                       for a, b in zip(f, f[1:], strict=False)) for f in fronts)
    ours = (f"{tj[0]['ptp_energy_measure']} energy; Pareto front (seed 1) {pts}; from the fastest to the most "
            f"economical: time +{stat(span_t, 100)} %, energy −{stat(span_e, 100)} %; time-optimal "
            f"{stat(_col(tj, 'ptp_duration_s'))} s vs ruckig {stat(_col(tj, 'ptp_ruckig_duration_s'))} s; "
            f"at ruckig's duration energy × {stat(_col(tj, 'ptp_energy_at_ruckig_duration_ratio'))}")
    verdict = ("no paper number (values lost): raising k2 trades time for energy; a weighted sum k1 T + k2 E "
               "makes the front monotone by construction" if monotone and _mean(span_e) > 0
               else "differs: no monotone time/energy front")
    rows = [Row("ptp_tradeoff", "§5.5 PtP time/energy trade-off (eq. 40, k1 T + k2 E)",
                "\"a compromise between time and energy optimality is adjusted with k1 and k2\" (values lost)",
                ours, verdict, {"time_increase": span_t, "energy_decrease": span_e})]
    vib = [(s.get("ptp_settle_residual_vibration_max_m"), s.get("ptp_smooth_settle_residual_vibration_max_m"))
           for s in tj]
    if all(a is not None and b is not None for a, b in vib):
        r = [a / b for a, b in vib]
        cost = stat(_col(tj, "ptp_smooth_time_cost"), 100)
        rows.append(Row("ptp_smooth", "§5 jerk-continuous PtP on the elastic arm",
                        "continuous jerks keep the \"gear elasticities\" from being \"overly excited\"",
                        f"residual TCP vibration after the move {stat([a for a, _ in vib], 1e3)} mm (time-optimal) vs "
                        f"{stat([b for _, b in vib], 1e3)} mm (jerk-limited, {cost} % slower)",
                        "reproduced" if _mean(r) > 1 else "differs: smoothing does not reduce the vibration",
                        {"vibration_reduction": r}))
    return rows


# ---------------------------------------------------------------------------------- execution
PLANS = ("cp", "cp_smooth", "ptp", "ptp_smooth")


def failed_gates(run: Run, stage: str = "trajectory") -> list[str]:
    gates = run[stage].summary.get("quality_gates") or {}
    return [c["name"] for c in gates.get("checks", []) if not c["passed"]]


def execution_row(runs: Sequence[Run], acc: Sequence[Run]) -> Row:
    """The plans run in the servo simulation of the (elastic) hidden robot: the largest 4 ms mean
    of the commanded torque over the full limits (the trajectory stage's gate: <= 1)."""
    key = "{}_sim_max_averaged_torque_ratio"
    tj = [r["trajectory"].summary for r in runs]
    plans = [p for p in PLANS if key.format(p) in tj[0]]
    vals = {p: _col(tj, key.format(p)) for p in plans}
    ours = "paper's limits: " + ", ".join(f"{p} {stat(vals[p], digits=3)}" for p in plans)
    ours += f" (failed gates: {', '.join(failed_gates(runs[0])) or 'none'})"
    values = {f"{p}_torque_ratio": v for p, v in vals.items()}
    if acc:
        ta = [r["trajectory"].summary for r in acc]
        va = {p: _col(ta, key.format(p)) for p in plans if key.format(p) in ta[0]}
        ours += "; with acceleration limits: " + ", ".join(f"{p} {stat(v, digits=3)}" for p, v in va.items())
        ours += f" (failed gates: {', '.join(failed_gates(acc[0])) or 'none'})"
        values.update({f"{p}_torque_ratio_acceleration_limits": v for p, v in va.items()})
    rough = max(_mean(vals[p]) for p in plans if not p.endswith("smooth"))
    smooth = max((_mean(vals[p]) for p in plans if p.endswith("smooth")), default=np.inf)
    if rough <= 1.0:
        verdict = "all plans are executed within the torque limits"
    elif smooth < rough:
        verdict = (f"reproduced (the paper's §5 argument): the optimum with speed and torque limits only needs "
                   f"{rough:.2f}× the torque limit on the elastic hidden robot, the jerk-limited plans "
                   f"{smooth:.2f}×")
    else:
        verdict = "differs: the jerk-limited plans excite the elastic joints as much as the others"
    return Row("executed", "§5.3/§5.5 plans executed by the servo on the elastic arm (4 ms mean of τ/τ_max)",
               "measured torques at (not beyond) their limits (Fig. 8); jerk-continuous plans so that \"the gear "
               "elasticities are not overly excited\"", ours, verdict, values)


def failure_row(failures: dict[str, str], n_planned: int, n_main: int) -> Row:
    """Runs of the study that raised an error (their seeds are left out of the rows they feed)."""
    text = "; ".join(f"{name}: {msg}" for name, msg in failures.items())
    return Row("failures", "runs that failed", "—", text,
               f"differs: {len(failures)} run(s) failed ({n_main - n_planned} of {n_main} main trajectory runs); "
               "their seeds are left out of the trajectory rows", {"n_failed": [float(len(failures))]})


def all_rows(runs: Sequence[Run], rigid: Sequence[Run] = (), acc: Sequence[Run] = (),
             full_torque: Sequence[Run] = (), failures: dict[str, str] | None = None) -> list[Row]:
    """Every row; the experiments' runs may be empty (their parts are left out), and a main run
    without a trajectory stage (it failed) feeds only the rows of the earlier stages."""
    planned = [r for r in runs if "trajectory" in r]
    rows = settings_rows(runs) + [excitation_row(runs, full_torque)] + fig2_rows(runs, rigid) + [fig5_row(runs)]
    if planned:
        rows += fig8_rows(planned, acc) + ptp_rows(planned) + [execution_row(planned, acc)]
    if failures:
        rows.append(failure_row(failures, len(planned), len(runs)))
    return rows


def markdown(rows: Sequence[Row]) -> str:
    out = ["| result | paper | ours | verdict |", "|---|---|---|---|"]
    out += [f"| {r.item} | {r.paper} | {r.ours} | {r.verdict} |" for r in rows]
    return "\n".join(out)
