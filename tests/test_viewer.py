"""Meshcat viewer: the robot is really drawn (headless Chromium screenshot of the page)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pipeline.config import load_config
from pipeline.runner import run_pipeline
from pipeline.viewer import Viewer, find_saved_motions

CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)


def screenshot(url: str, out: Path, tmp_path: Path, size: str = "800,600") -> np.ndarray:
    """Load ``url`` in headless Chromium and return the screenshot as an (H, W, C) float array."""
    from matplotlib.image import imread

    profile = tmp_path / f"chromium-profile-{out.stem}"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={profile}", f"--screenshot={out}", f"--window-size={size}",
           "--virtual-time-budget=5000", url]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and out.exists(), proc.stderr[-2000:]
    return imread(out)[..., :3]


def changed_fraction(a: np.ndarray, b: np.ndarray, threshold: float = 0.1) -> float:
    assert a.shape == b.shape
    return float(np.mean(np.abs(a - b).max(axis=-1) > threshold))


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (make test installs it via apt)")
def test_robot_is_drawn_in_meshcat(rx130l, tmp_path):
    import meshcat

    vis = meshcat.Visualizer()                    # starts a meshcat server on 127.0.0.1
    proc = vis.window.server_proc
    try:
        assert vis.url().startswith("http://127.0.0.1:")
        empty = screenshot(vis.url(), tmp_path / "empty.png", tmp_path)
        viewer = Viewer(rx130l, viewer=vis)
        robot_zero = screenshot(vis.url(), tmp_path / "robot.png", tmp_path)
        viewer.show(np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0]) + np.deg2rad([90, 0, 0, 0, 0, 0]))
        viewer.show(np.deg2rad([0, 60, 30, 0, 0, 0]))
        robot_bent = screenshot(vis.url(), tmp_path / "bent.png", tmp_path)
    finally:
        proc.kill()
        proc.wait(timeout=10)
    drawn = changed_fraction(empty, robot_zero)
    moved = changed_fraction(robot_zero, robot_bent)
    assert drawn > 0.01, f"only {drawn:.4f} of the pixels changed when the robot was loaded"
    assert moved > 0.005, f"only {moved:.4f} of the pixels changed when the robot moved"
    # the URDF's yellow links are on screen now and were not before
    yellow = (robot_zero[..., 0] > 0.7) & (robot_zero[..., 1] > 0.4) & (robot_zero[..., 2] < 0.3)
    yellow_empty = (empty[..., 0] > 0.7) & (empty[..., 1] > 0.4) & (empty[..., 2] < 0.3)
    assert yellow.sum() > 500 and yellow_empty.sum() < 50


def test_configurations_and_trajectories_api(rx130l):
    import meshcat

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


def test_view_command_on_a_run(fake_stages, tmp_path):
    import subprocess
    import sys

    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, log=lambda m: None)
    proc = subprocess.run([sys.executable, "-m", "pipeline", "view", str(tmp_path / "r"), "--once"],
                          capture_output=True, text=True, timeout=120)
    # the fake stages are not registered in the subprocess: their directories are still read
    assert proc.returncode == 0, proc.stderr
    assert "http://127.0.0.1:" in proc.stdout
    assert "configurations a/test" in proc.stderr and "trajectory c/move" in proc.stderr
    bad = subprocess.run([sys.executable, "-m", "pipeline", "view", str(tmp_path / "nope")],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "run directory not found" in bad.stderr and "Traceback" not in bad.stderr


def test_view_refuses_a_folder_that_is_not_a_run(tmp_path, capsys):
    from pipeline import cli
    from pipeline.viewer import is_run_dir

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
