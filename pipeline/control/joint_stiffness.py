"""The joint stiffness the elastic-joint feedforward uses, where it comes from, and what it is worth.

The elastic variants (:mod:`pipeline.control.elastic_feedforward`) lead each motor by the joint's
deflection ``tau_l / k`` (paper ``004_abbe750b8bbcc3aa.txt`` §2.3, "gear elasticities"), so a
relative stiffness error ``e`` leaves ``e tau_l / k`` of it uncompensated. Sources, per joint:

* ``calibrated``: ``1 / c`` of the elastostatic calibration (:mod:`pipeline.calibration.elastostatic`);
  with identified inertias downstream it is re-expressed for their gravity torques
  (:func:`pipeline.robot.stiffness.stiffness_for_gravity_model`): the calibration fits the
  compliance against the gravity torques of *its* model (nominal inertias, ~15 % mass errors),
  which biases each stiffness by the relative error of that joint's torque;
* ``nominal``: robot.yaml or the rated-torque rule (:mod:`pipeline.robot.stiffness`), for joints the
  calibration cannot identify (no gravity load: a vertical first axis, a wrist whose torque does not
  vary over the measured poses; or a compliance below :data:`MIN_SIGNIFICANCE` standard deviations,
  which says little more than "not rigid") or when the run has no elastostatic calibration.

:func:`deflection_budget` states the cost: per joint the largest TCP displacement of the deflection
the feedforward compensates along the reference (``|J_i(q)| |tau_l,i| / k_i``, first order), so a
stiffness wrong by ``e`` costs about ``e`` times that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.control.elastic_feedforward import link_torque
from pipeline.robot.handoff import ElastostaticRecord
from pipeline.robot.model import RobotModel
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad, stiffness_for_gravity_model

#: a calibrated compliance is used when it is at least this many standard deviations (else nominal)
MIN_SIGNIFICANCE = 3.0


@dataclass
class StiffnessChoice:
    """Per joint: stiffness (N m/rad), source label, and the gravity-model factor applied (1: none)."""

    stiffness_Nm_rad: np.ndarray
    source: list[str]
    gravity_factor: np.ndarray
    elastostatic_calibration: bool = False   # the run's calibration fitted compliances

    @property
    def nominal_joints(self) -> list[int]:
        """1-based joints whose stiffness is nominal (not identified)."""
        return [i + 1 for i, s in enumerate(self.source) if s.startswith("nominal")]


def feedforward_stiffness(robot: RobotModel, record: ElastostaticRecord | None,
                          identified_inertias: bool,
                          nominal_Nm_rad: np.ndarray | None = None) -> StiffnessChoice:
    """The stiffness for the feedforward of ``robot`` (the run's best model, carrying the calibrated
    stiffness in ``actuation.joint_stiffness_Nm_rad``) and its source per joint.

    With the calibration's static-torque ``record``: a joint whose compliance the calibration
    identified keeps it if it is significant (``c >= MIN_SIGNIFICANCE`` standard deviations,
    ``record.compliance_std_rad_Nm``), else takes ``nominal_Nm_rad`` (default: ``robot``'s
    value); with identified inertias (``identified_inertias``) the calibrated ones are re-expressed
    for their gravity torques (module docstring)."""
    k = nominal_joint_stiffness_Nm_rad(robot)
    k_nom = k.copy() if nominal_Nm_rad is None else np.asarray(nominal_Nm_rad, float).copy()
    fitted = record is not None
    known = np.zeros(robot.nq, bool) if record is None else record.stiffness_identified.copy()
    # without a record (a rigid calibration, or artefacts written before it existed) a value that is not
    # the nominal one came from upstream
    source = ["calibrated" if kn else "nominal" if fitted or np.isclose(k[i], k_nom[i]) else "as handed on"
              for i, kn in enumerate(known)]
    std = np.zeros(robot.nq) if record is None else record.compliance_std_rad_Nm
    weak = known & ~(1.0 / k >= MIN_SIGNIFICANCE * np.nan_to_num(std, nan=np.inf))
    for i in np.flatnonzero(weak):
        source[i], k[i] = f"nominal (calibrated compliance < {MIN_SIGNIFICANCE:g} sigma)", k_nom[i]
    known &= ~weak
    factor = np.ones(robot.nq)
    if (identified_inertias and known.any() and record is not None and record.configurations_rad is not None
            and record.torques_Nm is not None and record.payload_torques_Nm is not None):
        g_fit = record.torques_Nm
        g_new = np.array([robot.gravity_torque(q) for q in record.configurations_rad]) + record.payload_torques_Nm
        k, factor = stiffness_for_gravity_model(k, known, g_fit, g_new)
        source = ["calibrated, identified gravity" if kn else src for kn, src in zip(known, source, strict=True)]
    return StiffnessChoice(k, source, factor, fitted)


def deflection_budget(robot: RobotModel, q_d: np.ndarray, v_d: np.ndarray, a_d: np.ndarray,
                      stiffness_Nm_rad: np.ndarray,
                      frame: str, stride: int = 5) -> dict[str, list[float]]:
    """Per joint along the reference (every ``stride``-th sample): the largest deflection the elastic
    feedforward compensates, ``max |tau_l,i| / k_i`` (rad), and its TCP displacement
    ``max |J_i(q)| |tau_l,i| / k_i`` (m; ``J_i`` the linear Jacobian column of ``frame``)."""
    s = slice(None, None, max(1, int(stride)))
    q, v, a = q_d[s], v_d[s], a_d[s]
    defl = np.abs(link_torque(robot, q, v, a)) / np.asarray(stiffness_Nm_rad, float)
    lever = np.array([np.linalg.norm(robot.jacobian(qk, frame)[:3], axis=0) for qk in q])
    return {"deflection_max_rad": defl.max(axis=0).tolist(),
            "tcp_deflection_max_m": (lever * defl).max(axis=0).tolist()}


def stiffness_markdown(choice: StiffnessChoice, budget: dict[str, list[float]]) -> str:
    """Report section: stiffness per joint, source, factor, and the cost of a stiffness error."""
    rows = ["### Joint stiffness of the elastic feedforward", "",
            "| joint | k [N·m/rad] | source | gravity-model factor | max compensated deflection [mrad] | "
            "its TCP effect [µm] |", "|---|---|---|---|---|---|"]
    for i, (k, src) in enumerate(zip(choice.stiffness_Nm_rad, choice.source, strict=True)):
        rows.append(f"| {i + 1} | {k:.4g} | {src} | {choice.gravity_factor[i]:.3f} | "
                    f"{budget['deflection_max_rad'][i] * 1e3:.3f} | {budget['tcp_deflection_max_m'][i] * 1e6:.0f} |")
    nominal = choice.nominal_joints
    rows.append("")
    if nominal:
        cost = sum(budget["tcp_deflection_max_m"][j - 1] for j in nominal)
        why = ("the elastostatic calibration did not identify it: no gravity load varying over the measured "
               f"poses, a non-positive estimate, or one below {MIN_SIGNIFICANCE:g} standard deviations"
               if choice.elastostatic_calibration
               else "this run has no elastostatic calibration")
        rows.append(f"Joints {', '.join(map(str, nominal))}: nominal stiffness (robot.yaml or the rated-torque rule; "
                    f"{why}). The feedforward compensates up to {cost * 1e6:.0f} µm of TCP deflection on them "
                    f"together; each 10 % of stiffness error leaves about {0.1 * cost * 1e6:.0f} µm of it "
                    "uncompensated (first order).")
    if any(f != 1.0 for f in choice.gravity_factor):
        rows.append("Calibrated stiffnesses are re-expressed for the identified inertias (factor = "
                    "sum g_cal g_id / sum g_cal², over the calibration's poses): the calibration fitted the "
                    "compliances against its own gravity model's torques.")
    return "\n".join(rows)
