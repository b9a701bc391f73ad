"""Commissioning toolkit for a 6-axis industrial arm.

Four stages share one robot model: geometric calibration, dynamic identification,
model-based feedforward control and time/energy-optimal trajectories.
"""

__version__ = "0.1.0"
