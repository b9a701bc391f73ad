"""Interactive 3-D viewer: the robot in meshcat (Pinocchio's ``MeshcatVisualizer``).

Python API (notebooks)::

    from pipeline.view.viewer import Viewer
    v = Viewer(robot)                     # starts a meshcat server on localhost, prints its URL
    v.show(q)                             # one configuration
    v.show_configurations(Q, "calibration")   # TCP points of a set + an animation through it
    v.play(t, q)                          # replay a joint trajectory (meshcat animation, scrubbable)
    v.jupyter_cell()                      # embed in a notebook
    v.close()

Command line: ``python -m pipeline view [RUN_DIR]`` (:mod:`pipeline.view.run_view`).

The visual model comes from the URDF's ``<visual>`` primitives, attached to the joints of
``robot.model``, so a calibrated model (moved joint placements) is drawn correctly.
"""

from __future__ import annotations

import html
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import coal
import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from meshcat.animation import Animation
from pinocchio.visualize import MeshcatVisualizer

from pipeline.core.errors import PipelineError
from pipeline.robot.model import RobotModel
from pipeline.robot.urdf_import import package_dirs
from pipeline.view.scene import (
    HALF_VIEW_TAN,
    LAYERS,
    LEGEND_DISTANCE_M,
    LEGEND_LINE_SHARE,
    camera_view,
    colour_name,
    legend_png,
    translation,
    workspace_box,
)


def capsule_geometry(robot: RobotModel) -> pin.GeometryModel:
    """The robot's collision capsules as a Pinocchio geometry model (drawn when meshes are missing)."""
    geometry = pin.GeometryModel()
    for capsule in getattr(robot, "capsules", []):
        fid = robot.model.getFrameId(capsule.frame)
        frame = robot.model.frames[fid]
        axis = np.asarray(capsule.p1, float) - np.asarray(capsule.p0, float)
        length = float(np.linalg.norm(axis))
        z = axis / length if length > 1e-9 else np.array([0.0, 0.0, 1.0])
        rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), z).matrix()
        local = pin.SE3(rotation, 0.5 * (np.asarray(capsule.p0, float) + np.asarray(capsule.p1, float)))
        obj = pin.GeometryObject(f"capsule_{capsule.name}", frame.parentJoint, fid, frame.placement * local,
                                 coal.Capsule(capsule.radius_m, length))
        obj.meshColor = np.array([0.6, 0.65, 0.75, 1.0])
        geometry.addGeometryObject(obj)
    return geometry


def visual_model(robot: RobotModel) -> tuple[pin.GeometryModel, str]:
    """(visual geometry, "meshes" | "capsules") of ``robot``.

    The URDF is read from its file so relative and ``package://`` meshes resolve (ROS_PACKAGE_PATH,
    the URDF's folder and its parents: :func:`pipeline.robot.urdf_import.package_dirs`); when a mesh
    cannot be found or read, the robot's collision capsules are drawn instead.
    """
    urdf = getattr(robot, "urdf_path", None)
    try:
        if urdf is not None and Path(urdf).is_file():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                geometry = pin.buildGeomFromUrdf(robot.model, str(urdf), pin.GeometryType.VISUAL, package_dirs(urdf))
        else:
            geometry = pin.buildGeomFromUrdfString(robot.model, robot.urdf_text, pin.GeometryType.VISUAL)
        missing = [g.meshPath for g in geometry.geometryObjects
                   if g.meshPath and not Path(g.meshPath).is_file() and "BOX" not in g.meshPath
                   and "CYLINDER" not in g.meshPath and "SPHERE" not in g.meshPath]
        if geometry.ngeoms and not missing:
            for g in geometry.geometryObjects:
                # Collada files go to the browser as text and are parsed there by three.js, which
                # headless browsers and some meshcat builds skip silently; the triangles coal already
                # loaded from the file are sent instead (same shape, the URDF's colour).
                if g.meshPath.lower().endswith(".dae") and isinstance(g.geometry, coal.BVHModelBase):
                    g.meshPath = ""
            return geometry, "meshes"
    except (RuntimeError, ValueError, OSError):
        pass
    return capsule_geometry(robot), "capsules"


