"""Placeholders and repairs for URDFs as vendors ship them: no ``<inertial>``, ``effort="0"``.

ROS-Industrial support packages (KUKA, ABB, Fanuc ...) and older research files describe the
kinematics and the meshes but leave the dynamics empty: links without ``<inertial>`` (or mass 0)
and joints with ``effort="0"`` / ``velocity="0"``. Such a file is loaded with placeholders sized
like a catalogue arm of the same reach, and every placeholder is listed as an assumption:

* each placeholder link's mass from its meshes' volume (:mod:`pipeline.robot.mesh_volume`: convex
  hulls at a density measured on arms that state their masses) when every such link has meshes
  that are found; else (and stated beside it, for comparison) the reach-class rule:
* total arm mass ``m = MASS_COEFF_KG * reach**MASS_EXPONENT``, a power law fitted in log-log to
  manufacturers' data sheets (ABB IRB 120: 0.58 m / 25 kg; KUKA KR 6 R900 sixx: 0.90 m / 52 kg;
  ABB IRB 140: 0.81 m / 98 kg; KUKA KR 16-2: 1.61 m / 235 kg; ABB IRB 2400-16: 1.55 m / 380 kg;
  KUKA KR 210 R2700 prime: 2.70 m / 1068 kg; ABB IRB 6640-185: 2.80 m / 1310 kg); a fifth of it
  is the base, the rest is shared by the moving links in proportion to their length plus a
  tenth of the reach (a wrist is light but not massless);
* each placeholder link a solid cylinder from its joint to the next (radius a quarter of that
  length, within 2 cm and 0.12 reach, as the fallback capsules of :mod:`pipeline.robot.urdf_import`);
* joint speeds as on those data sheets: axes 1-3 at ``ARM_SPEED_RAD_S * sqrt(1.6 m / reach)``
  (KR 16-2: 156 deg/s at 1.61 m; KR 210: 105 deg/s at 2.70 m), the wrist twice as fast;
* joint torques sized to hold the arm and accelerate it, as industrial drives are (Siciliano et
  al., Robotics, 2009, sec. 5.2 on actuator sizing): the larger of ``EFFORT_GRAVITY_FACTOR``
  times the largest gravity torque and ``EFFORT_INERTIA_FACTOR`` times the largest diagonal mass
  matrix entry times the acceleration limit assumed later (``5/s x velocity limit``, a vertical
  first axis has no gravity torque), over random configurations of the (placeholder) model; at
  least ``MIN_EFFORT_SHARE`` of the largest. A stated effort limit below the largest gravity torque
  of its joint over those configurations, with the file's own masses, cannot be the arm's (the arm
  could not hold itself; a value such as ``effort="30"`` on every joint of a 30 kg arm is a file's
  default): it is replaced the same way, and so is every joint's when the file gives one value for all.

An inertia that is not physically consistent (principal moments not positive or violating the
triangle inequality ``I1 + I2 >= I3``, Traversaro et al., IROS 2016) is repaired by the smallest
change: zero (or rounding-negative) moments raised to ``MOMENT_FLOOR_KGM2``, then the smallest
moment raised to ``I3 - I2``. A clearly negative principal moment is no rounding but a typo in the
file (a product of inertia copied from a moment, a lost sign): no small change finds the link's
inertia, so it becomes a placeholder, the stated mass and centre of mass kept: the stated moments
about the link's axes with the products dropped when those alone are consistent, else the solid
cylinder of the stated mass. It is listed as ``PLACEHOLDER inertials``, like a missing inertial.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

from pipeline.robot.mesh_volume import LINK_DENSITY_KG_M3, link_volume_m3
from pipeline.robot.urdf_import import ACCELERATION_PER_VELOCITY_1_S

MASS_COEFF_KG, MASS_EXPONENT = 100.0, 2.4
BASE_MASS_SHARE = 0.2
ARM_SPEED_RAD_S = 2.72
EFFORT_GRAVITY_FACTOR, EFFORT_INERTIA_FACTOR, MIN_EFFORT_SHARE = 3.0, 2.0, 0.03
MOMENT_FLOOR_KGM2 = 1e-6
#: a mesh-estimated placeholder link weighs at least this share of the reach-class rule's mass for it
MIN_MESH_MASS_SHARE = 0.05
#: a repair below this share of the largest principal moment is the rounding of a URDF's numbers
#: (e.g. an identified inertia on its triangle boundary written with six digits): no warning
ROUNDING_SHARE = 0.01
#: a principal moment below -this share of the largest is a typo (an error), not a rounding to repair
SIGN_ERROR_SHARE = 1e-3


def datasheet_mass_kg(reach_m: float) -> float:
    """Total mass of a catalogue industrial arm of this reach (module docstring)."""
    return float(MASS_COEFF_KG * max(reach_m, 0.05) ** MASS_EXPONENT)


def _segments(model: pin.Model, flange_local: np.ndarray) -> list[np.ndarray]:
    """Per moving joint, the vector from its origin to the next joint's origin (the flange for the last)."""
    return [np.asarray(model.jointPlacements[j + 1].translation if j + 1 < model.njoints else flange_local, float)
            for j in range(1, model.njoints)]


