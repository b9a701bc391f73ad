"""notebooks/02_identification.ipynb runs top to bottom in the quick setting."""

from __future__ import annotations

import pytest

#: a smaller quick setting: a fifth of the samples per period, 30 samples per period in the excitation NLP,
#: 4 random trajectories and 30 IPOPT iterations for the excitation, the linear friction model (no Stribeck
#: fits), the first 4 s of the TX40 record (the quick stage itself, Stribeck fits included:
#: tests/identification/test_stage.py; the whole TX40 record: tests/identification/test_tx40.py)
SMALL = {"identification.decimation": 20, "identification.excitation.n_samples": 30,
         "identification.excitation.n_random": 4, "identification.excitation.max_iter": 30,
         "identification.tx40.max_samples": 20000, "identification.friction_model": "viscous_coulomb"}


def _check(run) -> None:   # run: ExecutedNotebook (tests/conftest.py)
    """The notebook printed its figures' numbers and showed its figures inline."""
    text = run.text
    assert run.images, "no figure shown inline (no image/png output)"
    assert "base parameters" in text and "cond optimised" in text and "tx40_heldout_rms_Nm_physical" in text
    assert "physically consistent: True" in text and "within 3 sigma (nominal kinematics)" in text


def test_identification_notebook_executes(tmp_path, execute_notebook):
    """Every cell on a smaller setting (the same code path: excitation design, the load-dependent friction
    candidate, ISO path validation, the TX40 record); the slow twin runs the notebook as shipped (its
    Stribeck fits too)."""
    run = execute_notebook("02_identification.ipynb", tmp_path, {"SETTINGS": SMALL})
    _check(run)
    text = run.text
    assert "n_samples=30, n_starts=1, n_random=4, max_iter=30" in text        # the setting reached the stage


@pytest.mark.slow
def test_identification_notebook_executes_as_shipped(tmp_path, execute_notebook):
    """The notebook with its own quick setting (what a user runs): the full excitation design."""
    _check(execute_notebook("02_identification.ipynb", tmp_path))
