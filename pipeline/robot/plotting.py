"""Static matplotlib pictures of the robot (for reports; no browser needed).

The robot is drawn from Pinocchio frame placements: the kinematic chain as line segments
between joint origins (parent -> child, then flange and TCP), the collision capsules of
``robot.yaml`` as translucent cylinders, and joint origins as dots. Figures are created with
``matplotlib.figure.Figure`` (no pyplot state), so stage code can build them in any thread
and the runner saves them as PNG.

    fig = robot_figure(robot, q)                       # one or more views
    ax = new_3d_axes(); draw_robot(ax, robot, q); draw_points(ax, P)   # compose your own
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from mpl_toolkits.mplot3d.axes3d import Axes3D

from pipeline.robot.model import RobotModel

DEFAULT_VIEWS: tuple[tuple[float, float], ...] = ((25.0, -60.0), (0.0, -90.0))
#: dash patterns cycled with :func:`distinct_colors`: curves that coincide stay visible one over the other
LINE_STYLES: tuple[str, ...] = ("-", "--", "-.", ":")


def distinct_colors(n: int) -> list[tuple[float, float, float, float]]:
    """``n`` colours that differ pairwise (RGBA): the ten of matplotlib's ``tab10``, and for more than
    ten curves ``n`` evenly spaced ones of the ``turbo`` colour map (a figure never repeats a colour)."""
    if n <= 10:
        return [colormaps["tab10"](k) for k in range(n)]
    return [colormaps["turbo"](k / (n - 1)) for k in range(n)]


def chain_points(robot: RobotModel, q: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Segments (start, end) of the kinematic chain in the world frame at ``q``."""
    model = robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, np.asarray(q, float))
    pin.updateFramePlacements(model, data)
    segments: list[tuple[np.ndarray, np.ndarray]] = []
    for j in range(1, model.njoints):
        parent = model.parents[j]
        segments.append((data.oMi[parent].translation.copy(), data.oMi[j].translation.copy()))
    last = data.oMi[model.njoints - 1].translation.copy()
    prev = last
    for name in ("flange", "tcp"):
        if model.existFrame(name):
            p = data.oMf[model.getFrameId(name)].translation.copy()
            segments.append((prev, p))
            prev = p
    return segments


def new_3d_axes(fig: Figure | None = None, position: int | tuple[int, int, int] = 111) -> Axes3D:
    """A 3-D axes (creates a Figure when ``fig`` is None)."""
    if fig is None:
        fig = Figure(figsize=(6, 6))
    if isinstance(position, tuple):
        return fig.add_subplot(*position, projection="3d")
    return fig.add_subplot(position, projection="3d")


