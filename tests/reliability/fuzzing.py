"""The fast and the slow variant of a fuzz property (profiles ``fuzz`` and ``fuzz-slow``,
tests/reliability/conftest.py)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import given, settings


def fast_and_slow(share: float = 1.0, **strategies: Any) -> Callable[[Callable], tuple[Callable, Callable]]:
    """The property test over ``strategies`` (profile ``fuzz``; ``share`` of its inputs for a reader
    that takes long per input) and its slow-marked variant (``fuzz-slow``, ``make test-slow``)."""
    def make(body: Callable) -> tuple[Callable, Callable]:
        fast_profile = settings.get_profile("fuzz")
        fast = settings(fast_profile, max_examples=max(5, round(share * fast_profile.max_examples)))(
            given(**strategies)(body))
        slow = pytest.mark.slow(settings(settings.get_profile("fuzz-slow"))(given(**strategies)(body)))
        return fast, slow
    return make
