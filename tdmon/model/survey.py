"""Wellbore survey: positions from measured depth, inclination and azimuth by minimum curvature.

Between two survey stations the minimum-curvature method assumes the well path is a circular arc
tangent to both station directions. Positions, interpolated stations and the dogleg of every
interval all follow from that one assumption, so interpolated points lie exactly on the arcs.

Axes: north, east and true vertical depth (TVD, positive downwards); the unit tangent of a
station with inclination ``I`` and azimuth ``A`` is ``(sin I cos A, sin I sin A, cos I)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError

__all__ = [
    "Survey",
    "dogleg_angle",
    "interpolate_survey",
    "minimum_curvature",
    "ratio_factor",
    "tangent_vectors",
    "tvd_and_inclination",
]

FloatArray = NDArray[np.float64]

# Below this dogleg [rad] an interval is treated as straight: the arc formulas divide by
# sin(dogleg) and the series expansions are exact to machine precision there.
_STRAIGHT_DOGLEG = 1e-7


@dataclass(frozen=True)
class Survey:
    """Survey stations with their minimum-curvature positions.

    Attributes
    ----------
    md : measured depth [m], strictly increasing
    inclination : inclination from vertical [rad], 0..pi
    azimuth : azimuth from north, clockwise [rad], 0..2 pi
    tvd : true vertical depth [m], positive down
    north, east : horizontal displacement [m]
    dogleg : dogleg angle of the interval ending at each station [rad]; 0 at the first station
    dls : dogleg severity of the interval ending at each station [rad/m]; 0 at the first station
    """

    md: FloatArray
    inclination: FloatArray
    azimuth: FloatArray
    tvd: FloatArray
    north: FloatArray
    east: FloatArray
    dogleg: FloatArray
    dls: FloatArray

    def __len__(self) -> int:
        return int(self.md.size)

    @cached_property
    def tangents(self) -> FloatArray:
        """`tangent_vectors` of the stations, shape (n, 3), worked out once (a survey's arrays
        are never changed): every interpolation needs them, the friction calibration's load
        check one per window (~10 us of NumPy calls each time)."""
        return tangent_vectors(self.inclination, self.azimuth)


def tangent_vectors(inclination: ArrayLike, azimuth: ArrayLike) -> FloatArray:
    """Unit tangents (north, east, down) of the well path, shape (n, 3).

    Parameters
    ----------
    inclination, azimuth : [rad]
    """
    inc = np.asarray(inclination, dtype=np.float64)
    azi = np.asarray(azimuth, dtype=np.float64)
    sin_inc = np.sin(inc)
    return np.stack([sin_inc * np.cos(azi), sin_inc * np.sin(azi), np.cos(inc)], axis=-1)


def dogleg_angle(
    inclination1: ArrayLike, azimuth1: ArrayLike, inclination2: ArrayLike, azimuth2: ArrayLike
) -> FloatArray:
    """Dogleg angle between two directions [rad].

    Parameters
    ----------
    inclination1, azimuth1, inclination2, azimuth2 : [rad]

    Notes
    -----
    ``beta = 2 asin(sqrt(sin^2(dI/2) + sin I1 sin I2 sin^2(dA/2)))``: the haversine form, which
    stays accurate for small angles where the arccos of a dot product loses half the digits.
    The azimuth difference needs no wrapping because only ``sin^2(dA/2)`` enters.
    """
    i1 = np.asarray(inclination1, dtype=np.float64)
    i2 = np.asarray(inclination2, dtype=np.float64)
    d_azi = np.asarray(azimuth2, dtype=np.float64) - np.asarray(azimuth1, dtype=np.float64)
    haversine = np.sin((i2 - i1) / 2) ** 2 + np.sin(i1) * np.sin(i2) * np.sin(d_azi / 2) ** 2
    return np.asarray(2.0 * np.arcsin(np.sqrt(np.clip(haversine, 0.0, 1.0))), dtype=np.float64)


def ratio_factor(dogleg: ArrayLike) -> FloatArray:
    """Minimum-curvature ratio factor ``RF = (2 / beta) tan(beta / 2)`` (1 for a straight interval).

    Parameters
    ----------
    dogleg : dogleg angle beta [rad], below pi
    """
    beta = np.asarray(dogleg, dtype=np.float64)
    safe = np.where(beta < 1e-4, 1.0, beta)
    exact = 2.0 / safe * np.tan(safe / 2.0)
    series = 1.0 + beta**2 / 12.0 + beta**4 / 120.0  # Taylor expansion of the exact form
    return np.asarray(np.where(beta < 1e-4, series, exact), dtype=np.float64)


def _validate(md: FloatArray, inclination_deg: FloatArray, azimuth_deg: FloatArray) -> None:
    if md.ndim != 1 or inclination_deg.shape != md.shape or azimuth_deg.shape != md.shape:
        raise ModelError(
            "survey md, inclination and azimuth must be 1-D arrays of the same length "
            f"(got shapes {md.shape}, {inclination_deg.shape}, {azimuth_deg.shape})"
        )
    if md.size < 2:
        raise ModelError(f"a survey needs at least 2 stations, got {md.size}")
    for name, values in (("md", md), ("inclination", inclination_deg), ("azimuth", azimuth_deg)):
        bad = ~np.isfinite(values)
        if bad.any():
            index = int(np.flatnonzero(bad)[0])
            raise ModelError(f"survey {name} is not finite at station {index}: {values[index]}")
    steps = np.diff(md)
    if (steps <= 0).any():
        index = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise ModelError(
            f"survey md must increase strictly: station {index} at {md[index]} m follows "
            f"{md[index - 1]} m"
        )
    outside = (inclination_deg < 0.0) | (inclination_deg > 180.0)
    if outside.any():
        index = int(np.flatnonzero(outside)[0])
        raise ModelError(
            f"survey inclination must lie in 0-180 deg: station {index} has "
            f"{inclination_deg[index]} deg"
        )


def minimum_curvature(
    md: ArrayLike,
    inclination_deg: ArrayLike,
    azimuth_deg: ArrayLike,
    *,
    tvd0: float = 0.0,
    north0: float = 0.0,
    east0: float = 0.0,
) -> Survey:
    """Positions of survey stations by the minimum-curvature method.

    Parameters
    ----------
    md : measured depth of the stations [m], strictly increasing
    inclination_deg : inclination [deg], 0..180
    azimuth_deg : azimuth from north [deg]; any value, wrapped into 0..360
    tvd0, north0, east0 : position of the first station [m]

    Returns
    -------
    Survey

    Raises
    ------
    ModelError
        Fewer than 2 stations, non-finite values, MD not strictly increasing, inclination
        outside 0-180 deg.

    Notes
    -----
    For the interval between stations 1 and 2, with dogleg ``beta`` and ratio factor
    ``RF = (2/beta) tan(beta/2)``::

        dN   = dMD/2 (sin I1 cos A1 + sin I2 cos A2) RF
        dE   = dMD/2 (sin I1 sin A1 + sin I2 sin A2) RF
        dTVD = dMD/2 (cos I1 + cos I2) RF

    Azimuths enter only through sines and cosines, so an interval crossing north
    (350 -> 10 deg) turns by 20 deg, not 340.

    References
    ----------
    .. [1] Sawaryn, S. J. and Thorogood, J. L. (2005). A compendium of directional calculations
       based on the minimum curvature method. SPE Drilling & Completion 20(1), 24-36.
    """
    md_arr = np.array(md, dtype=np.float64, ndmin=1)
    inc_deg = np.array(inclination_deg, dtype=np.float64, ndmin=1)
    azi_deg = np.array(azimuth_deg, dtype=np.float64, ndmin=1)
    _validate(md_arr, inc_deg, azi_deg)

    inclination = np.radians(inc_deg)
    azimuth = np.radians(np.mod(azi_deg, 360.0))
    tangents = tangent_vectors(inclination, azimuth)

    interval_dogleg = dogleg_angle(inclination[:-1], azimuth[:-1], inclination[1:], azimuth[1:])
    d_md = np.diff(md_arr)
    steps = (0.5 * d_md * ratio_factor(interval_dogleg))[:, None] * (tangents[:-1] + tangents[1:])
    start = np.array([north0, east0, tvd0], dtype=np.float64)
    positions = np.vstack([start, start + np.cumsum(steps, axis=0)])

    dogleg = np.concatenate([[0.0], interval_dogleg])
    dls = np.concatenate([[0.0], interval_dogleg / d_md])
    return Survey(
        md=md_arr,
        inclination=inclination,
        azimuth=azimuth,
        tvd=positions[:, 2].copy(),
        north=positions[:, 0].copy(),
        east=positions[:, 1].copy(),
        dogleg=dogleg,
        dls=dls,
    )


def _slerp_tangents(
    t1: FloatArray, t2: FloatArray, beta: FloatArray, fraction: FloatArray
) -> FloatArray:
    """Unit tangent a fraction of the way along the arc from ``t1`` to ``t2`` (dogleg ``beta``)."""
    curved = beta > _STRAIGHT_DOGLEG
    safe_beta = np.where(curved, beta, 1.0)
    sin_beta = np.sin(safe_beta)
    w1 = np.where(curved, np.sin((1.0 - fraction) * safe_beta) / sin_beta, 1.0 - fraction)
    w2 = np.where(curved, np.sin(fraction * safe_beta) / sin_beta, fraction)
    t = w1[:, None] * t1 + w2[:, None] * t2
    return np.asarray(t / np.linalg.norm(t, axis=1)[:, None], dtype=np.float64)


class _ArcPoints(NamedTuple):
    """Points on the survey's arcs (`interpolate_survey`): their MD, the interval each lies in,
    the fraction of it, the unit tangent there and at the interval's top, and the length the
    minimum-curvature step from the interval's top takes along ``start_tangent + tangent``."""

    md: FloatArray
    interval: NDArray[np.intp]
    fraction: FloatArray
    tangent: FloatArray
    start_tangent: FloatArray
    step_length: FloatArray


