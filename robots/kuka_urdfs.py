"""Generate the URDFs of the three KUKA arms of paper 000 §3.3.1 (KR 15, KR 300, KR 500).

Run: ``python robots/kuka_urdfs.py``; writes ``robots/kuka_kr*/kuka_kr*.urdf``. Every number is
either from a public source (stated per arm below) or an estimate (marked "estimate").

Kinematics: modified DH (Craig) tables in the convention of ``robots/rx130l`` and of the
*robotkinematicscatalogue* package (PyPI, file ``KUKA_KR500_R2830.py``): the zero pose is KUKA's
(A2 = 0: upper arm horizontal forward, A3 = 0: forearm continuing the upper arm), axes 2 and 3 turn
about +y as in KUKA's controller and the ROS-Industrial descriptions. Axes 1, 4 and 6 turn about
+z here while KUKA counts them about -z: their ranges are symmetric, so only the sign of those
angles differs from KUKA's display.

Lengths (d1, a1, a2, a3, d4, d6) are the data-sheet dimensions of each arm; KUKA's "reach" is
a1 + a2 + d4 (axis 1 to the wrist point), which each table reproduces:
- KR 15 (the KR 6/15/16 low-payload series, one kinematics): 675, 260, 680, 35, 670, 115 mm,
  reach 1610 mm (ARTE toolbox ``robots/KUKA/KR16_2/parameters.m`` and ``KR6_2``; KUKA KR 16
  data sheet: reach 1611 mm); ranges A1 ±185°, A2 -155/+35°, A3 -130/+154°, A4 ±350°, A5 ±130°,
  A6 ±350°; speeds 156, 156, 156, 330, 330, 615 °/s (same sources).
- KR 300 R2500 ultra: 675, 350, 1150, 41, 1000, 240 mm, reach 2500 mm (ROS description
  raccoon-ncku/kuka_kr300_support ``urdf/kr300r2500ultra_macro.xacro``); ranges A1 ±185°,
  A2 -140/-5°, A3 -120/+155°, A4 ±350°, A5 ±122.5°, A6 ±350° (KUKA KR QUANTEC data sheet);
  speeds 105, 107, 114, 136, 129, 206 °/s (estimate: KR QUANTEC ultra data-sheet class values).
- KR 500 R2830: 1045, 500, 1300, 55, 1025, 290 mm, reach 2825 mm (robotkinematicscatalogue
  ``KUKA_KR500_R2830.py``); ranges A1 ±185°, A2 -130/+20°, A3 -100/+144°, A4 ±350°, A5 ±120°,
  A6 ±350° (same file); speeds 79, 76, 76, 111, 110, 184 °/s (estimate, KR 500 data-sheet class).

Masses (estimate): the data-sheet total mass (KR 16: 235 kg, KR 300 R2500 ultra: about 1120 kg,
KR 500 R2830: about 2350 kg) minus a fixed base of 25 %, split over the moving links in the
proportions of the RX130L estimates of docs/DESIGN.md (45 : 35 : 20 : 22 : 2 : 0.3); centres of
mass mid-link, inertias of solid cylinders of the link's length and capsule radius
(:func:`pipeline.robot.mdh.cylinder_inertia`). Torque limits (estimate): 1.5 x the largest static
gravity torque of the stretched arm with the rated payload (computed here with Pinocchio), at
least 2 % of axis 1's for the wrist.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from pipeline.robot.mdh import JointSpec, LinkSpec, MDHRobotSpec, MDHRow, cylinder_inertia, urdf_from_mdh

HERE = Path(__file__).parent
DEG = np.pi / 180.0
#: RX130L moving-link mass proportions (docs/DESIGN.md "The robot")
MASS_SHARES = np.array([45.0, 35.0, 20.0, 22.0, 2.0, 0.3]) / 124.3


@dataclass(frozen=True)
class KukaArm:
    name: str
    d1: float
    a1: float
    a2: float
    a3: float
    d4: float
    d6: float
    range_deg: tuple[tuple[float, float], ...]
    speed_deg_s: tuple[float, ...]
    total_mass_kg: float
    payload_kg: float
    radius_m: tuple[float, ...]   # column, upper arm, elbow, forearm, wrist, flange (visual/inertia)

    def rows(self) -> list[MDHRow]:
        return [
            MDHRow(0.0, 0.0, 0.0, self.d1),
            MDHRow(-np.pi / 2, self.a1, 0.0, 0.0),
            MDHRow(0.0, self.a2, -np.pi / 2, 0.0),
            MDHRow(-np.pi / 2, -self.a3, 0.0, self.d4),
            MDHRow(np.pi / 2, 0.0, 0.0, 0.0),
            MDHRow(-np.pi / 2, 0.0, np.pi, self.d6),
        ]


ARMS = {
    "kuka_kr15": KukaArm("kuka_kr15", 0.675, 0.260, 0.680, 0.035, 0.670, 0.115,
                         ((-185, 185), (-155, 35), (-130, 154), (-350, 350), (-130, 130), (-350, 350)),
                         (156, 156, 156, 330, 330, 615), 235.0, 15.0, (0.20, 0.12, 0.11, 0.08, 0.06, 0.04)),
    "kuka_kr300": KukaArm("kuka_kr300", 0.675, 0.350, 1.150, 0.041, 1.000, 0.240,
                          ((-185, 185), (-140, -5), (-120, 155), (-350, 350), (-122.5, 122.5), (-350, 350)),
                          (105, 107, 114, 136, 129, 206), 1120.0, 300.0, (0.40, 0.25, 0.25, 0.17, 0.13, 0.09)),
    "kuka_kr500": KukaArm("kuka_kr500", 1.045, 0.500, 1.300, 0.055, 1.025, 0.290,
                          ((-185, 185), (-130, 20), (-100, 144), (-350, 350), (-120, 120), (-350, 350)),
                          (79, 76, 76, 111, 110, 184), 2350.0, 500.0, (0.50, 0.32, 0.30, 0.21, 0.16, 0.11)),
}


def _link(mass: float, start: list[float], end: list[float], radius: float, axis: int) -> LinkSpec:
    start_m, end_m = np.array(start, float), np.array(end, float)
    length = float(np.linalg.norm(end_m - start_m))
    return LinkSpec(mass_kg=mass, com_m=list(0.5 * (start_m + end_m)),
                    inertia_kgm2=list(cylinder_inertia(mass, radius, length, axis)),
                    visual_from_m=list(start_m), visual_to_m=list(end_m), visual_radius_m=radius)


def links(arm: KukaArm) -> list[LinkSpec]:
    m = 0.75 * arm.total_mass_kg * MASS_SHARES
    r = arm.radius_m
    return [
        _link(m[0], [0, 0, -0.6 * arm.d1], [arm.a1, 0, 0], r[0], axis=2),       # rotating column
        _link(m[1], [0, 0, 0], [arm.a2, 0, 0], r[1], axis=0),                   # upper arm
        _link(m[2], [0, 0, 0], [-arm.a3, 0.3 * arm.d4, 0], r[2], axis=1),       # elbow housing
        _link(m[3], [0, 0, -0.7 * arm.d4], [0, 0, 0], r[3], axis=2),            # forearm (rolls with A4)
        _link(m[4], [0, 0, 0], [0, 0.5 * arm.d6, 0], r[4], axis=1),             # wrist
        _link(m[5], [0, 0, -0.02], [0, 0, 0], r[5], axis=2),                    # flange
    ]


def tool_visuals() -> list[str]:
    return [
        '  <joint name="flange_joint" type="fixed"><origin xyz="0 0 0" rpy="0 0 0"/>',
        '    <parent link="link_6"/><child link="flange"/></joint>',
        '  <link name="flange">',
        '    <visual><origin xyz="0 0 0.1" rpy="0 0 0"/><geometry><cylinder radius="0.03" length="0.2"/>'
        '</geometry><material name="grey"/></visual>',
        '    <visual><origin xyz="0.05 0 0.12" rpy="0 0 0"/><geometry><sphere radius="0.019"/></geometry>'
        '<material name="dark"/></visual>',
        "  </link>",
    ]


def effort_limits(arm: KukaArm, urdf_text: str) -> np.ndarray:
    """1.5 x the largest static gravity torque over stretched poses with the payload (estimate)."""
    model = pin.buildModelFromXML(urdf_text)
    model.inertias[6] = model.inertias[6] + pin.Inertia.FromSphere(arm.payload_kg, 0.05).se3Action(
        pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.2])))
    data = model.createData()
    worst = np.zeros(model.nq)
    for q2 in np.linspace(arm.range_deg[1][0], arm.range_deg[1][1], 13) * DEG:
        for q5 in (-np.pi / 2, 0.0, np.pi / 2):
            q = np.array([0.0, q2, 0.0, 0.0, q5, 0.0])
            q[2] = np.clip(0.0, arm.range_deg[2][0] * DEG, arm.range_deg[2][1] * DEG)
            worst = np.maximum(worst, np.abs(pin.computeGeneralizedGravity(model, data, q)))
            q4 = q.copy()
            q4[3] = np.pi / 2
            worst = np.maximum(worst, np.abs(pin.computeGeneralizedGravity(model, data, q4)))
    effort = 1.5 * worst
    effort[0] = max(effort[0], effort[1])          # axis 1 carries the inertia of the whole arm
    return np.maximum(effort, 0.02 * effort[0])


def urdf(arm: KukaArm) -> str:
    def spec(effort: np.ndarray) -> MDHRobotSpec:
        joints = [JointSpec(lo * DEG, hi * DEG, v * DEG, float(e))
                  for (lo, hi), v, e in zip(arm.range_deg, arm.speed_deg_s, effort, strict=True)]
        return MDHRobotSpec(arm.name, arm.rows(), links(arm), joints, base_visual_height_m=0.5 * arm.d1,
                            base_visual_radius_m=1.2 * arm.radius_m[0], flange_extras=tool_visuals())

    first = urdf_from_mdh(spec(np.full(6, 1.0)))
    return urdf_from_mdh(spec(np.round(effort_limits(arm, first), 0)))


def main() -> None:
    for name, arm in ARMS.items():
        (HERE / name / f"{name}.urdf").write_text(urdf(arm))


if __name__ == "__main__":
    main()
