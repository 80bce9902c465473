"""The calibration's medians (the standard library's), means and spreads in Python are NumPy's
to the last bit (recorded numbers rest on it)."""

from __future__ import annotations

import math
from statistics import median

import numpy as np

from tdmon.calib.scatter import Scatter, scatter_std


def test_the_standard_librarys_median_is_numpys_to_the_last_bit() -> None:
    # odd and even counts, hook loads and their absolute deviations (many ties near zero)
    rng = np.random.default_rng(7)
    for n in (1, 2, 3, 4, 7, 8, 119, 120, 400):
        for _ in range(50):
            values = 1.4e6 + 3e3 * rng.standard_normal(n)
            assert median(values.tolist()) == np.median(values)
            deviations = np.abs(values - np.median(values))
            assert median(deviations.tolist()) == np.median(deviations)
            rounded = np.round(values, -3)  # ties
            assert median(rounded.tolist()) == np.median(rounded)


def test_scatter_std_is_the_numpy_formula() -> None:
    # tau^2 = (1.4826 median|diff mu| / sqrt 2)^2 - median(se^2), computed as NumPy would
    rng = np.random.default_rng(3)
    for n in (5, 6, 8, 13):
        mu = 0.25 + 0.03 * rng.standard_normal(n)
        se = 0.005 + 0.002 * rng.random(n)
        s = 1.4826 * float(np.median(np.abs(np.diff(mu)))) / math.sqrt(2.0)
        expected = math.sqrt(max(0.0, s * s - float(np.median(np.square(se)))))
        got = scatter_std(Scatter(tuple(mu.tolist()), tuple(se.tolist())), prior=0.5)
        assert got == expected
        assert got != 0.5  # estimated, not the prior


def test_window_mean_and_spread_are_numpys_to_the_last_bit() -> None:
    # the windows' mean and sample standard deviation skip np.mean/np.std's wrappers
    from tdmon.calib.windows import _mean_se

    rng = np.random.default_rng(11)
    for n in (2, 3, 7, 8, 9, 16, 17, 60, 119, 120, 300):
        for _ in range(30):
            values = 1.4e6 + 3e3 * rng.standard_normal(n)
            mean, se = _mean_se(values, floor=0.0)
            assert mean == float(np.mean(values))
            assert se == float(np.std(values, ddof=1)) / math.sqrt(n)
    assert _mean_se(np.array([5.0]), floor=2.0) == (5.0, 2.0)


def test_window_means_of_lists_are_numpys_to_the_last_bit() -> None:
    # depth, rotation and speed means skip np.mean's wrapper (lists and arrays alike)
    from tdmon.calib.windows import _mean

    rng = np.random.default_rng(13)
    for n in (1, 2, 3, 7, 8, 9, 16, 17, 60, 119, 120, 300, 9000):
        for _ in range(10):
            values = 2500.0 + 40.0 * rng.standard_normal(n)
            assert _mean(values) == float(np.mean(values))
            assert _mean(values.tolist()) == float(np.mean(values.tolist()))
