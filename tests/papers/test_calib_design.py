"""Quick variant of study calib-design (the full study: python -m pipeline study calib-design)."""

from __future__ import annotations

import json
import math

import pytest

from pipeline.papers import calib_design
from pipeline.papers import registry as studies


@pytest.mark.slow
def test_quick_calib_design_study_compares_every_index(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(studies, "study_dir", lambda name, root=None: tmp_path)
    assert calib_design.study_design(["--quick", "--robots", "rx130l", "--seeds", "0", "--n", "24",
                                      "--curve", "20", "--candidates", "400", "--region-poses", "60"]) == 0
    out = capsys.readouterr().out
    assert "winner at 24 configurations" in out and "measurement-effort curve" in out
    res = json.loads((tmp_path / "result.json").read_text())["robots"]["rx130l"]
    table = res["table"]
    for name in calib_design.INDICES:
        row = table[f"remove_and_replace/{name}/24"]
        assert 0 < row["actual_rms_m"] < 1e-3 and 0 < row["predicted_rms_m"] < 1e-3
    for key in ("every_kth/-/24", "random/-/24", "remove_and_replace/V/20", "every_kth/-/20"):
        assert key in table
    for head in res["headlines"].values():
        assert head["winner"] in table
        assert all(math.isfinite(g) for g in head["gain_vs_every_kth"] + head["gain_vs_O3"])
    assert all(0 < table[k]["tcp_aligned_rms_m"] < 1e-3 for k in table)
