"""A joint track a whole turn outside a wide joint range is the same motion a turn back inside."""

from __future__ import annotations

import numpy as np

from pipeline.robot.paths import wrap_into_limits


def test_a_wrist_a_turn_outside_its_range_is_shifted_inside_with_the_same_poses(rx130l):
    hi6 = rx130l.limits.upper_rad[5]                     # the RX130L's wrist turns ±270°
    Q = np.tile(np.radians([10.0, 20.0, 30.0, 0.0, 40.0, 0.0]), (20, 1))
    Q[:, 5] = np.linspace(-hi6 - 0.2, -hi6 + 0.3, 20)     # starts 0.2 rad below the lower limit
    wrapped = wrap_into_limits(rx130l, Q)
    assert np.all(wrapped >= rx130l.limits.lower_rad) and np.all(wrapped <= rx130l.limits.upper_rad)
    assert np.allclose(wrapped[:, 5] - Q[:, 5], 2 * np.pi)
    assert np.array_equal(wrapped[:, :5], Q[:, :5])
    for q, w in zip(Q, wrapped, strict=True):              # the same TCP pose at every sample
        assert np.allclose(rx130l.fk(q).homogeneous, rx130l.fk(w).homogeneous, atol=1e-12)


def test_a_track_no_turn_brings_inside_is_left_as_it_is(rx130l):
    Q = np.tile(np.radians([10.0, 20.0, 30.0, 0.0, 40.0, 0.0]), (5, 1))
    Q[:, 1] = np.linspace(-3.0, 3.0, 5)                   # spans more than joint 2's whole range
    assert np.array_equal(wrap_into_limits(rx130l, Q), Q)
