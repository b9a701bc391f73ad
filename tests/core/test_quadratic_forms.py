"""Quantiles of a weighted sum of chi-square variables (Imhof's inversion) against closed forms."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from pipeline.core.quadratic_forms import weighted_chi2_quantile


def test_imhof_quantile_matches_the_closed_form_of_two_weights():
    """``a chi2_2 + b chi2_2`` is a sum of two exponentials (means 2a, 2b): its survival function is
    ``(b e^(-x/2b) - a e^(-x/2a)) / (b - a)``; Imhof's inversion finds its quantiles."""
    a, b = 1.0, 0.3
    for p in (0.99, 1 - 0.99, 0.5):
        x = weighted_chi2_quantile(np.array([a, a, b, b]), p)
        sf = (a * np.exp(-x / (2 * a)) - b * np.exp(-x / (2 * b))) / (a - b)
        assert sf == pytest.approx(1 - p, abs=1e-8)
    # equal weights: chi-square with n dof
    assert weighted_chi2_quantile(np.full(9, 2.0), 0.99) == pytest.approx(2 * chi2.ppf(0.99, 9), rel=1e-9)
