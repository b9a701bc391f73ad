"""What limits the elastic-joint feedforward of the pipeline on the EN ISO 9283 path (stage 3).

Run: ``.venv/bin/python benchmarks/bench_elastic_gap.py [RUN_DIR]`` (default ``data/runs/rx130l``,
a run of the default configuration through ``identification``: ``python -m pipeline run --stages
identification``). The run's robot, seed and truth configuration are read from ``RUN_DIR``.

The control stage's ISO reference (:func:`pipeline.control.design.iso_reference`, the pipeline
model's kinematics) runs on the hidden robot's elastic plant (Stribeck friction, seeded) through
:func:`pipeline.control.simulate.simulate_joint_trajectory` with the servo gains of the pipeline
model and the stage's encoder-noise stream, for the ``elastic_flat`` feedforward (paper
``004_abbe750b8bbcc3aa.txt`` §2.3; :mod:`pipeline.control.elastic_feedforward`) built from

* the exact hidden robot (kinematics, inertias, rotor inertia, friction with its Stribeck term at
  zero load, true joint stiffness), and the hidden robot with the nominal stiffness rule;
* the pipeline's model (``<run>/identification/robot``: calibrated kinematics, identified inertias
  and friction) with the stiffness the control stage uses
  (:func:`pipeline.control.joint_stiffness.feedforward_stiffness`: calibrated and re-expressed for
  the identified inertias, nominal where not identified), and with the calibration's stiffness as
  the identification hands it on;
* the pipeline's model with ONE ingredient from the hidden robot: one joint's stiffness (its source
  in brackets), the stiffness of every nominal joint, every stiffness, the link inertias, the
  viscous + Coulomb numbers, the Stribeck friction, the rotor inertia, the kinematics; and the
  pipeline's model with the nominal stiffness rule
  (:func:`pipeline.robot.stiffness.nominal_joint_stiffness_Nm_rad`) for every joint.

Printed per case: the max TCP tracking error (measured TCP vs the hidden robot standing at the
reference joints, the stage's ``tcp_tracking_error_max_m``) and its ratio ``none / case`` (the
target of ``tests/control/test_targets_slow.py``: >= 10). The damping of the joints is not in any
model (the inverse neglects it).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from bench_help import exit_on_help

from pipeline.control.config import ControlConfig
from pipeline.control.design import iso_reference
from pipeline.control.joint_stiffness import StiffnessChoice, feedforward_stiffness
from pipeline.control.simulate import servo_gains, simulate_joint_trajectory
from pipeline.core.yaml12 import load_yaml
from pipeline.robot.model import RobotModel
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad
from pipeline.run.stages import load_config
from pipeline.sim.truth import RealRobot, TruthConfig
from pipeline.stage_api import stage_rng


def with_stiffness(robot: RobotModel, k_Nm_rad: np.ndarray) -> RobotModel:
    out = robot.copy()
    out.spec.actuation.joint_stiffness_Nm_rad = np.asarray(k_Nm_rad, float).copy()
    return out


def with_truth_friction(robot: RobotModel, truth: RobotModel, stribeck: bool, real: RealRobot) -> RobotModel:
    """Viscous + Coulomb numbers of the truth; with ``stribeck`` the truth's motor-side friction curve
    (Stribeck term, at zero load: the feedforward knows the speed, not the transmitted torque)."""
    out = robot.copy()
    for name in ("viscous_Nms_rad", "coulomb_Nm"):
        setattr(out.actuation, name, np.array(getattr(truth.actuation, name), float))
    if stribeck:
        tr = real.transmission
        out.friction_torque = lambda w: tr.friction_torque(np.asarray(w, float))  # type: ignore[method-assign]
    return out


def with_truth_inertias(robot: RobotModel, truth: RobotModel) -> RobotModel:
    out = robot.copy()
    for j in range(1, out.model.njoints):
        out.model.inertias[j] = truth.model.inertias[j].copy()
    return out


def with_truth_rotor(robot: RobotModel, truth: RobotModel) -> RobotModel:
    out = robot.copy()
    out.model.armature = np.array(truth.model.armature, float).copy()
    out.actuation.rotor_inertia_kgm2 = np.array(truth.actuation.rotor_inertia_kgm2, float).copy()
    return out


def with_truth_kinematics(robot: RobotModel, truth: RobotModel) -> RobotModel:
    """The truth's placements and frames carrying ``robot``'s inertias, rotor inertia, friction, stiffness."""
    out = truth.copy()
    for j in range(1, out.model.njoints):
        out.model.inertias[j] = robot.model.inertias[j].copy()
    out.model.armature = np.array(robot.model.armature, float).copy()
    for name in ("viscous_Nms_rad", "coulomb_Nm", "rotor_inertia_kgm2"):
        setattr(out.actuation, name, np.array(getattr(robot.actuation, name), float).copy())
    for name in ("static_friction_excess_Nm", "stribeck_velocity_rad_s"):   # identified Stribeck term or None
        setattr(out.actuation, name, getattr(robot.actuation, name))
    out.spec.actuation.joint_stiffness_Nm_rad = nominal_joint_stiffness_Nm_rad(robot)
    return out


def cases(pipe: RobotModel, handed_on: RobotModel, choice: StiffnessChoice, real: RealRobot,
          nominal: RobotModel) -> list[tuple[str, RobotModel]]:
    """``pipe``: the pipeline's model with the stiffness the control stage uses; ``handed_on``: the same
    with the calibration's stiffness as the identification hands it on."""
    truth = real.truth
    k_true = real.joint_stiffness_Nm_rad
    k_pipe = nominal_joint_stiffness_Nm_rad(pipe)
    exact = with_truth_friction(with_stiffness(truth, k_true), truth, True, real)
    out = [("(a) exact hidden robot", exact),
           ("(a) exact, nominal stiffness rule", with_truth_friction(with_stiffness(
               truth, nominal_joint_stiffness_Nm_rad(nominal)), truth, True, real)),
           ("(b) pipeline model (control stage's k)", pipe),
           ("(b) pipeline, calibration's k as handed on", handed_on)]
    for i in range(pipe.nq):
        k = k_pipe.copy()
        k[i] = k_true[i]
        src = choice.source[i].split(" ")[0].rstrip(",")
        out.append((f"(c) pipeline, true k{i + 1} ({src})", with_stiffness(pipe, k)))
    nominal_joints = [j - 1 for j in choice.nominal_joints]
    if nominal_joints:
        k = k_pipe.copy()
        k[nominal_joints] = k_true[nominal_joints]
        out.append(("(c) pipeline, true k of the nominal joints", with_stiffness(pipe, k)))
    out += [("(c) pipeline, every k true", with_stiffness(pipe, k_true)),
            ("(c) pipeline, k = nominal rule", with_stiffness(pipe, nominal_joint_stiffness_Nm_rad(nominal))),
            ("(c) pipeline, true link inertias", with_truth_inertias(pipe, truth)),
            ("(c) pipeline, true viscous+Coulomb", with_truth_friction(pipe, truth, False, real)),
            ("(c) pipeline, true friction+Stribeck", with_truth_friction(pipe, truth, True, real)),
            ("(c) pipeline, true rotor inertia", with_truth_rotor(pipe, truth)),
            ("(c) pipeline, true kinematics", with_truth_kinematics(pipe, truth))]
    return out


