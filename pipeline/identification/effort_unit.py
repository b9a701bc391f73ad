"""The unit of a record's efforts, read against the nominal model, and their conversion to joint torques.

A drive logs in ``effort`` what it measures: a joint torque in N·m (a torque sensor, or currents the
controller has already converted), a motor current in A (Universal Robots' ROS 2 driver publishes the
joint currents there), or a motor-side torque. The fits need joint-side torques; a record in another
unit fits as well as one in N·m (every column of the regressor scales with it), so the fit residual
cannot tell, and the handed-on masses would be off by the drive's constant, joint by joint.

**The ratio to the nominal model.** For every measured joint ``j`` the processed effort ``e_j`` is
regressed on the nominal model's rigid-body torque ``tau_j`` (the URDF's inertias and the stated rotor
inertia: the record's own regressor times the nominal standard parameters with no friction) and the
joint's friction columns of that regressor (viscous, Coulomb, offset: not known beforehand, so free)::

    e_j = c_j tau_j + f_v,j v_j + f_c,j tanh(v_j / w) + o_j + r_j.

``c_j`` is *determined* when ``tau_j`` explains at least :data:`MIN_PARTIAL_R2` of what the friction
columns leave of ``e_j`` (partial R², ``1 - RSS_full / RSS_friction``); a wrist joint whose torque is
mostly friction does not determine it. The record reads as joint torques when the median ratio of the
determined joints lies within ``[1 / MAX_NOMINAL_FACTOR, MAX_NOMINAL_FACTOR]``: a URDF's masses are off
by tens of per cent, a current's torque constant times the gear ratio (about 5 to 100 N·m/A on arms
that log currents) or a gear ratio by far more. One median for the record: one log has one unit.

**Conversion** (``identification.effort_scale``):

* ``auto`` (default): a record that reads as joint torques is used as logged. One that does not is
  converted with the nominal model's scale, ``s_j = 1 / c_j`` N·m per logged unit on the determined
  joints and the geometric mean of theirs on the others. The assumption is stated: the URDF's masses
  set the torque scale of every joint. The record-term ``effort_gain`` (:mod:`.friction_terms`) then
  corrects each joint's constant against the others, within its bound. When the URDF's inertials are
  ``robot init``'s placeholders the ratios are reported and the efforts used as logged, with a warning
  when they do not read as torques: masses estimated from the arm's size cannot set a unit.
* a list, joint-side N·m per logged unit per joint (``k_t x gear ratio`` for motor currents): stated;
  the ratios are still computed, and a median outside the band is warned of.
* ``none``: the efforts are taken as joint torques, unchecked; the report says so.

**Sign.** A determined joint whose ratio is negative logs its effort with the opposite sign of the
model's joint torque (a driver's direction convention): under ``auto`` it is negated, stated as an
assumption, whatever the unit; a stated scale carries its own sign, and a reversed joint under it is
warned of.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from pipeline.identification.measure import ProcessedData

#: the nominal model's torque must explain at least this share of what friction leaves of a joint's effort
MIN_PARTIAL_R2 = 0.3
#: a joint-torque record's median ratio to the nominal model lies within [1 / this, this]
MAX_NOMINAL_FACTOR = 3.0
#: ratio c_j x gear ratio within [1 / this, this] on every determined joint: motor-side torques
GEAR_HINT_FACTOR = 2.0

EffortStatus = Literal["joint torques", "converted", "stated", "unchecked"]


@dataclass(frozen=True)
class EffortUnit:
    """What the record's efforts were read as, and the scale applied (joint-side N·m per logged unit)."""

    status: EffortStatus
    scale_Nm_per_unit: np.ndarray       # (n_rows,) per measured joint; 1 when used as logged, -1 when negated
    nominal_ratio: np.ndarray           # (n_rows,) c_j of the logged efforts (NaN: not computed)
    partial_r2: np.ndarray              # (n_rows,) share of the residual the nominal torque explains
    determined: np.ndarray              # (n_rows,) bool: c_j determined (partial R² >= MIN_PARTIAL_R2)
    median_ratio: float | None          # median |c_j| over the determined joints (None: none determined)
    motor_side_hint: bool = False       # |c_j| ~ 1 / gear ratio on every determined joint
    #: the URDF's inertials are placeholders: the ratios are reported, the unit never acted on
    placeholder_masses: bool = False

    @property
    def within_band(self) -> bool:
        return within_band(self.median_ratio)

    @property
    def reversed(self) -> np.ndarray:
        """(n_rows,) bool: determined joints whose effort has the opposite sign of the model's torque."""
        return self.determined & (self.nominal_ratio < 0)

    def note(self, joints: np.ndarray) -> str | None:
        """One warning line for a record not used as logged or not checked, else None (``joints``: the
        1-based numbers of the measured joints)."""
        ratios = ", ".join(f"{c:.3g}" if d else f"({c:.3g})"
                           for c, d in zip(self.nominal_ratio, self.determined, strict=True))
        flipped = [str(int(j)) for j in np.asarray(joints)[self.reversed]]
        if self.status == "stated":
            if self.within_band and not flipped:
                return None
            sign = f"; joint(s) {', '.join(flipped)} opposite in sign" if flipped else ""
            return (f"with the stated identification.effort_scale the efforts are {self.median_ratio:.3g}x the "
                    f"nominal model's torques (median; per joint {ratios}{sign}): check the scale")
        negated = (f"ASSUMED: joint(s) {', '.join(flipped)} log their effort with the opposite sign of the model's "
                   f"joint torque (ratios {ratios}): negated" if flipped else "")
        unit = self._unit_note(joints, ratios)
        return "; ".join(x for x in (unit, negated) if x) or None

    def _unit_note(self, joints: np.ndarray, ratios: str) -> str:
        if self.status == "unchecked" and self.placeholder_masses:
            if self.within_band or self.median_ratio is None:
                return ""
            return (f"the record's efforts are {self.median_ratio:.3g}x the nominal model's torques (median; per "
                    f"joint {ratios}), but its link masses are placeholders, which cannot tell the efforts' unit: "
                    "they are taken as joint torques in N·m; if they are motor currents, state the drives' constants "
                    "as identification.effort_scale (k_t x gear ratio per joint)")
        if self.status == "unchecked":
            return ("the record's efforts are taken as joint torques in N·m unchecked (identification.effort_scale: "
                    "none)" if not np.any(np.isfinite(self.nominal_ratio)) else
                    "the record's efforts could not be checked against the nominal model: on no joint does its "
                    f"torque explain {MIN_PARTIAL_R2:.0%} of what friction leaves (ratios {ratios}); they are taken "
                    "as joint torques in N·m")
        if self.status == "joint torques":
            return ""
        scales = ", ".join(f"{s:.3g}" if d else f"{s:.3g}*"
                           for s, d in zip(self.scale_Nm_per_unit, self.determined, strict=True))
        what = ("they look like motor-side torques (ratios near 1 / gear ratio; identification.data_side: motor "
                "converts them through the gear matrix)" if self.motor_side_hint else
                "motor currents in A or another unit")
        return (f"the record's efforts are not joint torques in N·m: they are {self.median_ratio:.3g}x the nominal "
                f"model's torques (median of |ratio| over the determined joints; per joint {ratios}, brackets: not "
                f"determined), {what}. ASSUMED: converted with the nominal model's scale, joint-side N·m per "
                f"logged unit {scales} for joints {', '.join(str(int(j)) for j in joints)} (*: the geometric mean "
                "of the determined joints'), so the URDF's masses set the torque scale; state the drives' "
                "constants as identification.effort_scale (k_t x gear ratio per joint) to replace it")


