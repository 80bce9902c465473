"""Laboratory friction measurements read from files: the I/O edge of :mod:`tdmon.calib.labfit`.

The fitting layer is pure and takes rows (:func:`tdmon.calib.labfit.tribometer_from_table`);
this module reads a tribometer CSV file into those rows. See docs/lab-fit.md.
"""

from __future__ import annotations

from pathlib import Path

from tdmon.calib.labfit import TribometerData, tribometer_from_table
from tdmon.errors import FitError

__all__ = ["read_tribometer_csv"]


def read_tribometer_csv(path: str | Path) -> TribometerData:
    """Read a tribometer CSV in the layout of ``glydril-tribometer.csv``.

    Columns ``test,temperature_C,friction_coefficient``; lines starting with ``#`` are
    comments; an empty friction cell is a failed run (dropped and counted).

    Parameters
    ----------
    path : the CSV file

    Returns
    -------
    TribometerData
        Temperatures [degC], friction coefficients [-] and test numbers of the successful
        runs, and the number of failed runs.

    Raises
    ------
    FitError
        The file cannot be read or holds bad values (the message names the file and row).
    """
    import pandas as pd  # only a lab fit needs pandas: keep it off the daemon's import path

    try:
        frame = pd.read_csv(path, comment="#", dtype=str, keep_default_na=False,
                            skipinitialspace=True)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise FitError(f"{path}: cannot read tribometer data: {exc}") from exc
    try:
        return tribometer_from_table(frame.itertuples(index=False, name=None),
                                     list(frame.columns))
    except FitError as exc:
        raise FitError(f"{path}: {exc}") from exc
