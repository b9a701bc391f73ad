"""What caps the elastic-joint feedforward when the model is exact: its approximations or the servo?

Run: ``.venv/bin/python benchmarks/bench_elastic_floor.py [RUN_DIR]`` (default ``data/runs/rx130l``,
a run through ``identification``; its robot, seed and truth are read from ``RUN_DIR``, the servo
gains come from its identified model as in the control stage). Companion of
``bench_elastic_gap.py`` (which swaps model ingredients): here the ``elastic_flat`` feedforward
(paper ``004_abbe750b8bbcc3aa.txt`` §2.3; :mod:`pipeline.control.elastic_feedforward`) is built
from the EXACT hidden robot, and one thing is switched off at a time:

* the servo and plant: encoder noise and quantisation, the set-point and measurement delays, the
  integration rate of the plant (100 kHz instead of >= 10 kHz);
* the feedforward's approximations: Savitzky-Golay link jerk/snap (window 4 ms) replaced by a 1 ms
  window or by plain central differences of the sampled link torque (the ruckig reference is
  jerk-limited, so its snap is impulsive: the central difference is its sampled impulse); joint
  damping in the inverse (``k delta + d delta' = tau_l``, solved exactly for a piecewise-linear
  ``tau_l``, so ``theta = q + delta``, ``omega = v + delta'``, ``alpha = a + (tau_l'/k - delta')
  k/d``); friction with the truth's load dependence (evaluated at ``tau_l``);
* the truth's non-linear friction: the load-dependent Coulomb part, the Stribeck excess (the
  feedforward keeps matching the truth);
* the velocity-loop gain: the cases above use the servo of the bandwidth design alone
  (``control.stick_slip_margin: 0``); then ``Kv`` raised to ``margin`` x the truth's steepest Stribeck
  slope minus viscous friction (``Ki`` scaled alike, :func:`pipeline.control.design.stick_slip_gains`),
  and the pipeline's model with the bandwidth design, that floor, and the stage's own floor from the
  identified Stribeck term (``control.stick_slip_margin``).

Why the last one: the Stribeck curve ``(F_s - F_c) exp(-(w/w_s)^2)`` falls with speed, at most by
``sqrt(2/e) (F_s - F_c)(1 + mu) / w_s`` (N m s/rad) at ``w = w_s / sqrt(2)``. That is a negative
damping on the motor; where it exceeds the drive's ``Kv`` + viscous friction the closed loop is
locally unstable at low speed (stick-slip: Armstrong-Hélouvry, Dupont, Canudas de Wit, Automatica
30(7), 1994, §"stick-slip"), whatever the feedforward: a joint that creeps through zero speed sticks
and then slips by a fraction of a milliradian. The table per joint prints that slope, ``Kv + viscous``
and the largest link error of the ``elastic_flat`` run.

Printed per case: the max TCP tracking error (measured TCP vs the hidden robot standing at the
reference joints) without feedforward and with ``elastic_flat``, and their ratio (the target of
``tests/control/test_targets_slow.py``: >= 10). The denominator changes with the case too.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from types import SimpleNamespace
from unittest import mock

import numpy as np
from bench_elastic_gap import load_run_models
from bench_help import exit_on_help
from scipy.signal import savgol_filter

from pipeline.control import simulate
from pipeline.control.config import ControlConfig
from pipeline.control.design import ServoGains, filter_alpha, iso_reference, servo_report, stick_slip_gains
from pipeline.control.elastic_feedforward import link_torque
from pipeline.control.simulate import servo_gains, simulate_joint_trajectory
from pipeline.robot.friction import stribeck_slope_Nms_rad
from pipeline.robot.model import RobotModel
from pipeline.sim.plant import Plant
from pipeline.sim.transmission import Transmission
from pipeline.sim.truth import RealRobot
from pipeline.stage_api import stage_rng


def true_slope_Nms_rad(tr: Transmission) -> np.ndarray:
    """Steepest fall of the truth's friction with motor speed (N m s/rad, at rated load)."""
    return stribeck_slope_Nms_rad(tr.static_excess_Nm * (1.0 + tr.coulomb_load_coefficient), tr.stribeck_velocity_rad_s)


def _derivative(x: np.ndarray, dt: float, order: int, window_s: float) -> np.ndarray:
    """Savitzky-Golay (cubic) over ``window_s``; ``window_s = 0``: repeated central differences."""
    if window_s <= 0:
        for _ in range(order):
            x = np.gradient(x, dt, axis=0)
        return x
    w = max(5, int(round(window_s / dt)) | 1)
    return savgol_filter(x, w, 3, deriv=order, delta=dt, axis=0, mode="interp")


