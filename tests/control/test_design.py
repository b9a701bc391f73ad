"""Servo design: gains from the reflected inertia, discrete loops stable with margins."""

from __future__ import annotations

import warnings

import control as ct
import numpy as np
import pytest

from pipeline.control.design import (
    design_gains,
    filter_alpha,
    frd_gain_phase_margins,
    loop_models,
    reflected_inertia,
    servo_report,
)


def test_gains_scale_with_inertia_and_loops_meet_bandwidths(rx130l):
    q = np.array([0.0, 0.3, 1.5, 0.0, 1.2, 0.0])
    J = reflected_inertia(rx130l, q)
    assert np.all(J >= rx130l.model.armature)  # rotor inertia is part of it
    g = design_gains(J, 2 * np.pi * 5.0, 2 * np.pi * 30.0)
    np.testing.assert_allclose(g.kv / J, 2 * np.pi * 30.0)
    rows = servo_report(g, 4e-4, 2, 1, filter_alpha(400.0, 2e-4))
    for r in rows:
        assert r["velocity"]["closed_loop_stable"] and r["position"]["closed_loop_stable"]
        assert r["velocity"]["phase_margin_deg"] > 45 and r["velocity"]["gain_margin_db"] > 6
        assert r["position"]["phase_margin_deg"] > 45
        assert 20.0 < r["velocity_bandwidth_hz"] < 60.0
        assert 3.0 < r["position_bandwidth_hz"] < 10.0


def test_too_aggressive_velocity_loop_loses_margin(rx130l):
    J = reflected_inertia(rx130l, np.zeros(6))
    g = design_gains(J, 2 * np.pi * 5.0, 2 * np.pi * 600.0)
    rows = servo_report(g, 4e-4, 2, 1, filter_alpha(400.0, 2e-4))
    assert all(r["velocity"]["phase_margin_deg"] < 30 or not r["velocity"]["closed_loop_stable"] for r in rows)


@pytest.mark.parametrize("joint", [
    (0.5, 2 * np.pi * 5.0, 2 * np.pi * 30.0, 400.0, 1),      # the quick profile's loops
    (30.0, 20.0, 1500.0, 150.0, 2),                           # a fast velocity loop, longer delay
    (0.05, 80.0, 100.0, 30.0, 0),                             # a slow filter, no delay
])
def test_frd_margins_are_python_controls_number_for_number(joint):
    """The loops near z = 1 where python-control falls back to frequency-response data: the gain and
    phase margins and crossovers the servo report uses are exactly ``ct.stability_margins``'."""
    J, wp, wv, filter_hz, delay = joint
    loops = loop_models(J, wp, J * wv, J * wv * wv / 4, 4e-4, 2, delay, filter_alpha(filter_hz, 2e-4))
    for name in ("velocity_open", "position_open"):
        with warnings.catch_warnings():
            warnings.simplefilter("error", UserWarning)      # the fallback warns: it is taken
            with pytest.raises(UserWarning, match="frd"):
                ct.stability_margins(loops[name])
            warnings.simplefilter("ignore", UserWarning)
            gm, pm, _sm, wpc, wgc, _ws = ct.stability_margins(loops[name])
        assert frd_gain_phase_margins(loops[name]) == (gm, pm, wpc, wgc), name