def _on_arcs(survey: Survey, md: ArrayLike) -> _ArcPoints:
    """The part of `interpolate_survey` every caller needs (checks included)."""
    target = np.array(md, dtype=np.float64, ndmin=1)
    if target.ndim != 1 or target.size == 0:
        raise ModelError("interpolation depths must be a non-empty 1-D array")
    if not np.isfinite(target).all():
        raise ModelError("interpolation depths must be finite")
    tolerance = 1e-9 * max(1.0, abs(survey.md[-1]))
    if target[0] < survey.md[0] - tolerance or target[-1] > survey.md[-1] + tolerance:
        raise ModelError(
            f"interpolation depths {target[0]:.2f}..{target[-1]:.2f} m lie outside the survey "
            f"{survey.md[0]:.2f}..{survey.md[-1]:.2f} m"
        )
    # np.diff's subtraction and np.clip's method without their wrappers (~4 us of the ~95 of
    # the loads' interpolation at 340 nodes)
    if target.size > 1 and (target[1:] - target[:-1] <= 0).any():
        raise ModelError("interpolation depths must increase strictly")

    tangents = survey.tangents
    interval = (np.searchsorted(survey.md, target, side="right") - 1).clip(0, survey.md.size - 2)
    md1 = survey.md[interval]
    d_md = survey.md[interval + 1] - md1
    fraction = ((target - md1) / d_md).clip(0.0, 1.0)
    beta = survey.dogleg[interval + 1]
    t1 = tangents[interval]
    t_new = _slerp_tangents(t1, tangents[interval + 1], beta, fraction)

    partial_length = fraction * d_md
    step_length = 0.5 * partial_length * ratio_factor(fraction * beta)
    return _ArcPoints(target, interval, fraction, t_new, t1, step_length)


