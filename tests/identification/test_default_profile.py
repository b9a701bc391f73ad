"""Identification targets in the default profile on the default hidden robot (Stribeck and
load-dependent Coulomb friction): condition number, z-scores of the base parameters and of the
load-dependent coefficient against the truth, validation torque RMS, the TX40 record (slow: about
1.5-2 min per seed on 2 cores)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.identification import stage

from .helpers import quick_context, true_base


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_default_profile_meets_the_targets(tmp_path, seed):
    ctx, real = quick_context(tmp_path, seed=seed)
    ctx.config = stage.Config(run_tx40=True)  # the default profile (+ the TX40 record)
    res = stage.run(ctx)
    s = res.summary
    assert s["cond_random_median"] >= 5 * s["cond_optimized"]
    z = (res.arrays["base_beta"] - true_base(real, res.arrays["base_matrix_E"])) / res.arrays["base_sigma"]
    assert np.mean(np.abs(z) <= 3) >= 0.95
    assert np.all(np.asarray(s["validation_torque_rms_Nm"]) <= 1.1 * np.asarray(s["torque_noise_sigma_Nm"]))
    assert s["validation_trajectory"] == "iso9283"
    assert s["physically_consistent"] and s["tx40_physically_consistent"]
    assert s["tx40_heldout_rms_Nm_physical"] <= 3.35
    # the held-out data choose the load-dependent term; its coefficient is the truth's mu F_c / tau_max
    assert s["friction_model_handed_on"] == "stribeck_load"
    tr = real.transmission
    fl_true = tr.coulomb_load_coefficient * tr.coulomb_Nm / tr.effort_Nm
    fl, fl_sigma = res.arrays["load_friction_coefficient"], res.arrays["load_friction_sigma"]
    kept = fl > 0
    assert np.all(np.abs(fl - fl_true)[kept] <= 3 * fl_sigma[kept])
    np.testing.assert_array_equal(res.robot.actuation.coulomb_load_coefficient, fl)
