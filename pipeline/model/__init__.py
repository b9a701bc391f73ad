"""Stage ``model``: the robot the later stages start from (:mod:`pipeline.model.stage`)."""
