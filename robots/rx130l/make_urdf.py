"""Regenerate rx130l.urdf from the modified-DH table of DESIGN.md ("The robot").

Run: ``python robots/rx130l/make_urdf.py``. Masses, centres of mass and solid-cylinder
inertias are the estimates of DESIGN.md; the tool and reflector visuals follow robot.yaml.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from pipeline.robot.mdh import JointSpec, LinkSpec, MDHRobotSpec, MDHRow, cylinder_inertia, urdf_from_mdh

HERE = Path(__file__).parent
DEG = np.pi / 180.0

ROWS = [
    MDHRow(0.0, 0.0, 0.0, 0.550),
    MDHRow(-np.pi / 2, 0.0, -np.pi / 2, 0.0),
    MDHRow(0.0, 0.625, -np.pi / 2, 0.0),
    MDHRow(-np.pi / 2, 0.0, 0.0, 0.925),
    MDHRow(np.pi / 2, 0.0, 0.0, 0.0),
    MDHRow(-np.pi / 2, 0.0, np.pi, 0.110),
]
RANGE_DEG = [(-160, 160), (-137.5, 137.5), (-142.5, 142.5), (-270, 270), (-105, 120), (-270, 270)]
SPEED_DEG_S = [200, 200, 255, 315, 360, 870]
# DESIGN.md estimates 550, 500, 220, 55, 40, 30 N·m; axes 2 and 3 raised to 700 and 350 N·m because the
# estimated masses need 520 and 141 N·m just to hold the stretched arm (a real RX130L has a balancing
# spring on axis 2). Decision recorded in README.md, "Design decisions".
EFFORT_NM = [550, 700, 350, 55, 40, 30]


def _link(mass: float, start: list[float], end: list[float], radius: float, axis: int) -> LinkSpec:
    start_m, end_m = np.array(start), np.array(end)
    length = float(np.linalg.norm(end_m - start_m))
    return LinkSpec(
        mass_kg=mass,
        com_m=list(0.5 * (start_m + end_m)),
        inertia_kgm2=list(cylinder_inertia(mass, radius, length, axis)),
        visual_from_m=start,
        visual_to_m=end,
        visual_radius_m=radius,
    )


LINKS = [
    _link(45.0, [0, 0, -0.30], [0, 0, 0.0], 0.18, axis=2),  # column
    _link(35.0, [0, 0, 0], [0.625, 0, 0], 0.12, axis=0),  # upper arm
    _link(20.0, [0, 0, 0], [0, 0.20, 0], 0.11, axis=1),  # elbow housing (axis-4 drive)
    _link(22.0, [0, 0, -0.925], [0, 0, 0], 0.08, axis=2),  # forearm tube elbow to wrist (rolls with axis 4)
    _link(2.0, [0, 0, 0], [0, 0.08, 0], 0.06, axis=1),  # wrist
    _link(0.3, [0, 0, -0.02], [0, 0, 0], 0.05, axis=2),  # flange
]


def tool_visuals(robot_yaml: dict) -> list[str]:
    tcp = robot_yaml["tool"]["transform_tcp_to_flange"]["xyz"]
    reflector = robot_yaml["tool"]["reflector_offset_m"]
    length = float(np.linalg.norm(tcp))
    return [
        '  <joint name="flange_joint" type="fixed"><origin xyz="0 0 0" rpy="0 0 0"/>',
        '    <parent link="link_6"/><child link="flange"/></joint>',
        '  <link name="flange">',
        f'    <visual><origin xyz="0 0 {length / 2:.6g}" rpy="0 0 0"/><geometry><cylinder radius="0.03" '
        f'length="{length:.6g}"/></geometry><material name="grey"/></visual>',
        f'    <visual><origin xyz="{reflector[0] / 2:.6g} {reflector[1] / 2:.6g} {reflector[2]:.6g}" '
        f'rpy="0 1.5707963 0"/><geometry><cylinder radius="0.008" length="{np.hypot(*reflector[:2]):.6g}"/>'
        '</geometry><material name="grey"/></visual>',
        f'    <visual><origin xyz="{reflector[0]:.6g} {reflector[1]:.6g} {reflector[2]:.6g}" rpy="0 0 0"/>'
        '<geometry><sphere radius="0.019"/></geometry><material name="dark"/></visual>',
        "  </link>",
    ]


def main() -> None:
    robot_yaml = yaml.safe_load((HERE / "robot.yaml").read_text())
    joints = [
        JointSpec(lo * DEG, hi * DEG, v * DEG, e)
        for (lo, hi), v, e in zip(RANGE_DEG, SPEED_DEG_S, EFFORT_NM, strict=True)
    ]
    spec = MDHRobotSpec("rx130l", ROWS, LINKS, joints, flange_extras=tool_visuals(robot_yaml))
    (HERE / "rx130l.urdf").write_text(urdf_from_mdh(spec))


if __name__ == "__main__":
    main()