def ratio_to_model(effort: np.ndarray, model: np.ndarray, nuisance: np.ndarray) -> tuple[float, float]:
    """``(c, partial R²)`` of ``effort = c model + nuisance b + r`` (least squares; ``nuisance`` (N, k) free
    columns such as friction and an offset; all-zero ones ignored): the partial R² is
    ``1 - RSS / RSS_nuisance``, the share of what the nuisance columns leave that ``model`` explains."""
    F = nuisance[:, np.any(nuisance != 0.0, axis=0)]
    A = np.column_stack([model, F])
    coef, *_ = np.linalg.lstsq(A, effort, rcond=None)
    rss = float(np.sum((effort - A @ coef) ** 2))
    left = effort - F @ np.linalg.lstsq(F, effort, rcond=None)[0] if F.shape[1] else effort
    rss_nuisance = float(np.sum(left ** 2))
    return float(coef[0]), (1.0 - rss / rss_nuisance if rss_nuisance > 0 else 0.0)


def median_ratio(c: np.ndarray, partial_r2: np.ndarray) -> tuple[np.ndarray, float | None]:
    """The joints whose ratio counts (partial R² >= :data:`MIN_PARTIAL_R2`, a non-zero ratio) and the median
    of their ratios' magnitudes (None: no joint counts; a negative ratio is an effort of reversed sign)."""
    determined = (partial_r2 >= MIN_PARTIAL_R2) & np.isfinite(c) & (c != 0)
    return determined, (float(np.median(np.abs(c[determined]))) if np.any(determined) else None)


