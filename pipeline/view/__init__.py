"""Views of a run: the meshcat viewer, its scene, the calibration notebook view."""
