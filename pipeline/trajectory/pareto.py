"""The PtP Pareto sweep (time against energy, paper ``004_abbe750b8bbcc3aa.txt`` §5) without
silently hidden local optima: a point another dominates is solved again from a cold start, and the
better of the two (objective ``k1 T + k2 E`` with the fine-grid energy) stays."""

from __future__ import annotations

from collections.abc import Callable

from pipeline.core.errors import InfeasibleError, SolverError
from pipeline.trajectory.ptp import PtpResult


def settle_pareto(sweep: list[PtpResult], fine_energy: Callable[[PtpResult], float],
                  cold_solve: Callable[[PtpResult], PtpResult],
                  cold_started: tuple[PtpResult, ...] = ()) -> list[PtpResult]:
    """The Pareto sweep with fine-grid energies (``info["fine_energy"] = fine_energy(r)``) and no
    silently hidden local optima.

    While a point is dominated by another (:func:`dominated_flags`
    on duration and fine-grid energy) and has not been tried yet, ``cold_solve(r)`` re-solves its
    ``k2`` once from a cold start and the one with the lower ``k1 T + k2 E`` (fine-grid energy)
    stays (``info["cold_restart"]``: ``"kept"`` on the cold solution, ``"discarded"`` or
    ``"failed: ..."`` on the continuation's). Results in ``cold_started`` are not re-solved
    (``"is a cold start"``). Every result gets ``info["dominated"]`` of the final set."""
    def objective(r: PtpResult) -> float:
        return r.k1 * r.duration_s + r.k2 * r.info["fine_energy"]

    pts = list(sweep)
    for r in pts:
        r.info.setdefault("fine_energy", float(fine_energy(r)))
    tried = {id(r) for r in cold_started}
    while True:
        flags = dominated_flags([(r.duration_s, r.info["fine_energy"]) for r in pts])
        for r, f in zip(pts, flags, strict=True):
            if f and id(r) in tried and "cold_restart" not in r.info:
                r.info["cold_restart"] = "is a cold start"
        todo = [i for i, f in enumerate(flags) if f and id(pts[i]) not in tried]
        if not todo:
            break
        i = todo[0]
        warm = pts[i]
        tried.add(id(warm))
        try:
            cold = cold_solve(warm)
        except (InfeasibleError, SolverError) as exc:
            warm.info["cold_restart"] = f"failed: {exc.problem}"
            continue
        cold.info["fine_energy"] = float(fine_energy(cold))
        tried.add(id(cold))
        both = {"continuation": objective(warm), "cold": objective(cold)}
        warm.info["cold_restart_objectives"] = cold.info["cold_restart_objectives"] = both
        if both["cold"] < both["continuation"]:
            cold.info["cold_restart"] = "kept"
            pts[i] = cold
        else:
            warm.info["cold_restart"] = "discarded"
    for r, f in zip(pts, flags, strict=True):
        r.info["dominated"] = bool(f)
    return pts


def dominated_flags(points: list[tuple[float, float]], rtol: float = 1e-9) -> list[bool]:
    """For each ``(duration, energy)`` point: is another point at least as good in both and
    strictly better in one (beyond the relative tolerance ``rtol``)? Dominated points of a
    Pareto sweep are poorer local optima of the NLP."""
    def better(a: float, b: float) -> bool:       # a clearly below b
        return a < b - rtol * max(abs(a), abs(b))

    return [any(j != i and not better(t, tj) and not better(e, ej) and (better(tj, t) or better(ej, e))
                for j, (tj, ej) in enumerate(points))
            for i, (t, e) in enumerate(points)]
