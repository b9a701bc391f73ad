"""The control stage's Bode figure: every axis drawn, each in a style of its own."""

from __future__ import annotations

import numpy as np

from pipeline.control.config import ControlConfig
from pipeline.control.design import ServoDesign, filter_alpha
from pipeline.control.report import bode_figure
from pipeline.control.simulate import servo_gains


def test_bode_figure_draws_every_axis_in_its_own_style(rx130l):
    cfg = ControlConfig()
    gains = servo_gains(rx130l, np.zeros(rx130l.nq), cfg)
    nv = cfg.velocity_samples_per_position_sample
    alpha = filter_alpha(cfg.velocity_filter_hz, cfg.sample_time_s / nv)
    servo = ServoDesign(gains, nv, alpha, [])      # the margins' report is not drawn
    fig = bode_figure(servo.loop_models(rx130l.nq, cfg.sample_time_s, cfg.measurement_delay_samples))
    for ax in fig.axes:
        curves = [line for line in ax.get_lines() if len(line.get_xdata()) > 2]     # not the 0 dB / -180 deg lines
        assert len(curves) == rx130l.nq
        styles = {(line.get_color() if isinstance(line.get_color(), str) else tuple(line.get_color()),
                   line.get_linestyle(), line.get_linewidth()) for line in curves}
        assert len(styles) == rx130l.nq
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert [s.split(" (")[0] for s in labels] == [f"axis {j + 1}" for j in range(rx130l.nq)]