@dataclass
class RunModels:
    """What a run through identification hands the control stage, rebuilt from its folder."""

    seed: int
    robot_name: str
    config: ControlConfig                 # the run's control settings, saturation clipped
    nominal: RobotModel
    handed_on: RobotModel                 # <run>/identification/robot
    choice: StiffnessChoice               # the stiffness the control stage uses
    pipe: RobotModel                      # handed_on with that stiffness
    real: RealRobot                       # the run's hidden robot


def load_run_models(run_dir: str | Path) -> RunModels:
    """The run's robot, seed and truth read from ``run_dir`` and its models built as the stage does."""
    run = Path(run_dir)
    raw = load_yaml((run / "config.yaml").read_text())
    seed, robot_name = int(raw.get("seed", 0)), str(raw.get("robot", "rx130l"))
    truth_cfg = TruthConfig(**raw.get("truth", {}))
    cfg = load_config(values={"robot": robot_name, "seed": seed, "control.on_saturation": "clip"}).control
    nominal = RobotModel.load(robot_name)
    handed_on = RobotModel.load(run / "identification" / "robot")
    with np.load(run / "calibration" / "results.npz") as z:
        cal_arrays = {k: z[k] for k in z.files}
    choice = feedforward_stiffness(handed_on, cal_arrays, True, nominal_joint_stiffness_Nm_rad(nominal))  # as the stage
    pipe = with_stiffness(handed_on, choice.stiffness_Nm_rad)
    real = RealRobot.create(nominal, seed, truth_cfg)
    return RunModels(seed, robot_name, cfg, nominal, handed_on, choice, pipe, real)


def main(run_dir: str = "data/runs/rx130l") -> None:
    run = Path(run_dir)
    m = load_run_models(run)
    seed, robot_name, cfg, nominal, handed_on, choice, pipe, real = (
        m.seed, m.robot_name, m.config, m.nominal, m.handed_on, m.choice, m.pipe, m.real)
    t0 = time.perf_counter()
    iso_run = iso_reference(pipe, cfg)
    ref, frame = iso_run.ref, iso_run.frame
    gains = servo_gains(pipe, np.mean(ref.q_d, axis=0), cfg)
    noise_seed = int(stage_rng(seed, "control").integers(2**32))   # the control stage's first draw
    at_ref = real.plant.measure_tcp(ref.q_d, frame)
    print(f"{robot_name}, seed {seed}, run {run}: ISO path {ref.t_s[-1]:.2f} s, reference in "
          f"{time.perf_counter() - t0:.1f} s")
    np.set_printoptions(precision=0, suppress=True)
    print(f"joint stiffness [N m/rad] true     {real.joint_stiffness_Nm_rad}")
    print(f"                          handed on {nominal_joint_stiffness_Nm_rad(handed_on)}")
    print(f"                          control  {choice.stiffness_Nm_rad}  {choice.source}")
    print(f"                          nominal  {nominal_joint_stiffness_Nm_rad(nominal)}")

    def tracking_max_m(model: RobotModel, variant: str) -> float:
        res = simulate_joint_trajectory(real, model, ref.t_s, ref.q_d, ref.v_d, ref.a_d, cfg, variant,
                                        np.random.default_rng(noise_seed), gains=gains, tcp_frame=frame)
        return float(np.linalg.norm(res.tcp_position_m - at_ref, axis=1).max())

    base = tracking_max_m(pipe, "none")
    print(f"\n{'feedforward (elastic_flat unless named)':<50} {'max tracking [mm]':>18} {'none / case':>12}")
    print(f"{'none (no feedforward)':<50} {base * 1e3:>18.3f} {1.0:>12.2f}")
    ff = tracking_max_m(pipe, "full_friction")
    print(f"{'rigid full_friction, pipeline model':<50} {ff * 1e3:>18.3f} {base / ff:>12.2f}")
    for label, model in cases(pipe, handed_on, choice, real, nominal):
        e = tracking_max_m(model, "elastic_flat")
        print(f"{label:<50} {e * 1e3:>18.3f} {base / e:>12.2f}")
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(*sys.argv[1:2])
