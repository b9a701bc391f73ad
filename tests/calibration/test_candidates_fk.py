"""The vectorised numpy chain of the candidate filter against Pinocchio (RobotModel)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.calibration import batch_kinematics as bk
from pipeline.calibration import candidates as cd
from pipeline.robot.model import RobotModel


@pytest.mark.parametrize("name", ["rx130l", "staubli_tx40"])
def test_numpy_chain_matches_pinocchio(name):
    robot = RobotModel.load(name)
    ch = bk.chain_from_robot(robot)
    rng = np.random.default_rng(7)
    # random configurations, also outside the joint limits (the kinematics must not care)
    Q = rng.uniform(ch.lower - 0.5, ch.upper + 0.5, size=(200, robot.nq))
    kin = bk.kinematics(ch, Q)
    seg = bk.capsule_segments(ch, kin)
    assert np.allclose(kin.p_reflector, robot.positions(Q, robot.frame_reflector), atol=1e-12, rtol=0)
    assert np.allclose(kin.o_flange, robot.positions(Q, robot.frame_flange), atol=1e-12, rtol=0)
    _, R_refl = robot.poses(Q, robot.frame_reflector)
    assert np.allclose(kin.reflector_axis, R_refl @ robot.reflector_axis, atol=1e-12, rtol=0)
    assert np.allclose(seg, robot.capsule_segments(Q), atol=1e-12, rtol=0)
    # the clearances the filter thresholds are Pinocchio's
    pair, floor = robot.capsule_clearances(seg)
    pair_ref, floor_ref = robot.capsule_clearances(robot.capsule_segments(Q))
    assert np.allclose(pair, pair_ref, atol=1e-12, rtol=0) and np.allclose(floor, floor_ref, atol=1e-12, rtol=0)
    # margin-free filter verdicts agree with the Pinocchio collision rule
    mask, _ = cd.filter_configurations(ch, Q, cd.FilterMargins(0.0, 0.0, 0.0), visibility=False)
    inside = np.all((Q >= ch.lower) & (Q <= ch.upper), axis=1)
    ref = inside & np.all(pair_ref >= 0, axis=1) & np.all(floor_ref >= 0, axis=1)
    assert np.array_equal(mask, ref)


@pytest.mark.parametrize("visibility,n", [(False, 60), (True, 200)])
def test_random_candidates_stop_filtering_at_the_last_one_needed_and_keep_the_draws(rx130l, visibility, n):
    """The last batch filtered only up to its n-th feasible draw gives the configurations, and leaves
    the generator where, filtering and counting every draw (the candidate set's report), it would."""
    chain = bk.chain_from_robot(rx130l)
    runs = []
    for count_all in (False, True):
        rng = np.random.default_rng(11)
        Q, counts = cd.random_candidates(chain, n, rng, cd.FilterMargins(), visibility=visibility,
                                         count_all=count_all)
        runs.append((Q, counts, rng.random()))
    (Q, counts, after), (Q_all, counts_all, after_all) = runs
    assert len(Q) == n and np.array_equal(Q, Q_all) and after == after_all
    assert counts_all["feasible"] >= counts["feasible"] >= n
    assert counts["total"] < counts_all["total"]      # the rest of the batch was never filtered
    mask, _ = cd.filter_configurations(chain, Q, cd.FilterMargins(), visibility=visibility)
    assert mask.all()


@pytest.mark.parametrize("visibility", [True, False])
def test_incidence_first_filter_rejects_the_same_rows(rx130l, visibility):
    """``reasons=False`` (incidence before the capsules, capsules on the rows it passes) keeps exactly the
    rows of the full check; only the split of the rejections between collision and visibility may move."""
    chain = bk.chain_from_robot(rx130l)
    Q = np.random.default_rng(3).uniform(chain.lower - 0.2, chain.upper + 0.2, size=(20000, rx130l.nq))
    full, counts_full = cd.filter_configurations(chain, Q, visibility=visibility)
    fast, counts_fast = cd.filter_configurations(chain, Q, visibility=visibility, reasons=False)
    assert full.any() and not full.all() and np.array_equal(fast, full)
    for key in ("total", "limits", "feasible"):
        assert counts_fast[key] == counts_full[key]
    assert (counts_fast["collision"] + counts_fast["visibility"]
            == counts_full["collision"] + counts_full["visibility"] > 0)
