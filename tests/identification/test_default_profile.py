"""Identification targets in the default profile: condition number, z-scores of the base parameters,
validation torque RMS, the TX40 record (slow: about 1-2 min per seed on 2 cores)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.identification import stage

from .helpers import NO_LOAD_FRICTION, quick_context, true_base


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_default_profile_meets_the_targets(tmp_path, seed):
    ctx, real = quick_context(tmp_path, seed=seed, truth=NO_LOAD_FRICTION)   # z-scores: model contains the truth
    ctx.config = stage.Config(run_tx40=True)  # the default profile (+ the TX40 record)
    res = stage.run(ctx)
    s = res.summary
    assert s["cond_random_median"] >= 5 * s["cond_optimized"]
    z = (res.arrays["base_beta"] - true_base(real, res.arrays["base_matrix_E"])) / res.arrays["base_sigma"]
    assert np.mean(np.abs(z) <= 3) >= 0.95
    assert np.all(np.asarray(s["validation_torque_rms_Nm"]) <= 1.3 * np.asarray(s["torque_noise_sigma_Nm"]))
    assert s["validation_trajectory"] == "iso9283"
    assert s["physically_consistent"] and s["tx40_physically_consistent"]
    assert s["tx40_heldout_rms_Nm_physical"] <= 3.35
