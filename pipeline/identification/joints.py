"""Joints without a torque signal, and the joints whose torques the fit uses.

A logged torque column carries no signal when it is

* constant (no logged value differs from the first),
* mostly exact zeros (at least :data:`MOSTLY_ZEROS_FRACTION` of the logged values are exactly 0:
  a drive that logs 0 whenever it does not report, e.g. the TIAGo wrist currents), or
* quantised: fewer than :data:`MIN_TORQUE_LEVELS` distinct values (about 6 bits), too coarse to
  resolve the inertial and friction torques a fit needs.

``identification.joints`` names the joints to use instead (robot joint names or 1-based
indices). Joints left out contribute no rows to the fit: they carry no weight, no gate reads
them and the headline does not show them; the report and ``summary.json`` name them with the
reason. Their link's inertial parameters and their drive-train parameters stay at the previous
model's values in the handed-on robot (:func:`pipeline.identification.handed_on.with_unmeasured_joints_kept`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.core.errors import ConfigError

#: a column whose logged values are at least this fraction exact zeros carries no signal
MOSTLY_ZEROS_FRACTION = 0.5
#: a column with fewer distinct logged values than this is quantised beyond use (6 bits)
MIN_TORQUE_LEVELS = 64


def unmeasured_torque_columns(tau_Nm: np.ndarray) -> dict[int, str]:
    """Joint index -> why its logged torque column carries no signal (module doc)."""
    tau = np.asarray(tau_Nm, float)
    n = tau.shape[0]
    min_levels = min(MIN_TORQUE_LEVELS, max(n // 10, 2))
    out: dict[int, str] = {}
    for j in range(tau.shape[1]):
        col = tau[:, j]
        zeros = float(np.mean(col == 0.0))
        levels = len(np.unique(col))
        if levels == 1:
            out[j] = f"constant torque column ({col[0]:g} N·m in every sample)"
        elif zeros >= MOSTLY_ZEROS_FRACTION:
            out[j] = f"{zeros:.0%} of its logged torques are exactly 0"
        elif levels < min_levels:
            out[j] = f"quantised torque column ({levels} distinct values in {n} samples)"
    return out


@dataclass
class JointSelection:
    """The joints whose torques the fit uses and the ones left out (with the reason)."""

    used: np.ndarray  # joint indices, increasing
    left_out: dict[int, str]
    names: list[str]  # every joint of the robot

    @property
    def all_used(self) -> bool:
        return not self.left_out

    def per_joint(self, values: np.ndarray | list[float]) -> list[float | None]:
        """A value per used joint -> a list over all joints, ``None`` for the joints left out."""
        out: list[float | None] = [None] * len(self.names)
        for j, v in zip(self.used, np.asarray(values, float), strict=True):
            out[int(j)] = float(v)
        return out

    def to_dict(self) -> dict:
        return {"joints_used": [self.names[j] for j in self.used],
                "joints_unmeasured": {self.names[j]: why for j, why in sorted(self.left_out.items())}}


def select_joints(requested: list[str | int], names: list[str], detected: dict[int, str],
                  field: str = "identification.joints") -> JointSelection:
    """``requested`` empty: every joint whose column carries a signal (``detected`` left out);
    else exactly the named joints (names or 1-based indices), the others left out as not named."""
    nq = len(names)
    if not requested:
        used = [j for j in range(nq) if j not in detected]
        left = dict(detected)
    else:
        idx: list[int] = []
        for item in requested:
            if isinstance(item, int) and not isinstance(item, bool):
                if not 1 <= item <= nq:
                    raise ConfigError(None, field, f"joint index {item} is not in 1..{nq}")
                idx.append(item - 1)
            elif isinstance(item, str) and item in names:
                idx.append(names.index(item))
            else:
                raise ConfigError(None, field, f"{item!r} is neither a joint of the robot ({', '.join(names)}) "
                                  f"nor an index 1..{nq}")
        used = sorted(set(idx))
        left = {j: "not named in identification.joints" for j in range(nq) if j not in used}
    if not used:
        raise ConfigError(None, field, "no joint left to identify: every torque column is unmeasured "
                          f"({'; '.join(f'{names[j]}: {w}' for j, w in left.items())})")
    return JointSelection(np.asarray(used, int), left, list(names))
