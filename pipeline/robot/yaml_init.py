"""``python -m pipeline robot init ARM.urdf``: a commented robot.yaml with the values assumed for a URDF.

:func:`write_robot_yaml` loads the URDF alone (:mod:`pipeline.robot.urdf_import` assumes what it
lacks), and writes those values as a ``robot.yaml`` beside it (or at ``out``) for the user to edit,
each section headed by the rule it came from. Loading the URDF again then reads this file instead
of assuming. The file is written atomically and never overwrites an existing one.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from pipeline.artefacts import write_text
from pipeline.errors import RobotFileError
from pipeline.robot.model import RobotModel
from pipeline.robot.spec import robot_spec_to_yaml

_HEADER = """\
# robot.yaml written by `python -m pipeline robot init` from {urdf}
# Every value below was ASSUMED because a URDF does not carry it. Edit what you know better;
# units are SI (m, rad, kg, N·m, s). Assumptions made:
{assumptions}
"""

_SECTION_NOTES = {
    "tool": "# TCP pose and laser-tracker reflector in the flange frame",
    "actuation": "# drive train, joint side: gear ratios, rotor inertia, viscous and Coulomb friction",
    "limits": "# position, velocity and effort limits come from the URDF; accelerations are stated here",
    "tracker": "# nominal laser-tracker pose in the base frame (p_base = T * p_tracker); delete the section "
               "if there is no tracker (then no calibration stage)",
    "collision": "# floor height and the first joint whose capsules must stay above it",
    "capsules": "# collision capsules: segment p0-p1 in the frame `frame`, swept by a sphere of radius_m",
}


def write_robot_yaml(urdf: str | Path, out: str | Path | None = None, *, base: str | None = None,
                     tip: str | None = None) -> Path:
    """Write the commented robot.yaml of ``urdf`` (beside it unless ``out``) and return its path."""
    urdf = Path(urdf)
    target = Path(out) if out is not None else urdf.parent / "robot.yaml"
    if target.exists():
        raise RobotFileError(target, "robot.yaml", "already exists; remove it or write elsewhere (--out)")
    robot = RobotModel.load(urdf, base=base, tip=tip)
    spec = robot.spec
    data = robot_spec_to_yaml(spec, str(Path(urdf).resolve()) if target.parent.resolve() != urdf.parent.resolve()
                              else urdf.name)
    data.pop("assumptions", None)
    lines = [_HEADER.format(urdf=urdf, assumptions="\n".join(f"#  - {a}" for a in robot.assumptions))]
    for key, value in data.items():
        if key in _SECTION_NOTES:
            lines.append(_SECTION_NOTES[key])
        lines.append(yaml.safe_dump({key: value}, sort_keys=False, allow_unicode=True, width=110).rstrip())
    write_text(target, "\n".join(lines) + "\n")
    return target
