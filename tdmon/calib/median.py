"""The median of a few finite floats as ``np.median`` gives it, to the last bit, in Python.

The calibration takes medians of a window's samples or of the last few windows, once per window
or per frame: at these sizes (up to a few hundred values) NumPy's cost per call is larger than
sorting the values in Python. An odd count gives the middle value; an even count the mean of
the middle two as ``(a + b) / 2``, which is what NumPy's mean of two float64 values computes.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["median"]


def median(values: Iterable[float]) -> float:
    """Median of finite ``values`` (at least one), equal to ``float(np.median(values))``.

    Not for NaN: NumPy's median of an array holding one is NaN, a sort's middle is not.
    """
    ordered = sorted(values)
    half = len(ordered) // 2
    return ordered[half] if len(ordered) % 2 else (ordered[half - 1] + ordered[half]) / 2