def _cylinder_inertia(mass_kg: float, segment: np.ndarray, reach_m: float) -> pin.Inertia:
    """Solid cylinder along ``segment`` from the joint origin (radius a quarter of its length)."""
    length = max(float(np.linalg.norm(segment)), 0.05 * reach_m)
    radius = float(np.clip(0.25 * length, 0.02, 0.12 * reach_m))
    axis = segment / np.linalg.norm(segment) if np.linalg.norm(segment) > 1e-9 else np.array([0.0, 0.0, 1.0])
    axial, transverse = 0.5 * mass_kg * radius**2, mass_kg * (3 * radius**2 + length**2) / 12
    inertia = transverse * np.eye(3) + (axial - transverse) * np.outer(axis, axis)
    return pin.Inertia(mass_kg, 0.5 * np.asarray(segment, float), inertia)


def child_links(root: ET.Element) -> dict[str, str]:
    """Joint name -> child link name."""
    return {str(j.get("name")): str(j.find("child").get("link")) for j in root.findall("joint")}


def placeholder_inertias(model: pin.Model, root: ET.Element, flange_local: np.ndarray,
                         reach_m: float, urdf: Path | None = None) -> list[str]:
    """Give every moving body of mass <= 0 a placeholder inertia (in place); the sentences stating it.

    With meshes for every such link (``urdf`` given to find them), each mass is the link's mesh
    volume at :data:`pipeline.robot.mesh_volume.LINK_DENSITY_KG_M3`; else the reach-class rule
    (module docstring) shares the catalogue mass. The sentence states which, with the other's total."""
    links = child_links(root)
    bad = [j for j in range(1, model.njoints) if abs(model.inertias[j].mass) < 1e-12]   # negative: an error
    if not bad:
        return []
    segments = _segments(model, flange_local)
    weights = np.array([np.linalg.norm(s) + 0.1 * reach_m for s in segments])
    moving_kg = (1 - BASE_MASS_SHARE) * datasheet_mass_kg(reach_m)
    rule_kg = {j: float(moving_kg * weights[j - 1] / weights.sum()) for j in bad}
    volumes = {j: (link_volume_m3(root, urdf, links.get(str(model.names[j]), "")) if urdf is not None else None)
               for j in bad}
    from_meshes = all(v is not None and v > 0 for v in volumes.values())
    for j in bad:
        # a flange or a cover with a small mesh: not lighter than a share of the rule's link mass
        mass = (max(LINK_DENSITY_KG_M3 * float(volumes[j] or 0.0), MIN_MESH_MASS_SHARE * rule_kg[j])
                if from_meshes else rule_kg[j])
        model.inertias[j] = _cylinder_inertia(mass, segments[j - 1], reach_m)
    listed = ", ".join(f"{links.get(str(model.names[j]), model.names[j])} {model.inertias[j].mass:.1f} kg"
                       for j in bad)
    rule = (f"a catalogue arm of {reach_m:.2f} m reach ({datasheet_mass_kg(reach_m):.0f} kg in all, "
            f"{MASS_COEFF_KG:g} kg x reach^{MASS_EXPONENT:g})")
    if from_meshes:
        total = sum(model.inertias[j].mass for j in bad)
        litres = 1e3 * sum(float(v or 0.0) for v in volumes.values())
        how = (f"{total:.0f} kg in all against {sum(rule_kg.values()):.0f} kg by the reach-class rule, estimated "
               f"from the links' mesh volumes ({litres:.3g} L of convex hulls at {LINK_DENSITY_KG_M3:g} kg/m³; "
               f"the rule: {rule})")
    else:
        why = "no meshes found for every such link" if urdf is not None else "no meshes looked up"
        how = f"sized like {rule} ({why})"
    return [f"PLACEHOLDER inertials (no <inertial> or mass 0 in the URDF): {listed}; {how}, each link a solid "
            "cylinder from its joint to the next: replace them by the real inertials (URDF) or identify them"]


