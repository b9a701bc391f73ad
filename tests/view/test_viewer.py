"""Meshcat viewer: the robot is really drawn (headless Chromium screenshot of the page)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path
from typing import NamedTuple

import meshcat
import numpy as np
import pytest
from matplotlib.image import imread

from pipeline import cli
from pipeline.core.config import load_config
from pipeline.robot.defaults import ready_pose_rad
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.run.runner import run_pipeline
from pipeline.view.run_view import find_saved_motions, is_run_dir, view_run
from pipeline.view.scene import LAYERS, camera_view, layer_of, workspace_box
from pipeline.view.viewer import Viewer

CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)


def screenshot(url: str, out: Path, tmp_path: Path, size: str = "800,600", budget_ms: int = 5000) -> np.ndarray:
    """Load ``url`` in headless Chromium and return the screenshot as an (H, W, C) float array
    (``budget_ms``: the page's virtual time before the shot, for the scene to arrive)."""
    profile = tmp_path / f"chromium-profile-{out.stem}"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={profile}", f"--screenshot={out}", f"--window-size={size}",
           f"--virtual-time-budget={budget_ms}", url]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=max(120.0, 2 * budget_ms / 1000))
    assert proc.returncode == 0 and out.exists(), proc.stderr[-2000:]
    return imread(out)[..., :3]


#: the share of the pixels that must change when a robot is shown (what the drawing tests assert; the
#: screenshots are retaken, with more page time, until a scene reaches it)
DRAWN_FRACTION = 0.01


def changed_fraction(a: np.ndarray, b: np.ndarray, threshold: float = 0.1) -> float:
    assert a.shape == b.shape
    return float(np.mean(np.abs(a - b).max(axis=-1) > threshold))


def test_configurations_and_trajectories_api(rx130l):
    vis = meshcat.Visualizer()
    try:
        v = Viewer(rx130l, viewer=vis)
        Q = np.deg2rad([[0, 0, 0, 0, 0, 0], [30, 20, 40, 0, 30, 0], [-30, -20, 60, 10, -30, 0]])
        v.show_configurations(Q, "demo")
        t = np.linspace(0.0, 1.0, 21)
        q = np.outer(t, np.deg2rad([40, 30, 20, 10, 10, 10]))
        anim = v.play(t, q, "move")
        # two clips: 3 configurations (2 s at 1 s each) and a 1 s trajectory, at 30 fps
        clip = next(iter(anim.clips.values()))
        times = [k["time"] for k in clip.tracks["position"].lower()["keys"]]
        assert min(times) == 0 and max(times) == (2 * 30 + 1) + 15 + 30
        with pytest.raises(Exception, match="expected an"):
            v.show_configurations(np.zeros((3, 5)), "bad")
    finally:
        vis.window.server_proc.kill()
        vis.window.server_proc.wait(timeout=10)


def test_saved_motions_found_in_run(fake_stages, tmp_path):
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, log=lambda m: None)
    sets, trajs = find_saved_motions(tmp_path / "r")
    assert set(sets) == {"a/test", "b/test", "c/test"} and sets["a/test"].shape == (2, 6)
    assert set(trajs) == {"a/move", "b/move", "c/move"}
    t, q = trajs["b/move"]
    assert t.shape == (5,) and q.shape == (5, 6)


