"""The calibration's designed poses for an arm: the tour through them, the pose table, the blank template.

Tour: from the start configuration, the nearest pose not yet visited (by the time of the move at
the velocity limits) whose quintic move (:func:`pipeline.run.export_motions.move`) keeps every
sample clear of the stages' capsules (self and floor); when none is clear the tour goes back through
the start configuration; at each pose the arm dwells ``DWELL_S`` (a tracker reading averaged over
the still window); it ends back at the start configuration.

``calibration_poses.csv`` (one row per pose in the tour's order): ``pose, arrival_s, dwell_s``,
``q_<joint>_rad``, the TCP and reflector positions the nominal model predicts in the base frame
(``tcp_x_m``..., ``reflector_x_m``...), the reflector in the nominal tracker frame
(``reflector_tracker_x_m``...), the tracker's line of sight to it (unit vector ``beam_x``...,
tracker frame), ``range_m`` and ``incidence_deg`` (beam against the reflector's opening axis).
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np

from pipeline.core.artefacts import write_text
from pipeline.core.errors import InfeasibleError
from pipeline.exchange.robot_program import SUFFIX, PoseProgram, write_program
from pipeline.robot.instruments import tracker_visibility
from pipeline.run import export_motions as em
from pipeline.run.export_motions import ExportContext
from pipeline.stage_api import StageOutput

#: time the arm stands still at each pose (s): settling, then the tracker's readings
DWELL_S = 2.0
#: samples of each move checked for collision per second of motion (at least its two ends)
COLLISION_CHECKS_PER_S = 50.0


def _clear(ctx: ExportContext, q: np.ndarray) -> bool:
    stride = max(int(ctx.rate_hz / COLLISION_CHECKS_PER_S), 1)
    rows = np.vstack([q[::stride], q[-1:]])
    return bool(np.all(em.collision_free(ctx.nominal, rows)))


def _rest(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return (q, np.zeros_like(q), np.zeros_like(q))


@dataclass(frozen=True)
class Tour:
    """The tour through the poses: their order, the pieces (t, q, q̇, q̈) of its motion, the arrival time at
    each pose in order, and its joint waypoints (start, poses, any return through the start, start) with
    the dwell at each (s)."""

    order: list[int]
    pieces: list[tuple[np.ndarray, ...]]
    arrivals: list[float]
    waypoints: np.ndarray
    dwell_s: np.ndarray


def tour(ctx: ExportContext, poses: np.ndarray) -> Tour:
    """The tour through ``poses`` (module docstring)."""
    limits = ctx.limits
    left = list(range(len(poses)))
    order: list[int] = []
    pieces: list[tuple[np.ndarray, ...]] = []
    arrivals: list[float] = []
    waypoints: list[tuple[np.ndarray, float]] = [(ctx.start_rad, 0.0)]
    clock = 0.0
    here = ctx.start_rad
    def add(piece: tuple[np.ndarray, ...]) -> None:
        nonlocal clock
        pieces.append(piece)
        clock += float(piece[0][-1])
    while left:
        cost = [float(np.max(np.abs(poses[i] - here) / limits.velocity_rad_s)) for i in left]
        chosen = None
        for i in (left[k] for k in np.argsort(cost)):
            piece = em.move(ctx.nominal, limits, _rest(here), _rest(poses[i]), ctx.rate_hz, "calibration_tour")
            if _clear(ctx, piece[1]):
                chosen = (i, piece)
                break
        if chosen is None:
            if np.array_equal(here, ctx.start_rad):
                raise InfeasibleError(None, "calibration_tour", f"no collision-free joint move from the start "
                                      f"configuration to any of the poses {left}; give another --start")
            add(em.move(ctx.nominal, limits, _rest(here), _rest(ctx.start_rad), ctx.rate_hz, "calibration_tour"))
            here = ctx.start_rad
            waypoints.append((here, 0.0))
            continue
        i, piece = chosen
        add(piece)
        arrivals.append(clock)
        n_dwell = max(int(round(DWELL_S * ctx.rate_hz)), 1)
        t = np.linspace(0.0, DWELL_S, n_dwell + 1)
        add((t, np.tile(poses[i], (len(t), 1)), np.zeros((len(t), len(here))), np.zeros((len(t), len(here)))))
        order.append(i)
        left.remove(i)
        here = poses[i]
        waypoints.append((here, DWELL_S))
    back = em.move(ctx.nominal, limits, _rest(here), _rest(ctx.start_rad), ctx.rate_hz, "calibration_tour")
    if not _clear(ctx, back[1]):
        raise InfeasibleError(None, "calibration_tour", "the move from the last pose back to the start "
                              "configuration collides; give another --start")
    add(back)
    waypoints.append((ctx.start_rad, 0.0))
    return Tour(order, pieces, arrivals, np.array([w for w, _ in waypoints]), np.array([d for _, d in waypoints]))


def _table(columns: list[str], rows: np.ndarray, formats: list[str]) -> str:
    buffer = io.StringIO()
    buffer.write(",".join(columns) + "\n")
    for row in rows:
        buffer.write(",".join(f.format(v) if v == v else "" for f, v in zip(formats, row, strict=True)) + "\n")
    return buffer.getvalue()


def pose_table(ctx: ExportContext, Q: np.ndarray, arrivals: list[float]) -> str:
    """``calibration_poses.csv`` text (module docstring) for the poses ``Q`` in tour order."""
    robot = ctx.nominal
    names = [str(n) for n in robot.model.names[1:]]
    tcp = robot.positions(Q, robot.frame_tcp)
    reflector = robot.positions(Q, robot.frame_reflector)
    T_tb = robot.tracker.transform_tracker_to_base
    in_tracker = (reflector - T_tb.translation) @ T_tb.rotation      # R^T (p - t), row-wise
    vis = tracker_visibility(robot, T_tb, Q)
    beam = in_tracker / np.linalg.norm(in_tracker, axis=1, keepdims=True)
    columns = (["pose", "arrival_s", "dwell_s"] + [f"q_{n}_rad" for n in names]
               + [f"tcp_{a}_m" for a in "xyz"] + [f"reflector_{a}_m" for a in "xyz"]
               + [f"reflector_tracker_{a}_m" for a in "xyz"] + [f"beam_{a}" for a in "xyz"]
               + ["range_m", "incidence_deg", "visible_nominal"])
    rows = np.column_stack([np.arange(1, len(Q) + 1), arrivals, np.full(len(Q), DWELL_S), Q, tcp, reflector,
                            in_tracker, beam, vis.range_m, np.degrees(vis.incidence_rad), vis.visible.astype(float)])
    formats = ["{:.0f}", "{:.6f}", "{:.6f}"] + ["{:.17g}"] * (len(columns) - 4) + ["{:.0f}"]
    return _table(columns, rows, formats)


def template_table(Q: np.ndarray) -> str:
    """``q1..qn,x,y,z`` (the layout ``calibration.measurements_csv`` reads): q filled, x, y, z blank."""
    nq = Q.shape[1]
    columns = [f"q{i + 1}" for i in range(nq)] + ["x", "y", "z"]
    rows = np.column_stack([Q, np.full((len(Q), 3), np.nan)])
    return _table(columns, rows, ["{:.17g}"] * nq + ["{}"] * 3)


def calibration_files(ctx: ExportContext, calibration: StageOutput) -> None:
    """The poses table, the template and the tour motion of the calibration's designed poses."""
    Q = np.atleast_2d(np.asarray(calibration.arrays["configurations_selected"], float))
    path = tour(ctx, Q)
    ordered = Q[path.order]
    write_text(ctx.staging / "calibration_poses.csv", pose_table(ctx, ordered, path.arrivals))
    write_text(ctx.staging / "calibration_measurements_template.csv", template_table(ordered))
    ctx.written += ["calibration_poses.csv", "calibration_measurements_template.csv"]
    ctx.write_motion("calibration_tour", em.joined(ctx.nominal, path.pieces, ctx.nominal))
    program = tour_program(ctx, path)
    for fmt in ctx.programs:
        name = f"calibration_tour{SUFFIX[fmt]}"
        write_program(ctx.staging / name, program, fmt, [
            f"robot {ctx.nominal.name}; the poses of calibration_poses.csv in its order, a dwell of {DWELL_S:g} s at "
            "each for the tracker; the same joint waypoints as calibration_tour.csv",
            f"speeds: {em.MOVE_LIMIT_FRACTION:g} of the model's joint velocity and acceleration limits"])
        ctx.written.append(name)


def tour_program(ctx: ExportContext, path: Tour) -> PoseProgram:
    """The tour's waypoints as a point-to-point program (:mod:`pipeline.exchange.robot_program`): the joints'
    speed and acceleration ``MOVE_LIMIT_FRACTION`` of the slowest joint's limit (URScript's and RAPID's leading
    axis), and that fraction in per cent of each axis's own (KRL)."""
    f = em.MOVE_LIMIT_FRACTION
    return PoseProgram("calibration_tour", tuple(str(n) for n in ctx.nominal.model.names[1:]), path.waypoints,
                       path.dwell_s, float(f * np.min(ctx.limits.velocity_rad_s)),
                       float(f * np.min(ctx.limits.acceleration_rad_s2)), 100.0 * f, 100.0 * f)

