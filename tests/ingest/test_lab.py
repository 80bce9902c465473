"""Reading tribometer CSV files (tdmon.ingest.lab): the thesis's Table 14 file and bad files."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from tdmon.errors import FitError
from tdmon.ingest.lab import read_tribometer_csv

LAB_CSV = Path(__file__).resolve().parents[2] / "data" / "lab" / "glydril-tribometer.csv"


def test_reads_table_14_and_drops_the_failed_run() -> None:
    data = read_tribometer_csv(LAB_CSV)
    assert data.failed_runs == 1
    assert data.friction.size == 34
    assert set(data.test) == set(range(1, 8))
    # the first and last printed runs (30 degC test 1, 70 degC test 7) and the failed run's
    # neighbour (60 degC test 2)
    assert (data.temperature[0], data.friction[0]) == (30.0, 0.372)
    assert (data.temperature[-1], data.friction[-1]) == (70.0, 0.313)
    assert (data.test[21], data.temperature[21], data.friction[21]) == (2, 60.0, 0.183)
    # the same numbers as a plain read of the file, in file order
    with LAB_CSV.open() as handle:
        rows = [row for row in csv.DictReader(line for line in handle if not line.startswith("#"))
                if row["friction_coefficient"]]
    np.testing.assert_array_equal(data.temperature, [float(r["temperature_C"]) for r in rows])
    np.testing.assert_array_equal(data.friction, [float(r["friction_coefficient"]) for r in rows])


def test_non_numeric_value_names_the_file_and_row(tmp_path: Path) -> None:
    path = tmp_path / "lab.csv"
    path.write_text("# comment\ntest,temperature_C,friction_coefficient\n1,30,0.3\n"
                    "2,30,0.2O5\n3,40,0.31\n")
    with pytest.raises(FitError, match=r"lab\.csv: data row 2: 'friction_coefficient' is not "
                                       r"a number: '0\.2O5'"):
        read_tribometer_csv(path)


def test_missing_column_and_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "lab.csv"
    path.write_text("test,temp,mu\n1,30,0.3\n")
    with pytest.raises(FitError, match=r"lab\.csv: tribometer data has no 'temperature_C' "
                                       "column"):
        read_tribometer_csv(path)
    with pytest.raises(FitError, match=r"absent\.csv: cannot read tribometer data"):
        read_tribometer_csv(tmp_path / "absent.csv")
