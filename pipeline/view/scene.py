"""The viewer's scene layout: named layers and their colours, the floor's extent and the camera
framing any arm (:mod:`pipeline.view.viewer`).

meshcat's orbit controls always turn about the page's origin, and its default camera has a 75 deg
vertical field of view (three.js ``PerspectiveCamera(75, ...)``): the viewer frames an arm by
placing the camera along ``VIEW_DIRECTION`` from the centre of the arm's reachable box and shifting
the scene so that centre sits at the page's origin.
"""

from __future__ import annotations

import io

import numpy as np
import numpy.typing as npt
import pinocchio as pin
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

#: named layers (meshcat scene tree paths, each toggled in the page's Controls panel): colour, meaning
LAYERS: dict[str, tuple[int, str]] = {
    "candidates": (0x9E9E9E, "calibration candidates"),
    "chosen poses": (0xE6550D, "measured by the calibration"),
    "not visible poses": (0x252525, "chosen, not seen by the tracker"),
    "held-out poses": (0x31A354, "calibration validation"),
    "ISO path": (0x3182BD, "EN ISO 9283 path (control)"),
    "CP path": (0x756BB1, "continuous path (trajectory)"),
    "PtP path": (0xD62728, "point-to-point move (trajectory)"),
    "excitation path": (0x8C564B, "identification excitation"),
}
COLOUR_NAMES = {0xE6550D: "orange", 0x3182BD: "blue", 0x31A354: "green", 0x756BB1: "purple", 0xD62728: "red",
                0x8C564B: "brown", 0x9E9E9E: "grey", 0xD9D9D9: "light grey", 0x252525: "black", 0x444444: "dark grey"}
#: meshcat's default camera: vertical field of view (three.js PerspectiveCamera(75, ...))
CAMERA_FOV_DEG = 75.0
#: direction from the target to the camera: a three-quarter view from the front left, slightly above
VIEW_DIRECTION = np.array([0.75, -1.0, 0.55])
#: tan of half the vertical field of view
HALF_VIEW_TAN = float(np.tan(np.radians(CAMERA_FOV_DEG) / 2))
#: the legend picture: distance in front of the camera, height of one line as a share of the view's
LEGEND_DISTANCE_M = 0.5
LEGEND_LINE_SHARE = 0.03
#: camera distance as a share of the one at which the reachable box's bounding sphere spans the view
FRAME_SHARE = 0.8
#: random configurations whose joint and frame origins give the arm's reachable box
WORKSPACE_SAMPLES = 400


def workspace_box(model: pin.Model, floor_z_m: float = 0.0) -> np.ndarray:
    """(2, 3) lower and upper corner of the box holding every joint and frame origin over random
    configurations inside the joint limits (fixed seed; unbounded joints within +-pi), cut at the
    floor: the region the arm can sweep."""
    lo = np.clip(model.lowerPositionLimit, -np.pi, np.pi)
    hi = np.clip(model.upperPositionLimit, -np.pi, np.pi)
    data = model.createData()
    points: list[np.ndarray] = []
    for q in np.random.default_rng(0).uniform(lo, hi, (WORKSPACE_SAMPLES, model.nq)):
        pin.framesForwardKinematics(model, data, q)
        points.extend(f.translation.copy() for f in data.oMf)
    P = np.array(points)
    box = np.array([P.min(axis=0), P.max(axis=0)])
    box[0, 2] = max(box[0, 2], floor_z_m)
    box[1, 2] = max(box[1, 2], box[0, 2] + 1e-3)
    return box


def camera_view(model: pin.Model, floor_z_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(target, camera position), world frame: the target is the centre of :func:`workspace_box`,
    the camera looks at it along ``VIEW_DIRECTION`` from ``d = FRAME_SHARE rho / tan(fov / 2)``, rho
    the radius of the box's bounding sphere (the box's own outline, narrower than the sphere's,
    then still fits the picture)."""
    box = workspace_box(model, floor_z_m)
    target = box.mean(axis=0)
    rho = 0.5 * float(np.linalg.norm(box[1] - box[0]))
    distance = FRAME_SHARE * max(rho, 0.1) / np.tan(np.radians(CAMERA_FOV_DEG) / 2)
    return target, target + distance * VIEW_DIRECTION / np.linalg.norm(VIEW_DIRECTION)


def layer_of(key: str, trajectory: bool) -> str:
    """The named layer of a run's configuration set or trajectory ``<stage>/<name>``."""
    name = key.split("/", 1)[-1]
    if trajectory:
        for prefix, layer in (("iso", "ISO path"), ("cp", "CP path"), ("ptp", "PtP path"),
                              ("excitation", "excitation path")):
            if name.startswith(prefix):
                return layer
        return "paths"
    return {"selected": "chosen poses", "heldout": "held-out poses", "candidates": "candidates",
            "not_visible": "not visible poses"}.get(name, "poses")


def translation(p: npt.ArrayLike) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = np.asarray(p, float)
    return T


def colour_name(color: int) -> str:
    return COLOUR_NAMES.get(color, f"#{color:06x}")


def legend_png(legend: dict[str, tuple[int, str]]) -> tuple[bytes, float]:
    """The legend (layer -> colour, meaning) as a PNG with a white, half-transparent background, and
    its width / height."""
    lines = max(len(legend), 1)
    longest = max((len(layer) + len(text) for layer, (_, text) in legend.items()), default=10)
    width_in, height_in = 0.06 * (longest + 8), 0.22 * (lines + 0.6)
    fig = Figure(figsize=(width_in, height_in), dpi=150)
    fig.patch.set_facecolor((1.0, 1.0, 1.0, 0.75))
    FigureCanvasAgg(fig)
    for k, (layer, (color, text)) in enumerate(legend.items()):
        y = 1.0 - (k + 0.8) / (lines + 0.6)
        fig.text(0.08 / width_in, y, "\u25a0", color=f"#{color:06x}", fontsize=9, va="center")
        fig.text(0.25 / width_in, y, f"{layer}: {text}", fontsize=7, va="center")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", facecolor=fig.get_facecolor())
    return buffer.getvalue(), width_in / height_in