def _capsule_mesh(p0: np.ndarray, p1: np.ndarray, radius: float, n: int = 16) -> tuple[np.ndarray, ...]:
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    u = axis / length if length > 1e-12 else np.array([0.0, 0.0, 1.0])
    a = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(u, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    phi = np.linspace(0.0, 2 * np.pi, n)
    ring = radius * (np.outer(np.cos(phi), e1) + np.outer(np.sin(phi), e2))     # (n, 3)
    pts = np.stack([p0 + ring, p1 + ring])                                      # (2, n, 3)
    return pts[..., 0], pts[..., 1], pts[..., 2]


def draw_robot(ax: Axes3D, robot: RobotModel, q: np.ndarray | None = None, *, color: str = "tab:blue",
               capsules: bool = True, alpha: float = 0.18, label: str | None = None,
               linewidth: float = 3.0) -> None:
    """Draw the robot at ``q`` (default zeros) on a 3-D axes."""
    q = np.zeros(robot.model.nq) if q is None else np.asarray(q, float)
    segments = chain_points(robot, q)
    for k, (a, b) in enumerate(segments):
        ax.plot(*np.stack([a, b]).T, color=color, linewidth=linewidth, solid_capstyle="round",
                label=label if k == 0 else None)
    joints = np.array([s[1] for s in segments[: robot.model.njoints - 1]])
    ax.scatter(*joints.T, color="k", s=12, depthshade=False)
    tcp = segments[-1][1]
    ax.scatter(*tcp, color="tab:red", s=25, marker="^", depthshade=False)
    if capsules and getattr(robot, "capsules", None):
        segs = robot.capsule_segments(q[None, :])[0]
        for cap, (p0, p1) in zip(robot.capsules, segs, strict=True):
            ax.plot_surface(*_capsule_mesh(p0, p1, cap.radius_m), color=color, alpha=alpha,
                            linewidth=0, shade=True)


def draw_points(ax: Axes3D, points: np.ndarray, *, color: str = "tab:orange", size: float = 8.0,
                label: str | None = None) -> None:
    """Scatter ``(N, 3)`` points (e.g. TCP positions of a configuration set)."""
    P = np.atleast_2d(np.asarray(points, float))
    ax.scatter(P[:, 0], P[:, 1], P[:, 2], color=color, s=size, label=label, depthshade=False)


def draw_floor(ax: Axes3D, half_width_m: float, z_m: float = 0.0) -> None:
    xx, yy = np.meshgrid([-half_width_m, half_width_m], [-half_width_m, half_width_m])
    ax.plot_surface(xx, yy, np.full_like(xx, z_m), color="0.6", alpha=0.15, linewidth=0)


def set_equal_3d(ax: Axes3D, points: np.ndarray | None = None, margin_m: float = 0.1) -> None:
    """Equal scale on the three axes around ``points`` (default: what is drawn)."""
    if points is None:
        lims = np.array([ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d()])
    else:
        P = np.atleast_2d(points)
        lims = np.stack([P.min(axis=0), P.max(axis=0)], axis=1)
    centre = lims.mean(axis=1)
    half = (lims[:, 1] - lims[:, 0]).max() / 2 + margin_m
    ax.set_xlim3d(centre[0] - half, centre[0] + half)
    ax.set_ylim3d(centre[1] - half, centre[1] + half)
    ax.set_zlim3d(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(5))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")


def robot_extent(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """Points spanning what :func:`draw_robot` draws (chain + capsule ends +/- radius)."""
    pts = [p for seg in chain_points(robot, q) for p in seg]
    if getattr(robot, "capsules", None):
        segs = robot.capsule_segments(np.asarray(q, float)[None, :])[0]
        for cap, (p0, p1) in zip(robot.capsules, segs, strict=True):
            for p in (p0, p1):
                pts += [p - cap.radius_m, p + cap.radius_m]
    return np.array(pts)


def _hide_edge_on_axis(ax: Axes3D, elev_deg: float, azim_deg: float) -> None:
    """Orthographic projection and no tick labels on an axis seen edge-on (side/top views)."""
    e, a = np.deg2rad(elev_deg), np.deg2rad(azim_deg)
    edge_on = []
    if abs(np.cos(e)) > 0.999 and abs(np.sin(a)) > 0.999:
        edge_on.append(ax.yaxis)
    if abs(np.cos(e)) > 0.999 and abs(np.cos(a)) > 0.999:
        edge_on.append(ax.xaxis)
    if abs(np.sin(e)) > 0.999:
        edge_on.append(ax.zaxis)
    if edge_on:
        ax.set_proj_type("ortho")
    for axis in edge_on:
        axis.set_ticklabels([])
        axis.label.set_visible(False)


def robot_figure(robot: RobotModel, q: np.ndarray | None = None, *,
                 views: Sequence[tuple[float, float]] = DEFAULT_VIEWS, title: str | None = None,
                 points: np.ndarray | None = None, size_in: float = 5.0) -> Figure:
    """Figure with the robot at ``q`` seen from each ``(elevation_deg, azimuth_deg)`` view.

    ``points``: optional ``(N, 3)`` extra points drawn in every view.
    """
    q = np.zeros(robot.model.nq) if q is None else np.asarray(q, float)
    fig = Figure(figsize=(size_in * len(views), size_in))
    extent = robot_extent(robot, q)
    if points is not None:
        extent = np.vstack([extent, np.atleast_2d(points)])
    extent = np.vstack([extent, [[0.0, 0.0, 0.0]]])
    for k, (elev, azim) in enumerate(views):
        ax = new_3d_axes(fig, (1, len(views), k + 1))
        draw_robot(ax, robot, q)
        if points is not None:
            draw_points(ax, points)
        set_equal_3d(ax, extent)
        ax.view_init(elev=elev, azim=azim)
        _hide_edge_on_axis(ax, elev, azim)
        ax.set_title(f"elevation {elev:g}°, azimuth {azim:g}°", fontsize=9)
    if title:
        fig.suptitle(title)
    return fig
