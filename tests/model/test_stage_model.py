"""Stage ``model``: its settings are checked at load time (ranges) and before the run (the robot)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.core.config import load_config
from pipeline.core.errors import ConfigError
from pipeline.model import stage


def test_default_settings_pass(rx130l):
    cfg = stage.Config()
    cfg.validate("x.yaml")
    stage.check(cfg, rx130l)
    run_model = load_config().model            # rx130l's run_defaults pin its picture pose only
    assert dataclasses.replace(run_model, pose_deg=None) == cfg and len(run_model.pose_deg) == rx130l.nq
    stage.check(run_model, rx130l)


@pytest.mark.parametrize(
    ("value", "field_name", "problem"),
    [
        ("model.views_deg=[]", "model.views_deg", "expected 1 to 6"),
        ("model.views_deg=[[0,0],[0,0],[0,0],[0,0],[0,0],[0,0],[0,0]]", "model.views_deg", "got 7"),
        ("model.views_deg=[[95,0]]", "model.views_deg[0]", "elevation in [-90, 90]"),
        ("model.views_deg=[[10,-60],[0,.nan]]", "model.views_deg[1]", "azimuth"),
        ("model.picture_size_in=-1", "model.picture_size_in", "expected a size in [1, 20] inches, got -1"),
        ("model.picture_size_in=0", "model.picture_size_in", "inches"),
        ("model.picture_size_in=500", "model.picture_size_in", "inches"),
        ("model.picture_size_in=.inf", "model.picture_size_in", "inches"),
        ("model.pose_deg=[]", "model.pose_deg", "empty list"),
        ("model.pose_deg=[0,0,.nan,0,0,0]", "model.pose_deg", "finite"),
    ],
)
def test_bad_picture_settings_name_the_field(value, field_name, problem):
    with pytest.raises(ConfigError) as err:
        load_config(None, [value])
    assert str(err.value).startswith(f"--set: {field_name}: ") and problem in str(err.value)


def test_pose_checked_against_the_robot(rx130l):
    lower = np.rad2deg(rx130l.limits.lower_rad)
    upper = np.rad2deg(rx130l.limits.upper_rad)
    ok = dataclasses.replace(stage.Config(), pose_deg=tuple(upper))       # on the limits: fine
    stage.check(ok, rx130l)
    stage.check(dataclasses.replace(ok, pose_deg=tuple(lower)), rx130l)
    with pytest.raises(ConfigError, match=r"^model\.pose_deg: expected 6 angles \(deg\), one per joint, got 3"):
        stage.check(dataclasses.replace(ok, pose_deg=(0.0, 0.0, 0.0)), rx130l)
    beyond = np.zeros(6)
    beyond[4] = upper[4] + 1.0
    with pytest.raises(ConfigError) as err:
        stage.check(dataclasses.replace(ok, pose_deg=tuple(beyond)), rx130l)
    assert err.value.file is None and err.value.field == "model.pose_deg"
    assert "angle 5 (joint_5)" in err.value.problem and "outside the joint limits" in err.value.problem
