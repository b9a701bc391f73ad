"""The robot model shared by every stage: Pinocchio model + limits + actuators + tool.

``RobotModel.load`` reads a robot folder (``robots/<name>/robot.yaml`` + its URDF) or any
URDF + yaml pair and validates both, naming the file and the field of the first problem.
Kinematics and dynamics are Pinocchio's; this class adds the facts a URDF lacks (rotor
inertia as ``model.armature``, friction, TCP and reflector frames, tracker placement,
collision capsules) and an inverse kinematics that reports failure instead of returning
a wrong pose.
"""

from __future__ import annotations

import copy as _copy
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.optimize import minimize

from pipeline.core.artefacts import write_text
from pipeline.core.errors import RobotFileError
from pipeline.core.yaml12 import dump_yaml
from pipeline.robot.assumed_values import assumed_sentences
from pipeline.robot.capsule_check import always_colliding_pairs, capsule_clearances, capsule_segments, checked_pairs
from pipeline.robot.collision import CapsuleDistances
from pipeline.robot.friction import joint_friction_torque, load_free_from_applied, load_friction_torque
from pipeline.robot.ik import IKResult, solve_ik
from pipeline.robot.loading import ROBOTS_DIR, JointLimits, load_robot_files, resolve_robot_files, validate_joint_limits
from pipeline.robot.reflector_check import capsules_holding, describe, marker_points
from pipeline.robot.residual_map import ResidualMap
from pipeline.robot.spec import ActuationSpec, Capsule, RobotSpec, TrackerSpec
from pipeline.robot.spec_yaml import robot_spec_to_yaml
from pipeline.robot.urdf_export import export_urdf
from pipeline.robot.urdf_import import absolute_mesh_paths

WORLD = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
__all__ = ["ROBOTS_DIR", "JointLimits", "RobotModel", "resolve_robot_files"]


