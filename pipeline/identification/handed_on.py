"""The robot the identification hands on, step 4 of :mod:`pipeline.identification.stage`: the fits'
standard parameters and friction terms (:func:`.outcome.identified_robot`), and what it keeps from the
previous model (robot.yaml or the calibrated one), each stated in the summary's warnings:

* the link inertias and drive values of the joints left out of the fit (:func:`with_unmeasured_joints_kept`);
* the rotor inertia of the joints whose torques show none (:func:`unseen_rotor_inertia_joints`), still
  labelled as ``robot init``'s assumption when it was one (:func:`label_kept_assumptions`, as are the
  drive values kept for the joints left out).
"""

from __future__ import annotations

import numpy as np

from pipeline.identification import estimate as est_mod
from pipeline.identification.config import Config
from pipeline.identification.friction import LoadFriction, expand_to_joints
from pipeline.identification.joints import JointSelection
from pipeline.identification.outcome import Fits, Regressors, identified_robot
from pipeline.identification.regressor import standard_parameters
from pipeline.robot.assumed_values import value_digest
from pipeline.robot.model import RobotModel


def load_to_joints(load: LoadFriction, used: np.ndarray, nq: int) -> LoadFriction:
    """The term of the measured joints ``used`` on all ``nq`` joints (0 on the others)."""
    coef = np.zeros(nq)
    coef[used] = load.coefficient
    return LoadFriction(coef, load.coulomb_width_rad_s)


def handed_on_robot(robot: RobotModel, regs: Regressors, fits: Fits) -> RobotModel:
    """``robot`` with the handed-on fit's standard parameters and friction terms (Stribeck,
    load-dependent Coulomb) on all joints and the Coulomb smoothing widths the fits used (a record's, chosen
    per joint by :mod:`.coulomb_width`) (:func:`.outcome.identified_robot`); the joints left out keep
    ``robot``'s values (:func:`with_unmeasured_joints_kept`), the joints ``fits.stated_rotor_joints``
    ``robot``'s rotor inertia (:func:`unseen_rotor_inertia_joints`)."""
    nq = robot.nq
    p = with_stated_rotor_inertia(robot, with_unmeasured_joints_kept(robot, regs.selection, fits.phys.p),
                                  fits.stated_rotor_joints)
    handed = identified_robot(robot, p,
                              None if fits.stribeck is None else expand_to_joints(fits.stribeck, regs.used, nq),
                              None if fits.load is None else load_to_joints(fits.load.load, regs.used, nq),
                              regs.reg.joint_coulomb_width_rad_s)
    left_out = np.array(sorted(regs.selection.left_out), int)
    label_kept_assumptions(robot, handed, {
        "rotor_inertia_kgm2": np.union1d(fits.stated_rotor_joints, left_out).astype(int),
        "viscous_Nms_rad": left_out, "coulomb_Nm": left_out})
    return handed


#: robot.yaml's rotor inertia (its ``assumed`` key)
ROTOR_INERTIA_KEY = "actuation.rotor_inertia_kgm2"
#: a fitted rotor inertia below this multiple of its lower bound (:data:`.estimate.POSITIVE_LOWER_BOUND`)
#: sits on the bound (IPOPT's interior point ends a hair inside or outside it)
ON_BOUND_FACTOR = 2.0


def unseen_rotor_inertia_joints(regs: Regressors, p: np.ndarray) -> np.ndarray:
    """0-based measured joints whose torques show no inertia of the rotor: the physically consistent
    fit ``p`` put the joint's rotor inertia ``I_a,j`` on its lower bound (``<`` :data:`ON_BOUND_FACTOR` x
    :data:`.estimate.POSITIVE_LOWER_BOUND`).

    The rotor of a geared drive has an inertia ``I_m r^2`` well above the links' on the wrist; torques
    that carry no ``I_a,j qdd_j`` (a drive that logs its effort without the rotor's) leave it unidentified,
    not 0, and a model handed on with 1e-6 kg m^2 there gives the elastic plant's motor side nothing to
    move and a servo loop nothing to act on. A rotor inertia grouped with a link's (``I_a,1 + ZZ_1`` of a
    first vertical axis) sits on its bound only when the torques leave the sum no more than the link's
    own inertia, which the fit pulls towards the nominal one: they show no rotor there either."""
    ia = p[10 * (regs.reg.model.njoints - 1) + regs.used]
    return np.asarray(regs.used, int)[ia < ON_BOUND_FACTOR * est_mod.POSITIVE_LOWER_BOUND]