def within_band(median: float | None) -> bool:
    """A median ratio that reads as joint torques in N·m (module doc)."""
    return median is not None and 1 / MAX_NOMINAL_FACTOR <= median <= MAX_NOMINAL_FACTOR


def nominal_ratios(data: ProcessedData, p_rigid: np.ndarray, n_link: int, nq: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``(c, partial R²)`` per torque column of ``data`` (module doc): ``p_rigid`` the nominal standard
    parameters without friction, ``n_link`` the number of link parameters (10 per body) of the regressor,
    ``nq`` its joints."""
    n, m = data.tau.shape
    Y = data.Y.reshape(n, m, -1)
    tau_nominal = Y @ p_rigid                                  # (n, m)
    friction_cols = np.arange(n_link + nq, n_link + 4 * nq)   # viscous, Coulomb, offset of every joint
    pairs = [ratio_to_model(data.tau[:, j], tau_nominal[:, j], Y[:, j, friction_cols]) for j in range(m)]
    return np.array([c for c, _ in pairs]), np.array([r for _, r in pairs])


def read_effort_unit(data: ProcessedData, p_rigid: np.ndarray, n_link: int, nq: int,
                     setting: Literal["auto", "none"] | list[float], gear_ratio: np.ndarray,
                     placeholder_masses: bool = False) -> EffortUnit:
    """What the record's efforts are and the scale to apply (module doc). ``setting`` is
    ``identification.effort_scale`` restricted to the measured joints; ``gear_ratio`` the measured joints'.
    With ``placeholder_masses`` (the URDF's inertials are robot init's placeholders) ``auto`` reports the
    ratios and takes the efforts as logged: masses estimated from a reach class cannot set a unit."""
    m = data.tau.shape[1]
    if setting == "none":
        nan = np.full(m, np.nan)
        return EffortUnit("unchecked", np.ones(m), nan, nan, np.zeros(m, bool), None)
    stated = None if setting == "auto" else np.asarray(setting, float)
    probe = data if stated is None else scaled(data, stated)
    c, r2 = nominal_ratios(probe, p_rigid, n_link, nq)
    determined, median = median_ratio(c, r2)
    hint = bool(np.any(determined) and np.all(np.abs(np.log(np.abs(c[determined] * gear_ratio[determined])))
                                              <= np.log(GEAR_HINT_FACTOR)))
    if stated is not None:
        return EffortUnit("stated", stated, c, r2, determined, median, hint)
    sign = np.where(determined & (c < 0), -1.0, 1.0)       # a reversed effort is negated in any case
    if median is None or placeholder_masses:
        return EffortUnit("unchecked", sign, c, r2, determined, median, hint, placeholder_masses)
    if within_band(median):
        return EffortUnit("joint torques", sign, c, r2, determined, median, hint)
    scale = np.full(m, float(np.exp(np.mean(np.log(1.0 / np.abs(c[determined]))))))
    scale[determined] = 1.0 / np.abs(c[determined])
    return EffortUnit("converted", sign * scale, c, r2, determined, median, hint)


def scaled(data: ProcessedData, scale_Nm_per_unit: np.ndarray) -> ProcessedData:
    """``data`` with its torques (and their noise sigma) times the per-column scale."""
    s = np.asarray(scale_Nm_per_unit, float)
    if np.all(s == 1.0):
        return data
    noise = None if data.noise_sigma_Nm is None else data.noise_sigma_Nm * s
    return replace(data, tau=data.tau * s[None, :], noise_sigma_Nm=noise)
