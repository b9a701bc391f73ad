"""Hypothesis profiles of the fuzz tests (``test_fuzz_*.py``): ``fuzz`` for the fast suite (a
bounded number of inputs per reader, ``PIPELINE_FUZZ_EXAMPLES``, default 25) and ``fuzz-slow``
for the slow-marked variants that ``make test-slow`` runs (``PIPELINE_FUZZ_SLOW_EXAMPLES``,
default 200). The fast profile draws the same inputs every run (``derandomize``: ``make test`` does
not flake), the slow one new inputs every run (a failure prints the blob that reproduces it). No
deadline (a loaded two-core machine), no example database."""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

_COMMON = {"deadline": None, "database": None, "print_blob": True,
           "suppress_health_check": [HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                     HealthCheck.filter_too_much, HealthCheck.data_too_large]}
settings.register_profile("fuzz", max_examples=int(os.environ.get("PIPELINE_FUZZ_EXAMPLES", "25")),
                          derandomize=True, **_COMMON)
settings.register_profile("fuzz-slow", max_examples=int(os.environ.get("PIPELINE_FUZZ_SLOW_EXAMPLES", "200")),
                          **_COMMON)
