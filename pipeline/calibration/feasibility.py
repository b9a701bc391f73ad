"""Why no candidate configuration is feasible: rejections by cause and the setting to change.

A quick random sample of configurations inside the joint limits goes through the candidate
filter of :mod:`pipeline.calibration.candidates` (collision, incidence angle, beam occlusion, in
that order), chunk by chunk, and stops at the first chunk that holds a feasible configuration.
When none of the sample is feasible, the search over the whole grid or the random draws (up to
20 million configurations, minutes) cannot find one either in practice: the search stops there
with one line naming the dominant cause and the setting that changes it. The laser tracker of the
model has no range limit (DESIGN.md "Sensors"), so no range cause exists.

Besides the filter's own counts, the sample records in how many poses the reflector lies inside
each capsule (point-to-segment distance below the radius): a reflector inside the wrist capsule
(a URDF whose last link frame sits at the wrist centre) is hidden in every pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.core.errors import InfeasibleError
from pipeline.robot.collision import segment_distances

#: configurations per chunk of the probe, and the probe's size: 1 % of the 20 million random draws
#: (``candidates.random_candidates``: 50 draws of at most 400 000) the full search may make
PROBE_CHUNK = 20_000
PROBE_SIZE = 200_000
#: share of the sampled poses above which "the reflector lies inside capsule c" is the cause
INSIDE_SHARE = 0.5


@dataclass
class Diagnosis:
    """Counts of a sample through the candidate filter (each configuration counted once, at its
    first failing test), poses with the reflector inside each capsule, beam blockers per capsule."""

    n_sampled: int = 0
    n_feasible: int = 0
    counts: dict[str, int] = field(default_factory=lambda: {"limits": 0, "collision": 0, "incidence": 0,
                                                            "occlusion": 0})
    inside: dict[str, int] = field(default_factory=dict)
    blockers: dict[str, int] = field(default_factory=dict)

    def add(self, other: Diagnosis) -> None:
        self.n_sampled += other.n_sampled
        self.n_feasible += other.n_feasible
        for mine, theirs in ((self.counts, other.counts), (self.inside, other.inside),
                             (self.blockers, other.blockers)):
            for key, value in theirs.items():
                mine[key] = mine.get(key, 0) + value

    def counts_text(self) -> str:
        text = ", ".join(f"{k} {v}" for k, v in self.counts.items())
        if self.blockers:
            name, n = max(self.blockers.items(), key=lambda kv: kv[1])
            text += f" (beam blocked by capsule {name} in {n})"
        return text


def diagnose(chain: cd.Chain, Q: np.ndarray, margins: cd.FilterMargins, capsule_names: list[str],
             visibility: bool = True) -> Diagnosis:
    """Run ``Q`` through the candidate filter and count the rejections by cause."""
    Q = np.atleast_2d(np.asarray(Q, float))
    out = Diagnosis(n_sampled=len(Q))
    free, counts = cd.filter_configurations(chain, Q, margins, visibility=False)
    out.counts["limits"], out.counts["collision"] = counts["limits"], counts["collision"]
    kin = cd.kinematics(chain, Q)
    seg = cd.capsule_segments(chain, kin)
    for c, name in enumerate(capsule_names):
        p = kin.p_reflector
        d = segment_distances(p, p, seg[:, c, 0], seg[:, c, 1])
        n_in = int((d < chain.capsule_r[c]).sum())
        if n_in:
            out.inside[name] = n_in
    if not visibility:
        out.n_feasible = int(free.sum())
        return out
    inc = cd.incidence_ok(chain, kin, margins)
    out.counts["incidence"] = int((free & ~inc).sum())
    idx = np.flatnonzero(free & inc)
    blocked = cd.beam_blockers(chain, kin, seg, margins, idx) if idx.size else np.zeros((0, len(capsule_names)), bool)
    out.counts["occlusion"] = int(blocked.any(axis=1).sum())
    for c, name in enumerate(capsule_names):
        if blocked[:, c].any():
            out.blockers[name] = int(blocked[:, c].sum())
    out.n_feasible = int(len(idx) - out.counts["occlusion"])
    return out


def probe(chain: cd.Chain, margins: cd.FilterMargins, capsule_names: list[str], size: int = PROBE_SIZE,
          visibility: bool = True, seed: int = 0) -> Diagnosis:
    """Uniform random configurations inside the limits (own seeded generator: the stage's random
    stream is not touched), ``PROBE_CHUNK`` at a time, until a chunk holds a feasible one or
    ``size`` are checked."""
    rng = np.random.default_rng(seed)
    total = Diagnosis()
    while total.n_sampled < size and total.n_feasible == 0:
        n = min(PROBE_CHUNK, size - total.n_sampled)
        total.add(diagnose(chain, rng.uniform(chain.lower, chain.upper, (n, chain.nq)), margins, capsule_names,
                           visibility))
        if total.n_feasible == 0 and max(total.inside.values(), default=0) == total.n_sampled:
            break      # the reflector inside a capsule in every pose so far: the outcome is clear
    return total


def infeasible_error(diag: Diagnosis, robot_file: str | Path | None, what: str = "candidate configuration",
                     margins_hint: str = "the calibration.margin_* values") -> InfeasibleError:
    """One line for a sample without a feasible configuration: the dominant cause (reflector inside
    a capsule, collisions, incidence, occlusion), the setting that changes it, the counts."""
    n = diag.n_sampled
    tail = f"no feasible {what} in {n} random configurations ({diag.counts_text()})"
    inside = max(diag.inside.items(), key=lambda kv: kv[1], default=None)
    if inside is not None and inside[1] >= INSIDE_SHARE * n:
        every = "every sampled pose" if inside[1] == n else f"{inside[1]} of {n} sampled poses"
        return InfeasibleError(robot_file, "tool.reflector_offset_m",
                               f"the reflector lies inside capsule {inside[0]} in {every}, so the "
                               "tracker cannot see it; move it outside the capsule (beyond the tool along the "
                               "flange axis), or make the flange a frame outside the wrist (robot init --tip "
                               f"tool0 or the flange link); {tail}")
    causes = {k: v for k, v in diag.counts.items() if v}
    cause = max(causes, key=causes.__getitem__) if causes else "collision"
    if cause == "collision":
        return InfeasibleError(robot_file, "capsules",
                               "nearly every sampled pose collides (capsule pairs or floor): check the capsules and "
                               "collision.floor_z_m / ignore_pairs, or lower calibration.margin_collision_m; "
                               f"{tail}")
    if cause == "incidence":
        return InfeasibleError(robot_file, "tool.reflector_axis",
                               "the reflector's axis never points to within tracker.max_incidence_deg of the "
                               "tracker: turn tool.reflector_axis towards the tracker or move "
                               f"tracker.transform_tracker_to_base (or lower calibration.margin_incidence_deg); {tail}")
    if cause == "occlusion":
        name = max(diag.blockers, key=diag.blockers.__getitem__) if diag.blockers else "?"
        return InfeasibleError(robot_file, "tool.reflector_offset_m",
                               f"the arm blocks the tracker's beam (most often capsule {name}): move the reflector "
                               "out of the arm's shadow (tool.reflector_offset_m) or the tracker "
                               f"(tracker.transform_tracker_to_base), or lower {margins_hint}; {tail}")
    return InfeasibleError(robot_file, "limits", f"the joint limits leave no configuration; {tail}")
