"""The identification report's parameter figure names its base parameters."""

from __future__ import annotations

import numpy as np

from pipeline.identification.regressor import RegressorModel, base_parameters
from pipeline.identification.report import parameters_figure


def test_parameter_figure_names_each_base_parameter(rx130l):
    reg = RegressorModel(rx130l.model, np.eye(rx130l.nq), rx130l.actuation.coulomb_smoothing_rad_s)
    base = base_parameters(reg, np.random.default_rng(0), lower=rx130l.limits.lower_rad, upper=rx130l.limits.upper_rad)
    beta = np.random.default_rng(1).normal(size=base.n_base)
    fig = parameters_figure(base, beta, 0.1 * np.abs(beta), 1.05 * beta, 0.9 * beta, None)
    names = [t.get_text() for t in fig.axes[-1].get_xticklabels()]
    assert names == base.set_names and len(set(names)) == base.n_base