def _consistent(inertia_kgm2: np.ndarray) -> bool:
    """Positive principal moments that satisfy the triangle inequality ``I1 + I2 >= I3``."""
    a, b, c = np.sort(np.linalg.eigvalsh(0.5 * (inertia_kgm2 + inertia_kgm2.T)))
    return bool(a > 0 and a + b >= c)


def typo_inertia_placeholders(model: pin.Model, root: ET.Element, flange_local: np.ndarray,
                              reach_m: float) -> list[str]:
    """Replace every rotational inertia with a clearly negative principal moment (in place; module
    docstring): the stated diagonal when it alone is consistent, else the solid cylinder of the stated
    mass; the stated mass and centre of mass kept. The sentence stating it (none when no link has one)."""
    links = child_links(root)
    segments = _segments(model, flange_local)
    replaced = []
    for j in range(1, model.njoints):
        body = model.inertias[j]
        moments = np.linalg.eigvalsh(0.5 * (body.inertia + body.inertia.T))
        if not body.mass > 0 or moments.min() >= -SIGN_ERROR_SHARE * np.abs(moments).max():
            continue
        diagonal = np.diag(np.diag(body.inertia))
        if _consistent(diagonal):
            inertia, how = diagonal, "the stated moments about the link axes, products dropped"
        else:
            inertia = _cylinder_inertia(body.mass, segments[j - 1], reach_m).inertia
            how = "a solid cylinder of the stated mass from its joint to the next"
        model.inertias[j] = pin.Inertia(body.mass, body.lever, inertia)
        link = links.get(str(model.names[j]), str(model.names[j]))
        replaced.append(f"{link} (principal moments {np.round(moments, 6).tolist()} kg m²: {how})")
    if not replaced:
        return []
    return [f"PLACEHOLDER inertials (a physically impossible inertia in the URDF, a negative principal moment: "
            f"a typo no small change repairs): {'; '.join(replaced)}; the stated masses and centres of mass "
            "kept: replace them by the real inertias (URDF) or identify them"]


def consistent_inertia(body: pin.Inertia) -> tuple[np.ndarray, np.ndarray, pin.Inertia] | None:
    """The smallest change that makes ``body``'s rotational inertia physically consistent: principal
    moments raised to :data:`MOMENT_FLOOR_KGM2`, then the smallest raised to ``I3 - I2`` where
    ``I1 + I2 < I3``, axes kept. ``(moments, fixed moments, repaired body)``; None when nothing changes, the
    body has no mass, or a moment is clearly negative (a typo, :func:`typo_inertia_placeholders`)."""
    if not body.mass > 0:
        return None
    moments, axes = np.linalg.eigh(0.5 * (body.inertia + body.inertia.T))
    if moments.min() < -SIGN_ERROR_SHARE * np.abs(moments).max():
        return None
    fixed = np.maximum(moments, MOMENT_FLOOR_KGM2)
    order = np.argsort(fixed)
    a, b, c = fixed[order]
    if a + b < c:
        fixed[order[0]] = c - b
    if np.allclose(fixed, moments, rtol=0, atol=1e-12):
        return None
    repaired = axes @ np.diag(fixed) @ axes.T
    # exactly symmetric (halves first: no overflow near the float range)
    return moments, fixed, pin.Inertia(body.mass, body.lever, 0.5 * repaired + 0.5 * repaired.T)


def repair_inertias(model: pin.Model, root: ET.Element) -> list[str]:
    """Make every body's rotational inertia physically consistent by the smallest change (in place,
    :func:`consistent_inertia`); one note per body repaired, a warning unless it is a rounding."""
    links = child_links(root)
    notes = []
    for j in range(1, model.njoints):
        change = consistent_inertia(model.inertias[j])
        if change is None:
            continue
        moments, fixed, model.inertias[j] = change
        link = links.get(str(model.names[j]), str(model.names[j]))
        note = (f"inertia of link {link} repaired (principal moments {[float(f'{m:.4g}') for m in moments]} kg m² -> "
                f"{[float(f'{m:.4g}') for m in fixed]}: not positive or violating I1 + I2 >= I3; smallest change)")
        if np.max(np.abs(fixed - moments)) > ROUNDING_SHARE * np.abs(moments).max():
            warnings.warn(note, stacklevel=2)    # smaller changes are the URDF text's rounding: noted only
        notes.append(note)
    return notes