def damped_deflection(u: np.ndarray, dt: float, tau_s: np.ndarray) -> np.ndarray:
    """``delta`` with ``tau_s delta' + delta = u`` (``u = tau_l / k``, piecewise linear between the
    samples, ``tau_s = d / k``), starting at rest ``delta(0) = u(0)``: the exact first-order-hold solution."""
    e = np.exp(-dt / tau_s)
    delta = np.empty_like(u)
    delta[0] = u[0]
    for i in range(1, len(u)):
        slope = (u[i] - u[i - 1]) / dt
        delta[i] = e * delta[i - 1] + (1 - e) * u[i - 1] + slope * (dt - tau_s * (1 - e))
    return delta


def exact_flat_setpoints(model: RobotModel, sample_time_s: float, q_d: np.ndarray, v_d: np.ndarray,
                         a_d: np.ndarray, variant: str, rigid_tau_ff: np.ndarray, *, window_s: float = 4e-3,
                         damping_Nms_rad: np.ndarray | None = None,
                         friction: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``elastic_flat`` set points ``(theta_d, omega_d, tau_ff)`` with the options of the module docstring
    (the defaults reproduce :func:`pipeline.control.elastic_feedforward.elastic_feedforward`)."""
    k = np.asarray(model.spec.actuation.joint_stiffness_Nm_rad, float)
    dt = sample_time_s
    tau_l = link_torque(model, q_d, v_d, a_d)
    if damping_Nms_rad is None:
        delta = tau_l / k
        d_delta = _derivative(tau_l, dt, 1, window_s) / k
        dd_delta = _derivative(tau_l, dt, 2, window_s) / k
    else:
        tau_s = np.asarray(damping_Nms_rad, float) / k
        delta = damped_deflection(tau_l / k, dt, tau_s)
        d_delta = (tau_l / k - delta) / tau_s
        dd_delta = (_derivative(tau_l, dt, 1, window_s) / k - d_delta) / tau_s
    omega = v_d + d_delta
    fr = model.friction_torque(omega) if friction is None else friction(omega, tau_l)
    return q_d + delta, omega, np.asarray(model.model.armature) * (a_d + dd_delta) + tau_l + fr


def exact_model(real: RealRobot, tr: Transmission) -> RobotModel:
    """The hidden robot with its true stiffness and ``tr``'s friction curve at zero load."""
    out = real.truth.copy()
    out.spec.actuation.joint_stiffness_Nm_rad = real.joint_stiffness_Nm_rad.copy()
    out.friction_torque = lambda w: tr.friction_torque(np.asarray(w, float))  # type: ignore[method-assign]
    return out


@dataclasses.dataclass
class Case:
    label: str
    transmission: Transmission
    config: ControlConfig
    gains: ServoGains
    plant: dict = dataclasses.field(default_factory=dict)      # Plant keyword overrides
    setpoints: dict = dataclasses.field(default_factory=dict)  # exact_flat_setpoints options
    model: RobotModel | None = None                            # None: the exact hidden robot with ``transmission``


def main(run_dir: str = "data/runs/rx130l") -> None:
    run = Path(run_dir)
    m = load_run_models(run)
    seed, robot_name, cfg, pipe, real = m.seed, m.robot_name, m.config, m.pipe, m.real
    tr = real.transmission
    t0 = time.perf_counter()
    iso_run = iso_reference(pipe, cfg)
    ref, frame = iso_run.ref, iso_run.frame
    q_mean = np.mean(ref.q_d, axis=0)
    gains = servo_gains(pipe, q_mean, dataclasses.replace(cfg, stick_slip_margin=0.0))   # bandwidth design only
    stage_gains = servo_gains(pipe, q_mean, cfg)                                      # + the stage's floor
    noise_seed = int(stage_rng(seed, "control").integers(2**32))   # the control stage's first draw
    at_ref = real.plant.measure_tcp(ref.q_d, frame)
    slope = true_slope_Nms_rad(tr)
    margin = cfg.stick_slip_margin if cfg.stick_slip_margin > 0 else 1.5
    stiff_gains = stick_slip_gains(gains, slope, tr.viscous_Nms_rad, margin, 2 * np.pi * cfg.velocity_filter_hz)

    no_load = dataclasses.replace(tr, coulomb_load_coefficient=np.zeros_like(tr.effort_Nm))
    no_stribeck = dataclasses.replace(tr, static_excess_Nm=np.zeros_like(tr.effort_Nm))
    neither = dataclasses.replace(no_stribeck, coulomb_load_coefficient=np.zeros_like(tr.effort_Nm))
    no_delay = dataclasses.replace(cfg, setpoint_delay_samples=0, measurement_delay_samples=0)
    quiet = {"encoder_noise_rad": 0.0, "encoder_resolution_rad": 1e-12}
    fine = {"integration_rate_hz": 100000.0}
    d = tr.damping_Nms_rad
    load_friction = tr.friction_torque          # (w, tau_load)
    ff_exact = {"window_s": 0.0, "damping_Nms_rad": d, "friction": load_friction}

    def ff_cases(tag: str, t: Transmission) -> list[Case]:
        return [Case(f"{tag}ff: SG window 1 ms", t, cfg, gains, setpoints={"window_s": 1e-3}),
                Case(f"{tag}ff: central differences (impulsive snap)", t, cfg, gains, setpoints={"window_s": 0.0}),
                Case(f"{tag}ff: joint damping in the inverse", t, cfg, gains, setpoints={"damping_Nms_rad": d}),
                Case(f"{tag}ff: load-dependent friction at tau_l", t, cfg, gains,
                     setpoints={"friction": t.friction_torque}),
                Case(f"{tag}ff: the three together", t, cfg, gains,
                     setpoints=ff_exact | {"friction": t.friction_torque})]

    cases = [Case("exact hidden robot (as the stage, SG 4 ms)", tr, cfg, gains),
             Case("servo: encoder noise 0, resolution 1e-12 rad", tr, cfg, gains, plant=quiet),
             Case("servo: set-point and measurement delays 0", tr, no_delay, gains),
             Case("plant: integration at 100 kHz", tr, cfg, gains, plant=fine),
             Case("servo+plant: noise, delays off, 100 kHz", tr, no_delay, gains, plant=quiet | fine),
             *ff_cases("", tr),
             Case("all of the above off", tr, no_delay, gains, plant=quiet | fine, setpoints=ff_exact),
             Case("truth: load-dependent Coulomb 0", no_load, cfg, gains),
             Case("truth: Stribeck excess 0", no_stribeck, cfg, gains),
             Case("truth: Stribeck excess 0 and load dependence 0", neither, cfg, gains),
             *ff_cases("w/o Stribeck, ", no_stribeck),
             Case(f"servo: Kv >= {margin} x true Stribeck slope - viscous", tr, cfg, stiff_gains),
             Case("pipeline model, bandwidth design only", tr, cfg, gains, model=pipe),
             Case(f"pipeline model, Kv >= {margin} x true slope", tr, cfg, stiff_gains, model=pipe),
             Case("pipeline model, the stage's gains (identified slope)", tr, cfg, stage_gains, model=pipe)]

    print(f"{robot_name}, seed {seed}, run {run}: ISO path {ref.t_s[-1]:.2f} s, reference in "
          f"{time.perf_counter() - t0:.1f} s")
    alpha = filter_alpha(cfg.velocity_filter_hz, cfg.sample_time_s / cfg.velocity_samples_per_position_sample)
    pm = [r["velocity"]["phase_margin_deg"] for r in servo_report(
        stiff_gains, cfg.sample_time_s, cfg.velocity_samples_per_position_sample, cfg.measurement_delay_samples,
        alpha)]
    np.set_printoptions(precision=2, suppress=True, linewidth=150)
    print(f"steepest Stribeck slope [N m s/rad]   {slope}")
    print(f"Kv + viscous (bandwidth design)       {gains.kv + tr.viscous_Nms_rad}")
    print(f"slope / (Kv + viscous)                {slope / (gains.kv + tr.viscous_Nms_rad)}   (> 1: stick-slip prone)")
    print(f"Kv raised to {margin} x slope: velocity-loop phase margin [deg] {np.array(pm)} (rigid loop model)")
    print(f"stage's Kv (identified Stribeck)      {stage_gains.kv}  (bandwidth design {gains.kv})")

    def run_case(c: Case) -> tuple[float, float, np.ndarray]:
        plant = Plant(real.truth, **({"encoder_noise_rad": real.config.encoder_noise_rad} | c.plant),
                      transmission=c.transmission)
        hidden = SimpleNamespace(plant=plant)       # what simulate_joint_trajectory uses of a RealRobot
        model = exact_model(real, c.transmission) if c.model is None else c.model
        errors, link = [], np.zeros(real.truth.nq)
        for variant in ("none", "elastic_flat"):
            with mock.patch.object(simulate, "elastic_feedforward", partial(exact_flat_setpoints, **c.setpoints)):
                res = simulate_joint_trajectory(hidden, model, ref.t_s, ref.q_d, ref.v_d, ref.a_d, c.config,
                                                variant, np.random.default_rng(noise_seed), gains=c.gains,
                                                tcp_frame=frame)
            errors.append(float(np.linalg.norm(res.tcp_position_m - at_ref, axis=1).max()))
            link = np.abs(res.q_link - ref.q_d).max(axis=0)
        return errors[0], errors[1], link

    print(f"\n{'case (elastic_flat from the exact hidden robot unless named)':<62} {'none [mm]':>10} "
          f"{'elastic [mm]':>13} {'ratio':>7}   max link error per joint [mrad]")
    for c in cases:
        none, elastic, link = run_case(c)
        print(f"{c.label:<62} {none * 1e3:>10.4f} {elastic * 1e3:>13.4f} {none / elastic:>7.1f}   {link * 1e3}",
              flush=True)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(*sys.argv[1:2])
