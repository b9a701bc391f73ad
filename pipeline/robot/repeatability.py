"""The arm's ISO 9283 pose repeatability: its 1-sigma per axis, and the value assumed from the arm's reach.

ISO 9283 pose repeatability is ``RP = l_bar + 3 S_l``, ``l`` the distance of an attained position
from the barycentre of the attained positions. For an isotropic Gaussian scatter of ``sigma`` per
axis ``l`` is Maxwell distributed (mean ``2 sqrt(2/pi) sigma``, standard deviation
``sqrt(3 - 8/pi) sigma``), so ``RP = 3.616 sigma``: ``sigma = RP / 3.616``.

Which repeatability a calibration takes as known (:func:`repeatability_for_calibration`): the
robot.yaml value when the user stated it; the reach class's value that ``robot init`` assumed only
for simulated readings (the simulated arm scatters by it). With a recorded file and the value still
as ``robot init`` assumed it, the data decide: none is taken as known, and the remainder that the
calibration estimates from the record's residuals (REML, :mod:`pipeline.calibration.noise_model`)
takes up the arm's scatter. A data sheet's ±2 mm then is not read as the class's ±0.05 mm.
"""

from __future__ import annotations

import math

#: ``RP / sigma`` of an isotropic 3-D Gaussian scatter (module docstring)
RP_OVER_SIGMA = 2.0 * math.sqrt(2.0 / math.pi) + 3.0 * math.sqrt(3.0 - 8.0 / math.pi)

#: assumed ISO 9283 pose repeatability by reach class (vendor data sheets: UR3e/UR5e/UR10e +-0.03 mm,
#: UR10 (CB3) +-0.05 mm, KUKA KR 6-20 R1100-1800 +-0.02-0.04 mm, Stäubli TX2-60/90 +-0.02-0.03 mm,
#: ABB IRB 4600 +-0.05-0.06 mm, KUKA KR 210-500 R2700-2800 +-0.05-0.08 mm, Fanuc M-900 +-0.1 mm):
#: (reach up to, m; RP, m), the upper end of each class
REPEATABILITY_BY_REACH_M: tuple[tuple[float, float], ...] = ((1.5, 0.05e-3), (2.2, 0.06e-3), (math.inf, 0.1e-3))


def repeatability_sigma_m(rp_m: float) -> float:
    """1-sigma per axis of the arm's position scatter from ISO 9283 pose repeatability ``RP`` (m)."""
    return float(rp_m) / RP_OVER_SIGMA


#: the robot.yaml key of the repeatability (``assumed`` entries name it so)
REPEATABILITY_KEY = "repeatability_m"


def repeatability_for_calibration(rp_m: float | None, assumed: bool, recorded: bool) -> tuple[float, str]:
    """1-sigma per axis (m) of the arm's scatter a calibration takes as known, and where it comes from:
    ``"stated"`` (robot.yaml), ``"assumed"`` (``robot init``'s reach class, simulated readings),
    ``"data"`` (a recorded file with the value still assumed: the remainder estimated from the record
    takes it, module docstring) or ``"none"`` (not stated)."""
    if rp_m is None:
        return 0.0, "none"
    if assumed:
        return (0.0, "data") if recorded else (repeatability_sigma_m(rp_m), "assumed")
    return repeatability_sigma_m(rp_m), "stated"


def assumed_repeatability_m(reach_m: float) -> float:
    """ISO 9283 RP (m) assumed for an arm of ``reach_m`` (:data:`REPEATABILITY_BY_REACH_M`)."""
    return next(rp for limit, rp in REPEATABILITY_BY_REACH_M if reach_m <= limit)


def repeatability_rule() -> str:
    """The reach rule of :func:`assumed_repeatability_m`, for the ASSUMED comment."""
    parts = [f"{1e3 * rp:g} mm up to {limit:g} m reach" for limit, rp in REPEATABILITY_BY_REACH_M[:-1]]
    return ("ISO 9283 RP by reach class (vendor data sheets): " + ", ".join(parts)
            + f", {1e3 * REPEATABILITY_BY_REACH_M[-1][1]:g} mm beyond")