def _random_torque_terms(model: pin.Model, acceleration_rad_s2: np.ndarray,
                         samples: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """Per joint, over random configurations: the largest gravity torque ``|g(q)|`` and the largest
    ``diag(M(q)) x acceleration limit``."""
    data = model.createData()
    lo, hi = np.sort([model.lowerPositionLimit, model.upperPositionLimit], axis=0)   # swapped: refused later
    gravity, inertia = np.zeros(model.nq), np.zeros(model.nq)
    for q in np.random.default_rng(0).uniform(lo, hi, (samples, model.nq)):
        gravity = np.maximum(gravity, np.abs(pin.computeGeneralizedGravity(model, data, q)))
        inertia = np.maximum(inertia, np.diag(pin.crba(model, data, q)) * acceleration_rad_s2)
    return gravity, inertia


def _efforts_to_replace(effort_Nm: np.ndarray, gravity_Nm: np.ndarray, masses_stated: bool
                        ) -> tuple[list[int], list[int], bool]:
    """``(missing, short, all_stated)``: joints whose effort limit is 0 or missing; with the file's
    own masses (``masses_stated``) joints whose stated limit is below their largest gravity torque
    (the arm could not hold itself); and whether every stated limit goes with them, the file giving
    one value for all."""
    missing = [i for i, e in enumerate(effort_Nm) if not e > 0]
    short = [i for i, e in enumerate(effort_Nm) if masses_stated and 0 < e < gravity_Nm[i]]
    stated = effort_Nm[effort_Nm > 0]
    one_value = stated.size == effort_Nm.size >= 3 and np.ptp(stated) <= 1e-9 * stated.max()
    return missing, short, bool(short) and bool(one_value)


def placeholder_limits(model: pin.Model, root: ET.Element, reach_m: float,
                       keep: frozenset[str] | set[str] = frozenset(), masses_stated: bool = True) -> list[str]:
    """Replace velocity and effort limits <= 0 (``velocity="0"``, ``effort="0"``) by placeholders (in place).

    ``keep``: ``"velocity"`` / ``"effort"`` when robot.yaml sets that limit (nothing stated for it).
    A stated effort limit that cannot hold the arm is replaced only when the masses are the file's
    own (``masses_stated``): against placeholder masses the file's limit is the better fact."""
    notes = []
    nq = model.nq
    names = [str(n) for n in model.names[1:]]
    velocity = model.velocityLimit.copy()
    bad_v = [i for i in range(nq) if not velocity[i] > 0]
    if bad_v:
        arm = ARM_SPEED_RAD_S * np.sqrt(1.6 / max(reach_m, 0.05))
        for i in bad_v:
            velocity[i] = arm if i < 3 else 2 * arm
        model.velocityLimit = velocity
        if "velocity" not in keep:
            notes.append(f"PLACEHOLDER velocity limits (velocity 0 or missing in the URDF) on "
                         f"{', '.join(f'{names[i]} {velocity[i]:.2f} rad/s' for i in bad_v)}: axes 1-3 at "
                         f"{ARM_SPEED_RAD_S:g} rad/s x sqrt(1.6 m / reach), the wrist twice that (catalogue arms)")
    effort = model.effortLimit.copy()
    gravity, inertia = _random_torque_terms(model, ACCELERATION_PER_VELOCITY_1_S * model.velocityLimit)
    missing, short, all_stated = _efforts_to_replace(effort, gravity, masses_stated)
    replaced = sorted({*missing, *(range(nq) if all_stated else short)})
    if replaced:
        needed = np.maximum(EFFORT_GRAVITY_FACTOR * gravity, EFFORT_INERTIA_FACTOR * inertia)
        floor = MIN_EFFORT_SHARE * max(float(needed.max()), 1.0)
        why = ([f"effort 0 or missing in the URDF on {', '.join(names[i] for i in missing)}"] if missing else []) + (
            ["the URDF's limit below the largest gravity torque over random configurations, the arm could not hold "
             "itself, on " + ", ".join(f"{names[i]} ({effort[i]:.4g} < {gravity[i]:.4g} N·m)" for i in short)
             + ("; one value on every joint, so replaced on all" if all_stated else "")] if short else [])
        for i in replaced:
            effort[i] = max(float(needed[i]), floor)
        model.effortLimit = effort
        if "effort" not in keep:
            notes.append(f"PLACEHOLDER effort limits ({'; '.join(why)}) on "
                         f"{', '.join(f'{names[i]} {effort[i]:.0f} N·m' for i in replaced)}: "
                         f"{EFFORT_GRAVITY_FACTOR:g} x the largest gravity torque or {EFFORT_INERTIA_FACTOR:g} x "
                         f"inertia x acceleration limit, at least {MIN_EFFORT_SHARE:.0%} of the largest")
    return notes
