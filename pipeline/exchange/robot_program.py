"""A joint-space pose tour as the controllers of industrial arms run it: URScript, KUKA KRL, ABB RAPID.

The program moves point to point through joint targets in order, with exact stops (no blending), and
waits the stated dwell at each. A controller's point-to-point joint move interpolates every axis on a
straight line in joint space, synchronised, the path the export's quintic moves follow (only their timing
differs), so the collision checks of the tour hold for the program's path.

Per format (6 axes; angles as the controller writes them):

* ``urscript`` (``.script``, Universal Robots): ``movej([q1, ..., q6], a=A, v=V)`` in rad, rad/s², rad/s
  of the leading axis; ``sleep(T)``.
* ``krl`` (``.src``, KUKA KSS): ``PTP {A1 .., A6 ..}`` in degrees, ``$VEL_AXIS[i]`` and
  ``$ACC_AXIS[i]`` in per cent of each axis's maximum, ``WAIT SEC T``.
* ``rapid`` (``.mod``, ABB IRC5/OmniCore): module ``<name>_module``, procedure ``<name>``,
  ``MoveAbsJ [[j1, .., j6], [9E9, ..]], tour_speed, fine, tool0`` in degrees; ``tour_speed`` a ``speeddata``
  whose ``v_reax`` (deg/s) limits the joints, the TCP at most 100 mm/s; ``WaitTime T``.

**Stated assumption**, written into each program's header: the controller's axis ``i`` is the model's
joint ``i``, with the same zero and direction (true of the ROS-Industrial and the vendors' ROS
descriptions, whose joint states are the controller's axes). Run it first at reduced speed (T1).

:func:`read_program` reads the three formats back (the header's joint names, the targets, the dwells and
the speeds); angles round-trip to the written precision (:data:`DEGREE_DECIMALS` decimals of a degree,
URScript to 17 significant digits).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from pipeline.core.artefacts import write_text
from pipeline.core.errors import DataFileError

ProgramFormat = Literal["urscript", "krl", "rapid"]
PROGRAM_FORMATS: tuple[ProgramFormat, ...] = ("urscript", "krl", "rapid")
SUFFIX: dict[ProgramFormat, str] = {"urscript": ".script", "krl": ".src", "rapid": ".mod"}
#: the axes each format's joint target holds
AXES = 6
#: decimals of a degree in KRL and RAPID targets (1e-9 deg: 2e-11 rad)
DEGREE_DECIMALS = 9
#: RAPID's value for an external axis that is not there
RAPID_NO_AXIS = "9E9"


@dataclass(frozen=True)
class PoseProgram:
    """A tour of joint targets (rad, (K, 6)) with the dwell after each (s; 0: pass on), the joints' speed
    (rad/s) and acceleration (rad/s²) of the leading axis (URScript, RAPID's ``v_reax``), and the same as per
    cent of each axis's maximum (KRL)."""

    name: str
    joint_names: tuple[str, ...]
    q_rad: np.ndarray
    dwell_s: np.ndarray
    velocity_rad_s: float
    acceleration_rad_s2: float
    velocity_percent: float
    acceleration_percent: float


def _deg(q_rad: float) -> str:
    return f"{math.degrees(q_rad):.{DEGREE_DECIMALS}f}"


def _header(program: PoseProgram, comment: str, notes: list[str]) -> list[str]:
    lines = [f"{comment} {program.name}: {len(program.q_rad)} joint targets, exact stops",
             f"{comment} joints: {','.join(program.joint_names)}",
             f"{comment} ASSUMED: controller axis i is the model's joint i, same zero and direction;"
             " run it first at reduced speed (T1)"]
    return lines + [f"{comment} {note}" for note in notes]


def program_text(program: PoseProgram, fmt: ProgramFormat, notes: list[str] | None = None) -> str:
    """The program in ``fmt`` (module doc); ``notes``: comment lines for its header."""
    q, dwell = np.asarray(program.q_rad, float), np.asarray(program.dwell_s, float)
    if q.ndim != 2 or q.shape[1] != AXES:
        raise DataFileError(None, "--program", f"{fmt} drives {AXES} axes; the motion has "
                            f"{q.shape[1] if q.ndim == 2 else 0} joints")
    problems = [("name", not re.fullmatch(r"[A-Za-z_]\w*", program.name), f"{program.name!r} is no identifier"),
                ("joint_names", any("," in n or "\n" in n for n in program.joint_names) or
                 len(program.joint_names) != AXES, f"{AXES} names without commas needed, got {program.joint_names}"),
                ("q_rad", not np.all(np.isfinite(q)), "a joint target is not finite"),
                ("dwell_s", dwell.shape != (len(q),) or not np.all(np.isfinite(dwell) & (dwell >= 0)),
                 f"one finite dwell >= 0 per target needed ({len(q)} targets)"),
                ("speeds", not all(np.isfinite(x) and x > 0 for x in (
                    program.velocity_rad_s, program.acceleration_rad_s2, program.velocity_percent,
                    program.acceleration_percent)), "speeds and accelerations must be finite and > 0")]
    for field, bad, problem in problems:
        if bad:
            raise DataFileError(None, f"program.{field}", problem)
    extra = notes or []
    if fmt == "urscript":
        body = [*_header(program, "#", extra), f"def {program.name}():"]
        for k, (row, wait) in enumerate(zip(q, dwell, strict=True)):
            body.append(f"  movej([{', '.join(repr(float(v)) for v in row)}], "
                        f"a={program.acceleration_rad_s2!r}, v={program.velocity_rad_s!r})  # target {k + 1}")
            if wait > 0:
                body.append(f"  sleep({float(wait)!r})")
        return "\n".join([*body, "end", f"{program.name}()", ""])
    if fmt == "krl":
        body = ["&ACCESS RVP", f"DEF {program.name}()", *_header(program, ";", extra),
                "  INT i",
                f"  FOR i = 1 TO {AXES}",
                f"    $VEL_AXIS[i] = {program.velocity_percent:g}",
                f"    $ACC_AXIS[i] = {program.acceleration_percent:g}",
                "  ENDFOR"]
        for k, (row, wait) in enumerate(zip(q, dwell, strict=True)):
            axes = ", ".join(f"A{j + 1} {_deg(v)}" for j, v in enumerate(row))
            body.append(f"  PTP {{{axes}}} ; target {k + 1}")
            if wait > 0:
                body.append(f"  WAIT SEC {float(wait)!r}")
        return "\n".join([*body, "END", ""])
    reax = math.degrees(program.velocity_rad_s)
    body = [f"MODULE {program.name}_module", *_header(program, "!", extra),
            f"  CONST speeddata tour_speed := [100, 50, 100, {reax:.6f}];",
            f"  PROC {program.name}()"]
    for k, (row, wait) in enumerate(zip(q, dwell, strict=True)):
        joints = ", ".join(_deg(v) for v in row)
        body.append(f"    MoveAbsJ [[{joints}], [{', '.join([RAPID_NO_AXIS] * 6)}]], tour_speed, fine, tool0;"
                    f" ! target {k + 1}")
        if wait > 0:
            body.append(f"    WaitTime {float(wait)!r};")
    return "\n".join([*body, "  ENDPROC", "ENDMODULE", ""])


def write_program(path: str | Path, program: PoseProgram, fmt: ProgramFormat,
                  notes: list[str] | None = None) -> Path:
    """``program`` as ``fmt`` into ``path`` (atomic)."""
    path = Path(path)
    write_text(path, program_text(program, fmt, notes))
    return path


_NUMBER = r"[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?"


def read_program(path: str | Path) -> PoseProgram:
    """A program :func:`write_program` wrote, its format from the suffix (module doc)."""
    path = Path(path)
    fmt = next((f for f, s in SUFFIX.items() if path.suffix.lower() == s), None)
    if fmt is None:
        raise DataFileError(path, "suffix", f"not a program this tool writes ({', '.join(SUFFIX.values())})")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFileError(path, "file", f"cannot be read ({exc})") from None
    names = re.search(r"joints: ([^\r\n]+)", text)
    if names is None:
        raise DataFileError(path, "header", "no 'joints:' comment line")
    comment = {"urscript": "#", "krl": ";", "rapid": "!"}[fmt]
    code = "\n".join(line.split(comment, 1)[0] for line in text.splitlines())   # comments are not read
    try:
        return _parse(path, fmt, code, tuple(n.strip() for n in names.group(1).split(",")))
    except (ValueError, KeyError, IndexError) as exc:
        raise DataFileError(path, "program", f"not a {fmt} program this tool reads back ({exc!r})") from None


def _parse(path: Path, fmt: ProgramFormat, text: str, joint_names: tuple[str, ...]) -> PoseProgram:
    """The targets, waits and speeds of a program's code (comments removed)."""
    targets: list[list[float]] = []
    dwell: list[float] = []

    def wait(seconds: str) -> None:
        if not dwell:
            raise DataFileError(path, "program", "a wait before the first joint target")
        dwell[-1] += float(seconds)
    if fmt == "urscript":
        name = re.search(r"^def (\w+)\(\):", text, re.M)
        moves = re.finditer(rf"movej\(\[([^\]]*)\], a=({_NUMBER}), v=({_NUMBER})\)|sleep\(({_NUMBER})\)", text)
        speed = acc = math.nan
        for m in moves:
            if m.group(4) is not None:
                wait(m.group(4))
                continue
            targets.append([float(v) for v in m.group(1).split(",")])
            acc, speed = float(m.group(2)), float(m.group(3))
            dwell.append(0.0)
        percent = acc_percent = math.nan
    elif fmt == "krl":
        name = re.search(r"^DEF (\w+)\(\)", text, re.M)
        for m in re.finditer(rf"PTP \{{([^}}]*)\}}|WAIT SEC ({_NUMBER})", text):
            if m.group(2) is not None:
                wait(m.group(2))
                continue
            axes = dict(re.findall(rf"A(\d) ({_NUMBER})", m.group(1)))
            targets.append([math.radians(float(axes[str(j + 1)])) for j in range(AXES)])
            dwell.append(0.0)
        vel = re.search(rf"\$VEL_AXIS\[i\] = ({_NUMBER})", text)
        accel = re.search(rf"\$ACC_AXIS\[i\] = ({_NUMBER})", text)
        percent = float(vel.group(1)) if vel else math.nan
        acc_percent = float(accel.group(1)) if accel else math.nan
        speed = acc = math.nan
    else:
        name = re.search(r"^  PROC (\w+)\(\)", text, re.M)
        for m in re.finditer(rf"MoveAbsJ \[\[([^\]]*)\]|WaitTime ({_NUMBER});", text):
            if m.group(2) is not None:
                wait(m.group(2))
                continue
            targets.append([math.radians(float(v)) for v in m.group(1).split(",")])
            dwell.append(0.0)
        reax = re.search(rf"tour_speed := \[{_NUMBER}, {_NUMBER}, {_NUMBER}, ({_NUMBER})\]", text)
        speed = math.radians(float(reax.group(1))) if reax else math.nan
        acc = percent = acc_percent = math.nan
    if name is None or not targets or any(len(t) != AXES for t in targets):
        raise DataFileError(path, "program", f"no {fmt} program of {AXES}-axis joint targets")
    statement = {"urscript": "movej(", "krl": "PTP ", "rapid": "MoveAbsJ "}[fmt]
    if text.count(statement) != len(targets):
        raise DataFileError(path, "program", f"{text.count(statement)} {statement.strip()} statements, "
                            f"{len(targets)} read as joint targets (blended or computed targets are not read back)")
    if not np.all(np.isfinite(np.array(targets))):
        raise DataFileError(path, "program", "a joint target is not finite")
    return PoseProgram(name.group(1), joint_names, np.array(targets), np.array(dwell), speed, acc, percent,
                       acc_percent)