class Viewer:
    """The robot in a meshcat scene.

    ``zmq_url``: connect to a running ``meshcat-server`` instead of starting one;
    ``viewer``: an existing ``meshcat.Visualizer``; ``open_browser``: open the page.
    """

    def __init__(self, robot: RobotModel, *, zmq_url: str | None = None, viewer: meshcat.Visualizer | None = None,
                 open_browser: bool = False, root: str | None = None) -> None:

        self.robot = robot
        self.model = robot.model
        self._own_server = viewer is None and zmq_url is None
        if viewer is None:
            viewer = meshcat.Visualizer(zmq_url=zmq_url)
        self.vis = viewer
        geometry, self.drawn_as = visual_model(robot)
        if self.drawn_as == "capsules":
            print(f"viewer: meshes of {getattr(robot, 'name', 'the robot')} not found; drawing its collision "
                  "capsules", file=sys.stderr)
        self.viz = MeshcatVisualizer(self.model, geometry, geometry)
        self.viz.initViewer(viewer=viewer, open=open_browser)
        spec = getattr(robot, "spec", None)
        self.floor_z_m = float(spec.collision.floor_z_m) if spec is not None else 0.0
        self.legend: dict[str, tuple[int, str]] = {}                     # layer -> (colour, meaning)
        self.workspace_box_m = workspace_box(self.model, self.floor_z_m)
        # camera and floor first: a large mesh scene sent before them can delay them in the browser
        self.set_camera()
        self.draw_floor()
        self.root = root or str(getattr(robot, "name", "robot"))
        self.viz.loadViewerModel(rootNodeName=self.root)
        self._data = self.model.createData()
        self._clips: list[tuple[str, np.ndarray, np.ndarray]] = []     # (name, t, q) queued for animate()
        self.show(np.zeros(self.model.nq))

    # ------------------------------------------------------------------------ basics
    @property
    def url(self) -> str:
        return self.vis.url()

    def jupyter_cell(self, height: int = 400) -> Any:
        """The viewer in a notebook cell, with the legend of its layers above it."""
        cell = self.vis.jupyter_cell(height=height)
        items = "".join(f'<span style="margin-right:1em"><span style="color:#{color:06x}">&#9632;</span> '
                        f"<b>{html.escape(layer)}</b>: {html.escape(text)}</span>"
                        for layer, (color, text) in self.legend.items())
        return type(cell)(f'<div style="font-size:small">{items}</div>' + cell.data)

    def legend_text(self) -> str:
        """The layers drawn (meshcat scene tree paths, toggled in the page's Controls panel) and what
        each shows, one per line."""
        return "\n".join(f"  {layer}: {colour_name(color)}, {text}" for layer, (color, text) in self.legend.items())

    def set_camera(self, position_m: np.ndarray | None = None, target_m: np.ndarray | None = None) -> None:
        """Put the camera at ``position_m`` looking at ``target_m`` (world frame, z up; the page's
        orbit controls turn about the target). Default: :func:`camera_view`, the arm's reachable
        region framed."""
        if position_m is None or target_m is None:
            target, position = camera_view(self.model, self.floor_z_m)
            position_m = position if position_m is None else position_m
            target_m = target if target_m is None else target_m
        p, t = np.asarray(position_m, float), np.asarray(target_m, float)
        # meshcat's orbit controls always look at the page's origin: the scene (this viewer's
        # path, meshcat's grid and axes) is shifted by -target instead. The server replays its tree
        # to a new page in the order the paths were created: camera and grid before the meshes.
        self.target_m = t
        d = p - t       # the camera lives in a y-up frame: (x, y, z)_world -> (x, z, -y)
        self.vis["/Cameras/default/rotated/<object>"].set_property("position", [float(d[0]), float(d[2]), float(-d[1])])
        self.vis["/Grid"].set_property("visible", False)        # fixed at z = 0: draw_floor draws its own
        self.vis["/Axes"].set_transform(translation(-t))
        self.vis.set_transform(translation(-t))

    def draw_floor(self) -> None:
        """The floor at ``collision.floor_z_m`` under the arm's reach: a pale plate with a grid of
        round spacing (layer ``floor``)."""
        half = 1.2 * float(np.max(np.abs(self.workspace_box_m[:, :2])))
        step = next(s for s in (0.1, 0.25, 0.5, 1.0, 2.0, 5.0) if half / s <= 12)
        z = self.floor_z_m
        self.vis["floor"]["plate"].set_object(mg.Box([2 * half, 2 * half, 0.002]),
                                              mg.MeshLambertMaterial(color=0xD9D9D9, opacity=0.5, transparent=True))
        self.vis["floor"]["plate"].set_transform(translation([0.0, 0.0, z - 0.002]))
        ticks = np.arange(-np.floor(half / step), np.floor(half / step) + 1) * step
        ends = [[(x, -half, z), (x, half, z), (-half, x, z), (half, x, z)] for x in ticks]
        lines = np.array(ends, float).reshape(-1, 3)
        self.vis["floor"]["grid"].set_object(mg.LineSegments(mg.PointsGeometry(lines.T),
                                                             mg.LineBasicMaterial(color=0x808080)))
        self.legend["floor"] = (0xD9D9D9, f"floor at z = {z:g} m (collision.floor_z_m), grid {step:g} m")
        self.show_legend()

    def show(self, q: np.ndarray) -> None:
        """Place the robot at configuration ``q``."""
        self.viz.display(np.asarray(q, float))

    def close(self) -> None:
        """Stop the meshcat server this viewer started (if any)."""
        proc = getattr(self.vis.window, "server_proc", None)
        if self._own_server and proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------------ drawings
    def _tcp_points(self, Q: np.ndarray, frame: str) -> np.ndarray:
        if hasattr(self.robot, "positions"):
            return np.asarray(self.robot.positions(Q, frame))
        fid = self.model.getFrameId(frame)
        out = []
        for q in Q:
            pin.framesForwardKinematics(self.model, self._data, q)
            out.append(self._data.oMf[fid].translation.copy())
        return np.array(out)

    def show_points(self, points: np.ndarray, name: str, color: int = 0xE6550D, size_m: float | None = None,
                    layer: str = "points") -> None:
        """Draw ``(N, 3)`` points as a point cloud under ``<layer>/<name>`` (``size_m`` None: 1 % of
        the diagonal of the arm's reachable box for up to 100 points, smaller as 1 / sqrt(N) for more,
        at least 0.3 %)."""

        P = np.atleast_2d(np.asarray(points, float))
        if size_m is None:
            diagonal = float(np.linalg.norm(np.ptp(self.workspace_box_m, axis=0)))
            size_m = diagonal * max(0.003, 0.01 * min(1.0, float(np.sqrt(100.0 / len(P)))))
        rgb = np.array([(color >> 16) & 255, (color >> 8) & 255, color & 255], float) / 255.0
        colors = np.tile(rgb[:, None], (1, len(P)))
        self.vis[layer][name].set_object(mg.PointCloud(P.T, colors, size=size_m))
        self.add_legend(layer, color, f"{len(P)} points" + ("" if layer in LAYERS else f" ({name})"))

    def show_path(self, points: np.ndarray, name: str, color: int = 0x3182BD, layer: str = "paths") -> None:
        """Draw ``(N, 3)`` points as a polyline under ``<layer>/<name>``."""

        P = np.atleast_2d(np.asarray(points, float))
        self.vis[layer][name].set_object(
            mg.Line(mg.PointsGeometry(P.T), mg.LineBasicMaterial(color=color, linewidth=2)))
        self.add_legend(layer, color, "" if layer in LAYERS else f"TCP path ({name})")

    def add_legend(self, layer: str, color: int, text: str) -> None:
        """Name what layer ``layer`` shows in the legend (a named layer keeps its own meaning first)."""
        meaning = LAYERS[layer][1] if layer in LAYERS else None
        if layer in self.legend and meaning is None:
            text = f"{self.legend[layer][1]}; {text}"
        self.legend[layer] = (color, text if meaning is None else f"{meaning} ({text})" if text else meaning)
        self.show_legend()

    def show_legend(self) -> None:
        """The legend as a picture fixed in the top left corner of the view (a child of the camera,
        ``LEGEND_DISTANCE_M`` in front of it, so it stays in place while the view turns)."""
        png, aspect = legend_png(self.legend)
        height = LEGEND_LINE_SHARE * (len(self.legend) + 0.6) * 2 * HALF_VIEW_TAN * LEGEND_DISTANCE_M
        width = aspect * height
        edge = HALF_VIEW_TAN * LEGEND_DISTANCE_M        # top and (aspect >= 1) left edge of the view
        node = self.vis["/Cameras/default/rotated/<object>/legend"]
        node.set_object(mg.Box([width, height, 1e-4]),
                        mg.MeshBasicMaterial(map=mg.ImageTexture(mg.PngImage(png)), transparent=True,
                                             depthTest=False, side=0))     # front face only
        node.set_transform(translation([-0.97 * edge + width / 2, 0.97 * edge - height / 2, -LEGEND_DISTANCE_M]))

    def show_configurations(self, Q: np.ndarray, name: str = "configurations", *, frame: str = "tcp",
                            seconds_each: float = 1.0, color: int = 0xE6550D, animate: bool = True,
                            layer: str = "points") -> Any:
        """Show a configuration set: its TCP points, the robot at ``Q[0]``, and (``animate``)
        an animation that moves through the set, ``seconds_each`` per configuration (queued
        after earlier clips; :meth:`clear_animation` starts afresh). Returns the Animation."""
        Q = self._check_q(Q, name)
        self.show_points(self._tcp_points(Q, frame if self.model.existFrame(frame) else "flange"), name, color,
                         layer=layer)
        self.show(Q[0])
        t = np.arange(len(Q), dtype=float) * seconds_each
        if animate:
            self._clips.append((name, t, Q))
            return self.animate()
        return None

    def play(self, t: np.ndarray, q: np.ndarray, name: str = "trajectory", *, fps: float = 30.0,
             realtime: bool = False, speed: float = 1.0, frame: str = "tcp", color: int = 0x3182BD) -> Any:
        """Replay a joint trajectory ``q(t)``: draws the TCP path and either sets a meshcat
        animation (default; play/scrub it in the page's controls) or, ``realtime=True``,
        moves the robot from Python in (scaled) real time, blocking until done.
        Returns the meshcat Animation (None when ``realtime``)."""
        t = np.asarray(t, float).ravel()
        q = self._check_q(q, name)
        if len(t) != len(q):
            raise PipelineError(None, name, f"{len(t)} time stamps but {len(q)} configurations")
        if np.any(np.diff(t) < 0):
            raise PipelineError(None, name, "time stamps must not decrease")
        self.show_path(self._tcp_points(q[:: max(1, len(q) // 500)], frame if self.model.existFrame(frame)
                                        else "flange"), name, color)
        if realtime:
            frames = np.arange(t[0], t[-1] + 1e-12, 1.0 / fps)
            start = time.perf_counter()
            for tk in frames:
                self.show(_interp(t, q, tk))
                delay = (tk - t[0]) / speed - (time.perf_counter() - start)
                if delay > 0:
                    time.sleep(delay)
            return None
        self._clips.append((name, t, q))
        return self.animate(fps=fps)

    def clear_animation(self) -> None:
        self._clips.clear()

    def animate(self, fps: float = 30.0, gap_s: float = 0.5) -> Any:
        """Send one meshcat animation playing every queued clip (configuration sets and
        trajectories) one after the other; returns the ``meshcat.animation.Animation``."""

        anim = Animation(default_framerate=int(round(fps)))
        geom = self.viz.visual_model
        gdata = self.viz.visual_data
        nodes = [self.viz.getViewerNodeName(obj, pin.GeometryType.VISUAL) for obj in geom.geometryObjects]
        frame0 = 0
        for _name, t, q in self._clips:
            n_frames = max(1, int(np.ceil((t[-1] - t[0]) * fps))) + 1
            for k in range(n_frames):
                qk = _interp(t, q, t[0] + k / fps)
                pin.forwardKinematics(self.model, self.viz.data, qk)
                pin.updateGeometryPlacements(self.model, self.viz.data, geom, gdata)
                with anim.at_frame(self.vis, frame0 + k) as frame_vis:
                    for gid, node in enumerate(nodes):
                        frame_vis[node].set_transform(gdata.oMg[gid].homogeneous)
            frame0 += n_frames + int(round(gap_s * fps))
        if self._clips:
            self.vis.set_animation(anim, play=True, repetitions=1)
        return anim

    def _check_q(self, Q: np.ndarray, name: str) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, float))
        if Q.ndim != 2 or Q.shape[1] != self.model.nq or len(Q) == 0:
            raise PipelineError(None, name, f"expected an (N, {self.model.nq}) array, got shape {Q.shape}")
        return Q


def _interp(t: np.ndarray, q: np.ndarray, tk: float) -> np.ndarray:
    """Piecewise-linear q(tk), clamped to the ends."""
    if len(t) == 1:
        return q[0]
    return np.array([np.interp(tk, t, q[:, j]) for j in range(q.shape[1])])
