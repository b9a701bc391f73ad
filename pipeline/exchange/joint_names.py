"""Joints of a recording matched to the joints of the model, by name in any order.

Rules, in this order:

1. a stated mapping ``{name in the recording: name in the model}`` renames the recording's joints;
2. every model joint found under its own name;
3. otherwise the names with each side's longest common prefix up to a separator removed
   (``fer_joint3`` and ``panda_joint3`` both become ``joint3``), when that matches every model joint exactly once.

Joints of the recording that the model does not hold (grippers, a second arm) are ignored.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

from pipeline.core.errors import DataFileError


def _without_common_prefix(names: Sequence[str]) -> list[str]:
    """The names without their longest common prefix that ends at a separator (``_``, ``/``, ``-``, ``.``)."""
    if len(names) < 2:
        return list(names)
    prefix = os.path.commonprefix(list(names))
    cut = max(prefix.rfind(sep) for sep in "_/-.") + 1
    return [name[cut:] for name in names]


def match_joint_names(recorded: Sequence[str], model: Sequence[str],
                      name_map: Mapping[str, str] | None = None, *,
                      source: str | None = None, field: str = "joint_names") -> dict[str, str]:
    """``{model joint: recorded joint}`` for every model joint, or :class:`DataFileError` naming ``field``."""
    renamed = {rec: (name_map or {}).get(rec, rec) for rec in recorded}
    by_model_name = {new: rec for rec, new in renamed.items()}
    if all(name in by_model_name for name in model):
        return {name: by_model_name[name] for name in model}
    if not name_map:
        # the recording's joints that share the model's prefix structure: compare the tails
        model_tails = _without_common_prefix(model)
        lookup: dict[str, list[str]] = {}
        for tail, rec in zip(_without_common_prefix(recorded), recorded, strict=True):
            lookup.setdefault(tail, []).append(rec)
        if len(set(model_tails)) == len(model) and all(len(lookup.get(tail, [])) == 1 for tail in model_tails):
            return {name: lookup[tail][0] for name, tail in zip(model, model_tails, strict=True)}
    missing = [name for name in model if name not in by_model_name]
    raise DataFileError(source, field,
                        f"joints {missing} of the model are not in the recording (it holds {list(recorded)}); "
                        f"state {field} as {{name in the recording: name in the model}}")
