"""calibration_parameters.csv: the parameter table written and read back, every error parameter with a unit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.calibration import error_model as em
from pipeline.core.errors import DataFileError
from pipeline.exchange.parameter_table import ParameterTable, read_parameter_table_csv, write_parameter_table_csv


def test_the_table_reads_back_bit_for_bit(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    names = ("j2.dq", "j3.c", "reflector.dx", "a,b")       # a name with the separator is quoted
    table = ParameterTable(names, rng.normal(size=4) * 1e-4, np.abs(rng.normal(size=4)) * 1e-6,
                           ("rad", "rad/(N m)", "m", "m"))
    back = read_parameter_table_csv(write_parameter_table_csv(tmp_path / "p.csv", table))
    assert back.names == names and back.units == table.units
    np.testing.assert_array_equal(back.values, table.values)
    np.testing.assert_array_equal(back.stds, table.stds)


def test_a_bad_table_names_the_file_and_the_line(tmp_path: Path) -> None:
    bad = tmp_path / "p.csv"
    bad.write_text("name,value\nj1.dq,1\n")
    with pytest.raises(DataFileError, match="header"):
        read_parameter_table_csv(bad)
    bad.write_text("parameter,value,std,unit\nj1.dq,1,0.1,rad\nj2.dq,x,0.1,rad\n")
    with pytest.raises(DataFileError, match="line 3"):
        read_parameter_table_csv(bad)


def test_every_error_parameter_has_a_unit(rx130l) -> None:
    names = em.MeasurementModel(rx130l, compliance=True).names
    _, mdh_names = em.mdh_basis(rx130l, names)
    units = {name: em.parameter_unit(name) for name in [*names, *mdh_names]}
    assert units["j2.dx"] == units["reflector.dz"] == "m" and units["j2.dq"] == units["tracker.rz"] == "rad"
    assert units["j3.c"] == "rad/(N m)"
    assert {units[n] for n in mdh_names if n.split(".")[1] in ("da", "dd")} == {"m"}
    assert {units[n] for n in mdh_names if n.split(".")[1] in em.MDH_ROTATIONS} == {"rad"}
    with pytest.raises(ValueError, match="unknown component"):
        em.parameter_unit("j1.speed")
