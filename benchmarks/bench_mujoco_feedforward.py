"""Where the model-based feedforward's largest ISO path error comes from on the MuJoCo arm.

Run: ``.venv/bin/python benchmarks/bench_mujoco_feedforward.py RUN_DIR [seed]`` on a run made with
``--set truth.engine=mujoco`` (its ``control`` and ``identification`` stages). The control stage's own ISO
reference, gains and TCP frame (``control/results.npz``) are run again on the same hidden arm (the run's
robot and seed 1) with: no feedforward; ``full_friction`` from the identified model (the stage's figure: on
this arm, whose dry friction sticks, the Coulomb sign switches on the reference velocity with
``control.sticking_friction_width_rad_s``, :func:`pipeline.control.simulate.feedforward_coulomb_width`); the
same with the model's own smoothing width ``w`` (``F_c tanh(v / w)``, 0.01 rad/s: the feedforward before
the switching width); the same without its Stribeck term; ``full_friction`` from the hidden arm's true
parameters (no identification error left) with either width; the identified feedforward at other
switching widths (how sensitive the figure is to it); and none and the identified feedforward with the
dry-friction constraint at MuJoCo's default time constant, 0.02 s (200 of the arm's 100 µs steps, instead
of its ten: :data:`pipeline.sim.mujoco_plant.FRICTION_TIMECONST_STEPS`).
Printed, all measured in this run: per case the largest TCP error against the desired path (as the
control stage scores it), when it happens, the lag of every axis there and the ratio none / case.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from bench_help import exit_on_help

from pipeline.control.config import ControlConfig
from pipeline.control.design import ServoGains
from pipeline.control.simulate import simulate_joint_trajectory
from pipeline.core.config import RunConfig
from pipeline.robot.model import RobotModel
from pipeline.run.stages import load_config
from pipeline.sim.mujoco_plant import FRICTION_TIMECONST_STEPS
from pipeline.sim.mujoco_robot import MujocoRealRobot, create_hidden_robot
from pipeline.sim.truth import TruthConfig

#: MuJoCo's default friction time constant (0.02 s) in the arm's 100 µs integration steps
MUJOCO_DEFAULT_TIMECONST_STEPS = 200.0
#: other Coulomb switching widths of the feedforward (rad/s), for its sensitivity
OTHER_WIDTHS_RAD_S = (1e-4, 3e-4, 2e-3, 5e-3)


def main(run_dir: Path, seed: int) -> None:
    cfg: RunConfig = load_config(run_dir / "config.yaml", [])
    d = np.load(run_dir / "control" / "results.npz")
    identified = RobotModel.load(run_dir / "identification" / "robot")
    control = cfg.sections.get("control")
    cc = control if isinstance(control, ControlConfig) else ControlConfig()
    truth_cfg = cfg.sections.get("truth")
    truth_cfg = truth_cfg if isinstance(truth_cfg, TruthConfig) else TruthConfig(engine="mujoco")
    nominal = RobotModel.load(cfg.robot) if isinstance(cfg.robot, str) else identified
    real = create_hidden_robot(nominal, cfg.seed, truth_cfg)
    if not isinstance(real, MujocoRealRobot):
        raise SystemExit(f"{run_dir}: truth.engine is not mujoco")
    frame = identified.frame_reflector if cc.path_frame == "reflector" else identified.frame_tcp
    gains = ServoGains(d["servo_kp_1_s"], d["servo_kv_Nms_rad"], d["servo_ki_Nm_rad"], np.ones(identified.nq))
    t, q, v, a, desired = d["iso_t_s"], d["iso_q_d"], d["iso_v_d"], d["iso_a_d"], d["iso_tcp_desired_m"]
    no_stribeck = identified.copy()
    no_stribeck.spec.actuation.static_friction_excess_Nm = None
    no_stribeck.spec.actuation.stribeck_velocity_rad_s = None
    steps = FRICTION_TIMECONST_STEPS
    widths = identified.spec.actuation.coulomb_smoothing_rad_s
    model_width = replace(cc, sticking_friction_width_rad_s=float(np.max(widths)))
    cases = [("none", identified, "none", steps, cc), ("identified", identified, "full_friction", steps, cc),
             ("identified, model's width", identified, "full_friction", steps, model_width),
             ("identified, no Stribeck", no_stribeck, "full_friction", steps, cc),
             ("true parameters", real.truth, "full_friction", steps, cc),
             ("true parameters, model's width", real.truth, "full_friction", steps, model_width),
             *((f"identified, width {w:g} rad/s", identified, "full_friction", steps,
                replace(cc, sticking_friction_width_rad_s=w)) for w in OTHER_WIDTHS_RAD_S),
             ("none, MuJoCo's 0.02 s", identified, "none", MUJOCO_DEFAULT_TIMECONST_STEPS, cc),
             ("identified, MuJoCo's 0.02 s", identified, "full_friction", MUJOCO_DEFAULT_TIMECONST_STEPS, cc)]
    print(f"{run_dir}: ISO path {t[-1]:.2f} s, noise seed {seed}, feedforward switching width "
          f"{np.min(np.minimum(cc.sticking_friction_width_rad_s, widths)):g} rad/s")
    largest: dict[str, float] = {}
    for name, model, variant, timeconst_steps, case_cfg in cases:
        real.plant.friction_timeconst_steps = timeconst_steps
        start = time.perf_counter()
        res = simulate_joint_trajectory(real, model, t, q, v, a, case_cfg, feedforward=variant,
                                        rng=np.random.default_rng(seed), tcp_frame=frame, gains=gains)
        assert res.tcp_position_m is not None
        err = np.linalg.norm(res.tcp_position_m - desired, axis=1)
        k = int(np.argmax(err))
        largest[name] = float(err[k])
        none = largest["none" if timeconst_steps == steps else "none, MuJoCo's 0.02 s"]
        print(f"  {name:34s} max TCP error {err[k] * 1e6:7.1f} µm at t = {t[k]:.3f} s, ratio none / it "
              f"{none / err[k]:5.2f}; lag there (µrad) {np.round(res.lag_error_rad[k] * 1e6, 1).tolist()}; "
              f"axis velocities (rad/s) {np.round(v[min(k, len(v) - 1)], 3).tolist()} "
              f"[{time.perf_counter() - start:.0f} s wall]", flush=True)
    real.plant.friction_timeconst_steps = steps


if __name__ == "__main__":
    exit_on_help(__doc__)
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 21)