def keep_unseen_rotor_inertia(cfg: Config, regs: Regressors, fits: Fits) -> None:
    """With ``unseen_rotor_inertia: stated`` (default) set ``fits.stated_rotor_joints`` to the joints of
    :func:`unseen_rotor_inertia_joints` on the handed-on fit, so the robot handed on keeps robot.yaml's
    rotor inertia there (:func:`handed_on_robot`); with ``fitted`` none."""
    fits.stated_rotor_joints = (unseen_rotor_inertia_joints(regs, fits.phys.p) if cfg.unseen_rotor_inertia == "stated"
                                else np.zeros(0, int))


def with_stated_rotor_inertia(robot: RobotModel, p: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Standard parameters ``p`` with ``robot``'s rotor inertia on the 0-based ``joints`` (a copy)."""
    out = np.array(p, float)
    out[10 * (robot.model.njoints - 1) + np.asarray(joints, int)] = np.asarray(
        robot.actuation.rotor_inertia_kgm2, float)[np.asarray(joints, int)]
    return out


def label_kept_assumptions(robot: RobotModel, handed: RobotModel, kept: dict[str, np.ndarray]) -> None:
    """For each drive value ``name`` of ``kept`` (``rotor_inertia_kgm2``, ``viscous_Nms_rad``,
    ``coulomb_Nm``) that is ``robot init``'s assumption on ``robot`` and that ``handed`` keeps on the
    0-based joints ``kept[name]`` (torques that show no rotor inertia, joints left out of the fit), the
    assumption stays in force on ``handed``'s robot.yaml: its ``assumed`` entry gets the digest of the
    values handed on and a rule naming those joints, so a placeholder read back is still a placeholder
    (:mod:`pipeline.robot.assumed_values`; the whole vector is then assumed, the fitted joints' values
    included, and a later fit is not pulled towards any of them)."""
    for name, joints in kept.items():
        key = f"actuation.{name}"
        entry = robot.spec.assumed.get(key)
        if entry is None or not len(joints):
            continue
        which = ", ".join(str(int(j) + 1) for j in joints)
        handed.spec.assumed[key] = {
            "rule": f"{entry['rule']} on joint(s) {which}, which no torque identified; the others identified",
            "sha256": value_digest([float(v) for v in getattr(handed.actuation, name)])}


def unseen_rotor_note(robot: RobotModel, joints: np.ndarray) -> str:
    """One line for the summary's warnings: the joints whose rotor inertia the handed-on model takes from
    robot.yaml, with its values and whether they are ``robot init``'s assumption ("" when none)."""
    if not len(joints):
        return ""
    ia = np.asarray(robot.actuation.rotor_inertia_kgm2, float)
    assumed = ROTOR_INERTIA_KEY in robot.spec.assumed
    which = ", ".join(f"joint {j + 1} {ia[j]:.3g} kg m²" for j in joints)
    return (f"the torques show no rotor inertia on joint(s) {', '.join(str(j + 1) for j in joints)} "
            f"(the physically consistent fit puts it on its bound {est_mod.POSITIVE_LOWER_BOUND:g} kg m²): the robot "
            f"handed on keeps robot.yaml's {which}"
            f"{' (ASSUMED by robot init)' if assumed else ''}, which no torque validated "
            "(identification.unseen_rotor_inertia: fitted hands on the fit's)")


def with_unmeasured_joints_kept(robot: RobotModel, selection: JointSelection, p: np.ndarray) -> np.ndarray:
    """Standard parameters ``p`` with, for every joint left out of the fit, ``robot``'s values of its
    link's inertial parameters and of its drive train (rotor inertia, viscous and Coulomb friction).

    The fit sees those parameters only through the torques of the joints before them in the chain,
    in combinations (a one-joint fit puts a link mass 40 % off and a wrist inertia on its bound):
    handed on, they would give a later stage the wrong dynamics on the joints no torque validated."""
    if selection.all_used:
        return p
    nq, n_links = robot.nq, robot.model.njoints - 1
    act = robot.actuation
    kept = standard_parameters(robot.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    out = np.array(p, float)
    for j in selection.left_out:
        for idx in ([*range(10 * j, 10 * j + 10)] if j < n_links else []) + [10 * n_links + g * nq + j
                                                                               for g in range(3)]:
            out[idx] = kept[idx]
    return out


def unmeasured_joints_note(sel: JointSelection) -> str:
    """One line for the summary's warnings: which joints the handed-on model keeps nominal ("" when none)."""
    if sel.all_used:
        return ""
    left = ", ".join(sel.names[j] for j in sorted(sel.left_out))
    return (f"identified joint(s) {', '.join(sel.names[j] for j in sel.used)} only: the handed-on model keeps "
            f"the previous (nominal or calibrated) link inertias and drive values of {left}")
