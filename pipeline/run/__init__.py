"""The run layer: stage plan, reuse, locking, interrupts, second pass, headline, report, sweeps.

Importing it registers the stages (:mod:`pipeline.run.stages`) with the run configuration's loader.
"""

from pipeline.run import stages as _stages  # noqa: F401 - registers the stages