def interpolate_survey(survey: Survey, md: ArrayLike) -> Survey:
    """Survey at any measured depths, interpolated along the minimum-curvature arcs.

    Parameters
    ----------
    survey : the stations to interpolate between
    md : measured depths [m] within ``survey.md[0]..survey.md[-1]``, strictly increasing

    Returns
    -------
    Survey
        Directions and positions on the arcs; ``dogleg`` and ``dls`` are those of the intervals
        of the new grid (0 at its first point).

    Raises
    ------
    ModelError
        A depth lies outside the survey or the depths do not increase strictly.

    Notes
    -----
    On the arc from station 1 to 2 (dogleg ``beta``) a point at MD fraction ``f`` has the tangent
    ``t = (sin((1-f) beta) t1 + sin(f beta) t2) / sin(beta)``; its position follows from the
    minimum-curvature step from station 1 over ``f dMD`` with dogleg ``f beta``, which lies on
    the same circle. The path is the one `minimum_curvature` assumes, so interpolating at the
    stations returns them unchanged.
    """
    arc = _on_arcs(survey, md)
    target, interval, fraction, t_new = arc.md, arc.interval, arc.fraction, arc.tangent
    step = arc.step_length[:, None] * (arc.start_tangent + t_new)
    start = np.stack([survey.north[interval], survey.east[interval], survey.tvd[interval]], axis=1)
    position = start + step

    horizontal = np.hypot(t_new[:, 0], t_new[:, 1])
    inclination = np.arctan2(horizontal, t_new[:, 2])  # accurate near vertical, unlike arccos
    # In a vertical stretch the azimuth is undefined: keep the interval's own station azimuth.
    azimuth = np.where(
        horizontal > 1e-12,
        np.mod(np.arctan2(t_new[:, 1], t_new[:, 0]), 2.0 * np.pi),
        np.where(fraction < 0.5, survey.azimuth[interval], survey.azimuth[interval + 1]),
    )
    new_dogleg = np.concatenate(
        [[0.0], dogleg_angle(inclination[:-1], azimuth[:-1], inclination[1:], azimuth[1:])]
    )
    new_dls = np.concatenate([[0.0], new_dogleg[1:] / np.diff(target)]) if target.size > 1 else (
        np.zeros(1)
    )
    return Survey(
        md=target,
        inclination=inclination,
        azimuth=azimuth,
        tvd=position[:, 2].copy(),
        north=position[:, 0].copy(),
        east=position[:, 1].copy(),
        dogleg=new_dogleg,
        dls=new_dls,
    )


def tvd_and_inclination(survey: Survey, md: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """TVD [m] and inclination [rad] at measured depths ``md`` [m]: `interpolate_survey`'s, to
    the last bit, without the azimuths, doglegs and horizontal positions (the loads along the
    string need only these: 100 instead of 145 us at 420 nodes).

    Raises
    ------
    ModelError
        As `interpolate_survey`.
    """
    arc = _on_arcs(survey, md)
    t_new = arc.tangent
    # the vertical column of interpolate_survey's ``start + step``, element by element
    tvd = survey.tvd[arc.interval] + arc.step_length * (arc.start_tangent[:, 2] + t_new[:, 2])
    horizontal = np.hypot(t_new[:, 0], t_new[:, 1])
    return tvd, np.arctan2(horizontal, t_new[:, 2])