class RobotModel:
    """A validated robot: Pinocchio model with armature, limits, actuators, tool and capsules."""

    frame_flange = "flange"
    frame_tcp = "tcp"
    frame_reflector = "reflector"

    def __init__(self, spec: RobotSpec, model: pin.Model, urdf_text: str,
                 assumptions: list[str] | None = None) -> None:
        self.spec = spec
        self.model = model
        self.urdf_text = urdf_text
        if assumptions:
            spec.assumptions = list(dict.fromkeys([*spec.assumptions, *assumptions]))
        self._data = model.createData()
        self._frame_ids: dict[str, int] = {}
        self._check_frames()
        capsule_joints = [self.model.frames[self.frame_id(c.frame)].parentJoint for c in spec.capsules]
        self._capsule_joint = np.array(capsule_joints, dtype=int)
        self._self_pairs, self._floor_capsules = checked_pairs(spec, capsule_joints)
        #: the calibration's non-geometric residual map (None: not chosen), added to the tool frames
        self.residual_map: ResidualMap | None = None

    # ------------------------------------------------------------------ loading
    @classmethod
    def load(cls, robot: str | Path, yaml_path: str | Path | None = None, *, base: str | None = None,
             tip: str | None = None, lock: dict[str, float] | None = None, urdf_alone: bool = False) -> RobotModel:
        """Load ``robots/<robot>/``, a folder with ``robot.yaml``, a URDF + yaml, or a URDF alone.

        A URDF alone gets stated assumptions for what it lacks (``assumptions``); joints off the
        base->tip chain are locked, those in ``lock`` at the given positions (:mod:`pipeline.robot.loading`).
        ``urdf_alone``: ignore a robot.yaml beside the URDF. An assumed reflector (or probe diode) must lie
        outside every capsule; one robot.yaml gives (measured, calibrated) may not, which
        :func:`pipeline.robot.plausibility.robot_warnings` reports.
        """
        spec, model, urdf_text, assumptions = load_robot_files(robot, yaml_path, base=base, tip=tip, lock=lock,
                                                               urdf_alone=urdf_alone)
        assumed = spec.path == spec.urdf
        robot_model = cls._assemble(spec, model, urdf_text, assumptions)
        robot_model._check_always_colliding(fix=assumed or "capsules" in spec.assumed)
        for field, what, point in marker_points(spec):
            if not (assumed or field.split("[")[0] in spec.assumed):
                continue      # measured or calibrated: a fact (robot_warnings names a capsule that holds it)
            holding = capsules_holding(robot_model.model, spec.flange_frame, point, spec.capsules)
            if holding:
                raise RobotFileError(spec.path, field, f"{what} lies inside {describe(holding)}; move it out along "
                                     "the flange axis or put it on the tool flange (flange_frame: tool0, or robot "
                                     "init --tip tool0)")
        return robot_model

    @classmethod
    def _assemble(cls, spec: RobotSpec, model: pin.Model, urdf_text: str,
                  assumptions: list[str] | None = None) -> RobotModel:
        if not model.existFrame(spec.flange_frame):
            raise RobotFileError(spec.path, "flange_frame", f"frame '{spec.flange_frame}' not in the URDF "
                                 f"(frames: {', '.join(f.name for f in model.frames)})")
        model.armature = spec.actuation.rotor_inertia_kgm2.copy()
        for key, values in spec.limit_overrides.items():
            attr = {"lower_rad": "lowerPositionLimit", "upper_rad": "upperPositionLimit",
                    "velocity_rad_s": "velocityLimit", "effort_Nm": "effortLimit"}[key]
            setattr(model, attr, values.copy())
        flange_id = model.getFrameId(spec.flange_frame)
        flange = model.frames[flange_id]
        joint, placement = flange.parentJoint, flange.placement
        frame_type = pin.FrameType.OP_FRAME
        if spec.flange_frame != cls.frame_flange and not model.existFrame(cls.frame_flange):
            model.addFrame(pin.Frame(cls.frame_flange, joint, flange_id, placement, frame_type))
        for name, local in (
            (cls.frame_tcp, spec.tool.transform_tcp_to_flange),
            (cls.frame_reflector, pin.SE3(np.eye(3), spec.tool.reflector_offset_m)),
        ):
            if model.existFrame(name):
                raise RobotFileError(spec.urdf, name, f"the URDF already has a frame '{name}'; the yaml defines it")
            model.addFrame(pin.Frame(name, joint, flange_id, placement * local, frame_type))
        robot = cls(spec, model, urdf_text, assumptions)
        validate_joint_limits(spec, model, robot.limits)
        return robot

    def _check_always_colliding(self, fix: bool, samples: int = 200) -> None:
        """Capsule pairs that overlap in (almost) every random configuration inside the limits.

        Such a pair makes every candidate configuration "in collision". With assumed capsules (a URDF
        alone, or robot.yaml's capsules still as ``robot init`` fitted them) the pair is left out of the
        self-collision check (an assumption); with capsules the user gave it is an error naming the
        pair and the fix (:func:`pipeline.robot.capsule_check.always_colliding_pairs`).
        """
        if not self._self_pairs:
            return
        rng = np.random.default_rng(0)
        Q = rng.uniform(self.model.lowerPositionLimit, self.model.upperPositionLimit, size=(samples, self.nq))
        pair, _ = self.capsule_clearances(self.capsule_segments(Q))
        bad = always_colliding_pairs(self.spec, self._self_pairs, pair, fix)
        self._self_pairs = [p for p in self._self_pairs if p not in bad]

    def _check_frames(self) -> None:
        for k, capsule in enumerate(self.spec.capsules):
            if not self.model.existFrame(capsule.frame):
                raise RobotFileError(self.spec.path, f"capsules[{k}].frame",
                                     f"unknown frame '{capsule.frame}'")

    # --------------------------------------------------------------- properties
    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def nq(self) -> int:
        return self.model.nq

    @property
    def limits(self) -> JointLimits:
        m = self.model
        return JointLimits(m.lowerPositionLimit.copy(), m.upperPositionLimit.copy(), m.velocityLimit.copy(),
                           m.effortLimit.copy(), self.spec.acceleration_rad_s2.copy())

    @property
    def actuation(self) -> ActuationSpec:
        return self.spec.actuation

    @property
    def tracker(self) -> TrackerSpec:
        return self.spec.tracker

    @property
    def assumptions(self) -> list[str]:
        """What was assumed because the robot files do not say it (listed in the run report)."""
        return [*self.spec.assumptions, *assumed_sentences(self.spec.assumed)]

    @property
    def has_tracker(self) -> bool:
        """False when robot.yaml has no tracker section: no calibration stage (nominal kinematics)."""
        return self.spec.has_tracker

    @property
    def capsules(self) -> list[Capsule]:
        return self.spec.capsules

    def _relative_to_flange(self, frame: str, flange: str | None = None) -> pin.SE3:
        """``frame``'s placement in ``flange`` (None: :attr:`frame_flange`)."""
        frames = self.model.frames
        base = self.frame_flange if flange is None else flange
        return frames[self.frame_id(base)].placement.actInv(frames[self.frame_id(frame)].placement)

    def tool_facts(self) -> tuple[pin.SE3, np.ndarray, np.ndarray]:
        """TCP pose, reflector centre and reflector opening axis in the frame robot.yaml states them
        in (``flange_frame``), read from the model's frames: what :meth:`save` writes and ``load``
        rebuilds. A URDF may have a ``flange`` frame of its own, turned against ``flange_frame``
        (ROS-Industrial's ``flange`` and ``tool0``, REP 199): :attr:`frame_flange` is then that frame,
        and the TCP and reflector properties are in it, not in the stated one. The reflector frame's
        rotation (a calibrated tool rotation) is folded into the axis: ``load`` builds the reflector
        frame unturned."""
        stated = self.spec.flange_frame
        tcp = self._relative_to_flange(self.frame_tcp, stated)
        reflector = self._relative_to_flange(self.frame_reflector, stated)
        return tcp, reflector.translation.copy(), reflector.rotation @ self.reflector_axis

    @property
    def transform_tcp_to_flange(self) -> pin.SE3:
        """TCP pose in :attr:`frame_flange`, read from the model's frames (calibrated tool errors
        included); robot.yaml's own frame: :meth:`tool_facts`."""
        return self._relative_to_flange(self.frame_tcp)

    @property
    def reflector_offset_m(self) -> np.ndarray:
        """Reflector centre in :attr:`frame_flange` (from the model's frames); robot.yaml's own frame:
        :meth:`tool_facts`."""
        return self._relative_to_flange(self.frame_reflector).translation.copy()

    @property
    def reflector_axis(self) -> np.ndarray:
        """Reflector opening axis in the reflector frame: robot.yaml's axis, stated in ``flange_frame``,
        in which ``load`` builds the reflector frame unturned; the axis turns with the reflector frame
        (a calibrated tool rotation), so in the base frame it is ``R_reflector @ reflector_axis``."""
        return np.asarray(self.spec.tool.reflector_axis, float).copy()

    @property
    def payload_kg(self) -> float:
        return self.spec.payload_kg

    @property
    def urdf_path(self) -> Path:
        return self.spec.urdf

    def new_data(self) -> pin.Data:
        return self.model.createData()

    def frame_id(self, frame: str) -> int:
        if frame not in self._frame_ids:
            if not self.model.existFrame(frame):
                raise KeyError(f"unknown frame '{frame}'")
            self._frame_ids[frame] = self.model.getFrameId(frame)
        return self._frame_ids[frame]

    # --------------------------------------------------------------- kinematics
    def residual_map_of(self, frame: str) -> ResidualMap | None:
        """The residual map where it applies: the tool frames (flange, TCP, reflector), which move with
        the marker it was fitted at (a position correction, the same for points a tool's length apart)."""
        tool = frame in (self.frame_flange, self.frame_tcp, self.frame_reflector, self.spec.flange_frame)
        return self.residual_map if tool else None

    def _offsets(self, Q: np.ndarray, frame: str) -> np.ndarray | float:
        rmap = self.residual_map_of(frame)
        return 0.0 if rmap is None else rmap.predict(Q)[0]

    def fk(self, q: np.ndarray, frame: str = "tcp") -> pin.SE3:
        """Pose of ``frame`` in the base frame (a tool frame with the residual map's correction)."""
        fid = self.frame_id(frame)
        pin.forwardKinematics(self.model, self._data, np.asarray(q, float))
        pose = pin.updateFramePlacement(self.model, self._data, fid).copy()
        rmap = self.residual_map_of(frame)
        if rmap is not None:
            pose.translation = pose.translation + rmap.mean(q)
        return pose

    def positions(self, Q: np.ndarray, frame: str = "tcp") -> np.ndarray:
        """Positions ``(N, 3)`` of ``frame`` for configurations ``Q (N, nq)``."""
        Q = np.atleast_2d(np.asarray(Q, float))
        fid = self.frame_id(frame)
        out = np.empty((len(Q), 3))
        model, data = self.model, self._data
        for k, q in enumerate(Q):
            pin.forwardKinematics(model, data, q)
            out[k] = pin.updateFramePlacement(model, data, fid).translation
        return out + self._offsets(Q, frame)

    def poses(self, Q: np.ndarray, frame: str = "tcp") -> tuple[np.ndarray, np.ndarray]:
        """Positions ``(N, 3)`` and rotations ``(N, 3, 3)`` of ``frame``."""
        Q = np.atleast_2d(np.asarray(Q, float))
        fid = self.frame_id(frame)
        pos, rot = np.empty((len(Q), 3)), np.empty((len(Q), 3, 3))
        for k, q in enumerate(Q):
            pin.forwardKinematics(self.model, self._data, q)
            placement = pin.updateFramePlacement(self.model, self._data, fid)
            pos[k], rot[k] = placement.translation, placement.rotation
        return pos + self._offsets(Q, frame), rot

    def jacobian(self, q: np.ndarray, frame: str = "tcp") -> np.ndarray:
        """Frame Jacobian ``(6, nq)`` in LOCAL_WORLD_ALIGNED (linear rows first, with the residual map's)."""
        J = pin.computeFrameJacobian(self.model, self._data, np.asarray(q, float), self.frame_id(frame), WORLD)
        rmap = self.residual_map_of(frame)
        if rmap is not None:
            J[:3] += rmap.jacobian(q)
        return J

    def within_limits(self, q: np.ndarray, margin_rad: float = 0.0) -> bool:
        q = np.asarray(q, float)
        return bool(np.all(q >= self.model.lowerPositionLimit + margin_rad)
                    and np.all(q <= self.model.upperPositionLimit - margin_rad))

    def ik(self, target: pin.SE3, q0: np.ndarray, frame: str = "tcp", *, position_only: bool = False,
           tolerance_m: float = 1e-9, tolerance_rad: float = 1e-9, max_iterations: int = 200,
           restarts: int = 8, rng: np.random.Generator | None = None) -> IKResult:
        """Inverse kinematics inside the joint limits (:func:`pipeline.robot.ik.solve_ik`); with a residual
        map the rigid model's target is shifted by the map at the solution until the corrected tool
        frame reaches ``target`` (a fixed point: the map changes by far less than the arm over a step)."""
        def solve(goal: pin.SE3, start: np.ndarray, tries: int) -> IKResult:
            return solve_ik(self.model, self._data, self.frame_id(frame), goal, start, position_only=position_only,
                            tolerance_m=tolerance_m, tolerance_rad=tolerance_rad, max_iterations=max_iterations,
                            restarts=tries, rng=rng)

        result = solve(target, q0, restarts)
        rmap = self.residual_map_of(frame)
        if rmap is None:
            return result
        for _ in range(10):
            miss = float(np.linalg.norm(self.fk(result.q, frame).translation - target.translation))
            if not result.success or miss <= tolerance_m:
                break
            result = solve(pin.SE3(target.rotation, target.translation - rmap.mean(result.q)), result.q, 0)
        miss = float(np.linalg.norm(self.fk(result.q, frame).translation - target.translation))
        if result.success and miss > tolerance_m:
            result.success, result.position_error_m = False, miss
            result.message = f"IK with the residual map did not settle within {tolerance_m:g} m ({miss:.3g} m)"
        return result

    # ----------------------------------------------------------------- dynamics
    def friction_torque(self, v: np.ndarray) -> np.ndarray:
        """Joint friction ``f_v v + f_c tanh(v / width)`` (smooth Coulomb, DESIGN.md) plus the
        identified Stribeck excess when the actuation has one (:mod:`pipeline.robot.friction`); the
        load-dependent term is :meth:`load_friction_torque`."""
        return joint_friction_torque(self.spec.actuation, v)

    def load_friction_torque(self, load_Nm: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The identified load-dependent Coulomb friction at the load torque ``load_Nm`` (the model's
        torque without it: rigid body + :meth:`friction_torque`); zero without one."""
        return load_friction_torque(self.spec.actuation, load_Nm, v)

    def inverse_dynamics(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """``tau_0 = M(q) a + h(q, v) + friction(v)``, ``tau = tau_0 + load friction(tau_0, v)``; M
        includes the rotor inertia (armature)."""
        tau = pin.rnea(self.model, self._data, np.asarray(q, float), np.asarray(v, float), np.asarray(a, float))
        tau0 = tau + self.friction_torque(v)
        if self.spec.actuation.coulomb_load_coefficient is None:
            return tau0
        return tau0 + self.load_friction_torque(tau0, v)

    def forward_dynamics(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Joint accelerations under ``tau`` minus friction (ABA, armature included); the load-dependent
        friction from the load behind ``tau`` (:func:`pipeline.robot.friction.load_free_from_applied`)."""
        tau0 = load_free_from_applied(self.spec.actuation, tau, v)
        return pin.aba(self.model, self._data, np.asarray(q, float), np.asarray(v, float),
                       tau0 - self.friction_torque(v)).copy()

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        mass = pin.crba(self.model, self._data, np.asarray(q, float))
        return np.triu(mass) + np.triu(mass, 1).T

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        return pin.computeGeneralizedGravity(self.model, self._data, np.asarray(q, float)).copy()

    # ---------------------------------------------------------------- collision
    def capsule_segments(self, Q: np.ndarray) -> np.ndarray:
        """World end points of every capsule, shape ``(N, n_capsules, 2, 3)``."""
        caps = self.spec.capsules
        return capsule_segments(self.model, self._data, caps, [self.frame_id(c.frame) for c in caps], Q)

    def capsule_clearances(self, segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Self-pair and floor clearances ``(N, n_pairs)``, ``(N, n_floor)`` from capsule segments."""
        return capsule_clearances(self.spec, self._self_pairs, self._floor_capsules, segments)

    def capsule_distances(self, q: np.ndarray) -> CapsuleDistances:
        """Signed clearances between non-adjacent link capsules and of link capsules to the floor."""
        pair, floor = self.capsule_clearances(self.capsule_segments(q))
        names = [c.name for c in self.spec.capsules]
        return CapsuleDistances([(names[i], names[k]) for i, k in self._self_pairs], pair[0],
                                [names[i] for i in self._floor_capsules], floor[0])

    def typical_pair_clearances_m(self, samples: int = 200) -> np.ndarray:
        """``(n_pairs,)`` median clearance of each checked capsule pair over random configurations
        inside the limits (seed 0; the pairs of :attr:`self_collision_pairs`)."""
        if not self._self_pairs:
            return np.zeros(0)
        rng = np.random.default_rng(0)
        Q = rng.uniform(self.model.lowerPositionLimit, self.model.upperPositionLimit, size=(samples, self.nq))
        return np.median(self.capsule_clearances(self.capsule_segments(Q))[0], axis=0)

    @property
    def self_collision_pairs(self) -> list[tuple[int, int]]:
        """Index pairs of capsules checked against each other (non-adjacent links)."""
        return list(self._self_pairs)

    @property
    def floor_capsules(self) -> list[int]:
        return list(self._floor_capsules)

    def in_collision(self, q: np.ndarray, margin_m: float = 0.0) -> bool:
        distances = self.capsule_distances(q)
        return bool(min(distances.self_min_m, distances.floor_min_m) < margin_m)

    # ------------------------------------------------------------------ summary
    def summary(self) -> dict[str, object]:
        """DOF, reach (axis 1 to flange), moving mass and limits in readable units."""
        rng = np.random.default_rng(0)
        lim = self.limits
        samples = rng.uniform(lim.lower_rad, lim.upper_rad, size=(4000, self.nq))
        joint1 = self.model.jointPlacements[1]
        axis = joint1.rotation[:, 2]
        flange = self.positions(samples, self.frame_flange) - joint1.translation
        radial = flange - np.outer(flange @ axis, axis)
        reach = float(np.max(np.linalg.norm(radial, axis=1)))
        # refine the sampled maximum with the stretched configuration search of scipy
        best = samples[int(np.argmax(np.linalg.norm(radial, axis=1)))]

        def negative_reach(q: np.ndarray) -> float:
            p = self.fk(q, self.frame_flange).translation - joint1.translation
            return -float(np.linalg.norm(p - (p @ axis) * axis))

        refined = minimize(negative_reach, best, bounds=list(zip(lim.lower_rad, lim.upper_rad, strict=True)))
        reach = max(reach, -float(refined.fun))
        return {
            "name": self.name,
            "dof": self.nq,
            "reach_m": reach,
            "moving_mass_kg": float(sum(self.model.inertias[j].mass for j in range(1, self.model.njoints))),
            "payload_kg": self.payload_kg,
            "joint_names": [str(n) for n in self.model.names[1:]],
            "lower_deg": np.rad2deg(lim.lower_rad).round(3).tolist(),
            "upper_deg": np.rad2deg(lim.upper_rad).round(3).tolist(),
            "velocity_deg_s": np.rad2deg(lim.velocity_rad_s).round(3).tolist(),
            "effort_Nm": lim.effort_Nm.round(3).tolist(),
            "acceleration_deg_s2": np.rad2deg(lim.acceleration_rad_s2).round(3).tolist(),
            "gear_ratio": self.actuation.gear_ratio.tolist(),
        }

    # ------------------------------------------------------------ copy and save
    def copy(self) -> RobotModel:
        out = RobotModel(_copy.deepcopy(self.spec), self.model.copy(), self.urdf_text)
        out.residual_map = self.residual_map     # frozen: shared
        return out

    def with_model(self, model: pin.Model, spec: RobotSpec | None = None) -> RobotModel:
        """A RobotModel sharing this one's facts (and residual map) but with another Pinocchio model
        (same frames)."""
        out = RobotModel(_copy.deepcopy(spec if spec is not None else self.spec), model, self.urdf_text)
        out.residual_map = self.residual_map
        return out

    def save(self, folder: str | Path, urdf_text: str | None = None) -> Path:
        """Write ``<folder>/<name>.urdf`` and ``robot.yaml`` that :meth:`load` reads back.

        Joint placements, link inertials (as Pinocchio holds them, including identified or
        calibrated values), limits, armature and friction are written; visuals are kept from
        the source URDF. ``urdf_text``: the URDF to write instead of the model's own export (the
        same model in another form, e.g. with its source's joint types). Files are written atomically.
        """
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        urdf_name = f"{self.name}.urdf"
        spec = _copy.deepcopy(self.spec)
        spec.actuation.rotor_inertia_kgm2 = np.asarray(self.model.armature, float).copy()
        # tool frames as the model holds them (load() rebuilds them from these three facts)
        spec.tool.transform_tcp_to_flange, spec.tool.reflector_offset_m, spec.tool.reflector_axis = self.tool_facts()
        spec.limit_overrides = {}
        if urdf_text is None:
            urdf_text = export_urdf(self.model, self.urdf_text)
            if self.urdf_path is not None and Path(self.urdf_path).is_file():
                urdf_text = absolute_mesh_paths(urdf_text, Path(self.urdf_path))   # meshes still found from folder
        write_text(folder / urdf_name, urdf_text)
        write_text(folder / "robot.yaml", dump_yaml(robot_spec_to_yaml(spec, urdf_name)))
        return folder
