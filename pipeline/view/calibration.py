"""Meshcat view of a calibration: chosen configurations, reflector points, tracker and beams."""

from __future__ import annotations

import meshcat.geometry as g
import meshcat.transformations as tf
import numpy as np
import pinocchio as pin

from pipeline.robot.model import RobotModel
from pipeline.view.scene import LAYERS
from pipeline.view.viewer import Viewer


def show_calibration(robot: RobotModel, Q: np.ndarray, transform_tracker_to_base: pin.SE3 | None = None,
                     viewer: Viewer | None = None, seconds_each: float = 1.0) -> Viewer:
    """Open (or reuse) a :class:`pipeline.view.viewer.Viewer`, draw the configurations ``Q`` (reflector
    points + an animation through them), the tracker as a sphere and a beam to every point."""
    v = viewer if viewer is not None else Viewer(robot)
    T = transform_tracker_to_base if transform_tracker_to_base is not None else \
        robot.tracker.transform_tracker_to_base
    P = robot.positions(Q, robot.frame_reflector)
    v.vis["tracker"].set_object(g.Sphere(0.06), g.MeshLambertMaterial(color=0x444444))
    v.vis["tracker"].set_transform(tf.translation_matrix(np.asarray(T.translation, float)))
    segs = np.empty((3, 2 * len(P)))
    segs[:, 0::2] = np.asarray(T.translation, float)[:, None]
    segs[:, 1::2] = P.T
    v.vis["beams"].set_object(g.LineSegments(g.PointsGeometry(segs),
                                             g.LineBasicMaterial(color=0xD62728, linewidth=1)))
    v.add_legend("tracker", 0x444444, "the laser tracker (nominal pose)")
    v.add_legend("beams", 0xD62728, "beams from the tracker to the reflector")
    v.show_configurations(Q, "calibration", frame=robot.frame_reflector, seconds_each=seconds_each,
                          layer="chosen poses", color=LAYERS["chosen poses"][0])
    return v