def test_view_command_on_a_run(fake_stages, tmp_path, monkeypatch, capsys):
    """``view`` through :func:`pipeline.cli.main` (the ``python -m pipeline`` entry point itself is run
    in a child process by tests/test_cli.py)."""
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, log=lambda m: None)
    monkeypatch.undo()          # the real stage registry: the fake stages' directories are still read
    viewers: list[Viewer] = []

    def view_and_keep(*args, **kwargs) -> Viewer:
        viewers.append(view_run(*args, **kwargs))
        return viewers[-1]

    monkeypatch.setattr(cli, "view_run", view_and_keep)
    capsys.readouterr()
    try:
        code = cli.main(["view", str(tmp_path / "r"), "--once"])
    finally:
        for viewer in viewers:
            viewer.close()
    out, err = capsys.readouterr()
    assert code == 0, err
    assert len(viewers) == 1 and viewers[0].vis.window.server_proc.poll() is not None     # closed
    assert "http://127.0.0.1:" in out
    assert "configurations a/test" in err and "trajectory c/move" in err
    assert "layers (" in out and "  floor: " in out
    assert cli.main(["view", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {tmp_path / 'nope'}: run directory not found\n"


def test_view_refuses_a_folder_that_is_not_a_run(tmp_path, capsys):
    folder = tmp_path / "some_folder"
    (folder / "model").mkdir(parents=True)              # a sub-folder without manifest.json
    assert not is_run_dir(folder)
    assert cli.main(["view", str(folder), "--once"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {folder}: not a run directory") and err.count("\n") == 1
    (folder / "model" / "manifest.json").write_text("{}")
    assert is_run_dir(folder)
    (folder / "model" / "manifest.json").unlink()
    (folder / "config.yaml").write_text("name: x\n")
    assert is_run_dir(folder)


def robot_box(with_robot: np.ndarray, without_robot: np.ndarray, threshold: float = 0.1) -> tuple[float, ...]:
    """Bounding box (top, bottom, left, right) of the pixels the robot changes, as shares of the
    picture's height and width."""
    rows, cols = np.nonzero(np.abs(with_robot - without_robot).max(axis=-1) > threshold)
    assert rows.size > 100, "the robot changed almost no pixel"
    h, w = with_robot.shape[:2]
    return rows.min() / h, (rows.max() + 1) / h, cols.min() / w, (cols.max() + 1) / w


class Shots(NamedTuple):
    with_robot: np.ndarray          # the robot at q
    without: np.ndarray             # the same scene with the robot hidden (floor, legend)
    viewer: Viewer
    moved: np.ndarray | None        # the robot at the second pose, if one was given


def scene_screenshot(vis: meshcat.Visualizer, out: Path, tmp_path: Path, budget_ms: int) -> np.ndarray:
    """Screenshot of the scene ``vis`` holds now, from meshcat's static HTML export: the whole scene
    (objects, transforms, properties, camera) is inside the page, so the browser draws it without the
    websocket, whose several MB of mesh messages do not always arrive within the page time of a
    loaded machine."""
    page = out.with_suffix(".html")
    page.write_text(vis.static_html())
    return screenshot(page.as_uri(), out, tmp_path, budget_ms=budget_ms)


def framed_screenshots(robot, q: np.ndarray, tmp_path: Path, moved_q: np.ndarray | None = None) -> Shots:
    """Screenshots of the viewer's scene with ``robot`` at ``q`` and with the robot hidden (up to
    three tries while fewer than ``DRAWN_FRACTION`` of the pixels differ, each with three times the
    page time: 5 s to 45 s), then, with ``moved_q``, one with the robot moved there."""
    vis = meshcat.Visualizer()
    moved = None
    try:
        viewer = Viewer(robot, viewer=vis)
        viewer.show(q)
        for attempt in range(3):
            budget_ms = 5000 * 3 ** attempt
            with_robot = scene_screenshot(vis, tmp_path / f"robot{attempt}.png", tmp_path, budget_ms)
            vis[viewer.root].set_property("visible", False)
            without = scene_screenshot(vis, tmp_path / f"hidden{attempt}.png", tmp_path, budget_ms)
            vis[viewer.root].set_property("visible", True)
            if changed_fraction(with_robot, without) > DRAWN_FRACTION:
                break
        if moved_q is not None:
            viewer.show(moved_q)
            moved = scene_screenshot(vis, tmp_path / "moved.png", tmp_path, budget_ms)
    finally:
        vis.window.server_proc.kill()
        vis.window.server_proc.wait(timeout=10)
    return Shots(with_robot, without, viewer, moved)


#: the framed arm spans this share of the picture's height, and stays this far inside its edges
FRAMED_HEIGHT_SHARE = (0.2, 0.9)
EDGE_SHARE = 0.01


def assert_framed(with_robot: np.ndarray, without: np.ndarray) -> None:
    top, bottom, left, right = robot_box(with_robot, without)
    assert FRAMED_HEIGHT_SHARE[0] <= bottom - top <= FRAMED_HEIGHT_SHARE[1], (top, bottom)
    assert top > EDGE_SHARE and bottom < 1 - EDGE_SHARE and left > EDGE_SHARE and right < 1 - EDGE_SHARE, \
        (top, bottom, left, right)


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (make test installs it via apt)")
def test_primitive_arm_is_drawn_framed_with_its_floor_and_moves(rx130l, tmp_path):
    """The RX130L in meshcat, seen by headless Chromium: drawn (its yellow links on screen, absent
    when it is hidden), framed with the floor and the legend, and redrawn when it moves."""
    with_robot, without, viewer, bent = framed_screenshots(rx130l, ready_pose_rad(rx130l), tmp_path,
                                                           moved_q=np.deg2rad([90, 60, 30, 0, 0, 0]))
    assert viewer.drawn_as == "meshes"            # the URDF's own primitives (cylinders, boxes)
    drawn = changed_fraction(without, with_robot)
    moved = changed_fraction(with_robot, bent)
    assert drawn > DRAWN_FRACTION, f"only {drawn:.4f} of the pixels changed when the robot was shown"
    assert moved > 0.005, f"only {moved:.4f} of the pixels changed when the robot moved"
    # the URDF's yellow links are on screen, and not with the robot hidden
    yellow = (with_robot[..., 0] > 0.7) & (with_robot[..., 1] > 0.4) & (with_robot[..., 2] < 0.3)
    yellow_hidden = (without[..., 0] > 0.7) & (without[..., 1] > 0.4) & (without[..., 2] < 0.3)
    assert yellow.sum() > 500 and yellow_hidden.sum() < 50
    assert_framed(with_robot, without)
    assert "floor" in viewer.legend and "collision.floor_z_m" in viewer.legend_text()
    # the legend picture in the top left corner: pale, with dark text
    h, w = with_robot.shape[:2]
    corner = with_robot[int(0.02 * h):int(0.08 * h), int(0.15 * w):int(0.45 * w)]
    assert corner.mean() > 0.75 and (corner.max(axis=-1) < 0.5).mean() > 0.003


def test_layers_are_named_and_explained(rx130l):
    assert layer_of("calibration/selected", False) == "chosen poses"
    assert layer_of("calibration/heldout", False) == "held-out poses"
    assert layer_of("calibration/candidates", False) == "candidates"
    assert layer_of("control/iso_desired", True) == "ISO path"
    assert layer_of("trajectory/cp_smooth", True) == "CP path" and layer_of("trajectory/ptp", True) == "PtP path"
    vis = meshcat.Visualizer()
    try:
        v = Viewer(rx130l, viewer=vis)
        Q = np.deg2rad([[0, 0, 0, 0, 0, 0], [30, 20, 40, 0, 30, 0]])
        v.show_points(v._tcp_points(Q, "tcp"), "calibration/candidates", LAYERS["candidates"][0], layer="candidates")
        v.show_path(v._tcp_points(Q, "tcp"), "trajectory/ptp", LAYERS["PtP path"][0], layer="PtP path")
        text = v.legend_text()
        cell = v.jupyter_cell()
    finally:
        vis.window.server_proc.kill()
        vis.window.server_proc.wait(timeout=10)
    lines = text.splitlines()
    assert any(line.startswith("  candidates: grey, calibration candidates (2 points)") for line in lines)
    assert any(line.startswith("  PtP path: red, point-to-point move") for line in lines)
    assert "PtP path" in cell.data and "<iframe" in cell.data


def test_camera_frames_the_reach_of_small_and_large_arms(rx130l):
    small = RobotModel.load(example_arm_urdf("ur_description/urdf/ur3_robot.urdf") or pytest.skip("no example arms"))
    for robot in (rx130l, small):
        box = workspace_box(robot.model, robot.spec.collision.floor_z_m)
        target, position = camera_view(robot.model, robot.spec.collision.floor_z_m)
        assert np.all(box[0] <= target) and np.all(target <= box[1])
        assert box[0, 2] >= robot.spec.collision.floor_z_m
        size = np.linalg.norm(box[1] - box[0])
        # the camera stands outside the box, at a distance that scales with the arm
        assert np.any(position < box[0]) or np.any(position > box[1])
        assert 0.5 * size < np.linalg.norm(position - target) < 2.0 * size
