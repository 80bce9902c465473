"""Post-well report of flight recordings: one HTML page for a drilling engineer, its figures,
a CSV of window estimates and the summary JSON.

The page says which well and run (files, methods, hole sections), which operations were seen,
the friction factor per operation and hole section with its uncertainty in words and numbers,
the alarms in plain words (most important first) and the mu(T) verdict; the numbers come from
:func:`tdmon.record.digest.digest`, which is also written as ``summary.json``. Every figure
has a caption with its units; a figure without data is replaced by a note saying why.

Figures follow the thesis's conventions: depth downwards on the vertical axis, loads on the
horizontal one, the broomstick band as one line per friction factor. Figures and tables are in
the display units of :mod:`tdmon.display` (SI: kN, kN m, m, degC; field: klbf, kft lbf, ft,
degF); ``estimates.csv`` and ``summary.json`` stay SI, the unit in their keys. The page is
self-contained (PNG figures embedded as data URIs) and the PNGs are also written beside it.
"""

from __future__ import annotations

import base64
import csv
import html
import json
import math
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final

import numpy as np

from tdmon.display import UnitSystem, unit_system
from tdmon.errors import RecordError
from tdmon.record.digest import (
    ReportData,
    digest,
    friction_words,
    load,
    summary_path,
)
from tdmon.vocabulary import ROTATING_STATES, EstimateKind, RigState

__all__ = ["ReportData", "ReportResult", "load", "write_estimates_csv", "write_report"]

_STATE_COLOURS: Final[dict[str, str]] = {
    RigState.IN_SLIPS: "#7f7f7f", RigState.PICK_UP: "#d62728", RigState.SLACK_OFF: "#1f77b4",
    RigState.ROTATING_OFF_BOTTOM: "#2ca02c", RigState.REAMING: "#9467bd",
    RigState.BACK_REAMING: "#8c564b", RigState.DRILLING: "#e377c2",
    RigState.CIRCULATING: "#17becf", RigState.STATIC: "#bcbd22", RigState.UNKNOWN: "#c7c7c7",
}
_CSV_FIELDS: Final = ("time_utc", "t", "kind", "operation", "mu", "mu_std", "bit_depth_m")
_SI: Final = unit_system("si")
_METHOD_WORDS: Final = {
    "soft-string": "soft string (3D Johancsik, consistent sign convention)",
    "aadnoy": "Aadnoy's published formulas (the thesis's Tables 19-22, Aadnoy 2010)",
}


@dataclass
class ReportResult:
    """Files written by :func:`write_report`."""

    html: Path
    csv: Path
    figures: list[Path]
    summary: Path


@dataclass(frozen=True)
class Figure:
    """A figure's outcome: the PNG and its caption, or no PNG and the note saying why."""

    title: str
    path: Path | None
    text: str  # the caption, or the note replacing an empty figure


def _utc(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%d %H:%M:%S")


def _num(value: Any) -> float:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    return math.nan


def _legend(axes: Any, **options: Any) -> None:
    """The legend beside the axes, where it covers no data; none for a panel without
    labelled lines (matplotlib warns)."""
    if axes.get_legend_handles_labels()[0]:
        axes.legend(**{"loc": "upper left", "bbox_to_anchor": (1.02, 1.0),
                       "borderaxespad": 0.0, **options})


def _leading_zeros_dropped(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """``rows`` (in time order) from the first with a positive bit depth on: the rows before
    it read 0 m because no bit depth had come in yet, and would stretch a depth range."""
    ordered = sorted(rows, key=lambda r: _num(r.get("t")))
    for index, row in enumerate(ordered):
        if _num(row.get("bit_depth_m")) > 0.0:
            return ordered[index:]
    return ordered


def bit_depth_span(data: ReportData) -> tuple[float, float] | None:
    """The bit depths [m MD] the recording covers (rig states and model frames), without the
    0 m rows before the first bit depth came in; None without any."""
    depths = np.array([_num(r.get("bit_depth_m")) for rows in (data.states, data.models)
                       for r in _leading_zeros_dropped(rows)])
    depths = depths[np.isfinite(depths)]
    return (float(depths.min()), float(depths.max())) if depths.size else None


def write_estimates_csv(estimates: Sequence[dict[str, Any]], path: Path) -> int:
    """One row per window estimate (scalar kind-specific fields become extra columns)."""
    windows = [e for e in estimates if e.get("kind") == EstimateKind.WINDOW]
    extra = sorted({
        key for e in windows for key, value in e.items()
        if key not in _CSV_FIELDS and isinstance(value, int | float | str)
    })
    with open(path, "w", newline="") as out:
        writer = csv.DictWriter(out, fieldnames=[*_CSV_FIELDS, *extra], extrasaction="ignore")
        writer.writeheader()
        for estimate in windows:
            row = dict(estimate)
            row["time_utc"] = _utc(_num(estimate.get("t")))
            writer.writerow(row)
    return len(windows)


# -- figures --------------------------------------------------------------------------------


def _figure(width: float = 7.0, height: float = 6.0) -> tuple[Any, Any]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(width, height), dpi=110)
    return figure, axes


def _save(figure: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    figure.tight_layout()
    figure.savefig(path, bbox_inches="tight")  # the legend beside the axes included
    plt.close(figure)
    return path


def _state_at(states: Sequence[dict[str, Any]], times: np.ndarray) -> list[str]:
    if not states:
        return ["unknown"] * len(times)
    state_times = np.array([_num(s["t"]) for s in states])
    order = np.argsort(state_times, kind="stable")
    index = np.searchsorted(state_times[order], times, side="right") - 1
    names = [str(states[i]["state"]) for i in order]
    return [names[i] if i >= 0 else "unknown" for i in index]


def _depth_axis(axes: Any, title: str, xlabel: str, ylabel: str) -> None:
    axes.invert_yaxis()
    axes.set_ylabel(ylabel)
    axes.set_xlabel(xlabel)
    axes.set_title(title)
    axes.grid(True, alpha=0.3)


def _shoe(data: ReportData) -> float | None:
    """MD of the deepest casing shoe [m] from the ``well`` message's sections (None: unknown)."""
    sections = (data.wells[0].get("sections") or []) if data.wells else []
    cased = [_num(s.get("bottom_m")) for s in sections if s.get("kind") == "cased"]
    cased = [md for md in cased if math.isfinite(md)]
    return max(cased) if cased else None


def hookload_figure(data: ReportData, path: Path, units: UnitSystem = _SI) -> Figure:
    """Measured hook load against bit depth over the broomstick band."""
    title = "Hook load against bit depth"
    models = [m for m in _leading_zeros_dropped(data.models)
              if math.isfinite(_num(m.get("bit_depth_m")))]
    if not models:
        return Figure(title, None, "No hook-load figure: the recording holds no modelled loads "
                      "(no /tdmon/model messages: no well file, or no bit depth received).")
    models.sort(key=lambda m: _num(m["bit_depth_m"]))
    depth = units.depth(np.array([_num(m["bit_depth_m"]) for m in models]))
    figure, axes = _figure()
    band_mu = models[-1].get("band", {}).get("mu", [])
    for i, mu in enumerate(band_mu):
        for column, style in (("pick_up_N", "-"), ("slack_off_N", "--")):
            load_n = np.array([
                _num(m["band"][column][i]) if i < len(m["band"].get(column, [])) else math.nan
                for m in models
            ])
            label = f"mu = {mu:.2f}" if column == "pick_up_N" else None
            axes.plot(units.force(load_n), depth, style, color=f"C{i}", lw=0.9, label=label)
    rotating = np.array([_num(m["hookload_N"].get("rotating")) for m in models])
    axes.plot(units.force(rotating), depth, ":", color="k", lw=1.0, label="rotating (model)")
    measured = np.array([_num(m["measured"].get("hookload_N")) for m in models])
    times = np.array([_num(m["t"]) for m in models])
    states = _state_at(data.states, times)
    for state in sorted(set(states)):
        mask = np.array([s == state for s in states])
        axes.scatter(units.force(measured[mask]), depth[mask], s=5, color=_STATE_COLOURS.get(
            state, "k"), label=f"measured, {state}", zorder=3)
    _depth_axis(axes, "Hook load against bit depth", f"Hook load [{units.label('force')}]",
                f"Bit depth [{units.label('depth')} MD]")
    _legend(axes, fontsize=7)
    caption = (
        f"Measured hook load [{units.label('force')}] against bit depth "
        f"[{units.label('depth')} MD], one dot per model frame coloured by rig state, over the "
        "modelled broomstick band: solid lines pick-up, dashed slack-off, one colour per "
        f"friction factor ({', '.join(f'{mu:.2f}' for mu in band_mu) or 'none'}); dotted: the "
        "rotating (friction-free axial) hook load.")
    return Figure(title, _save(figure, path), caption)


def torque_figure(data: ReportData, path: Path, units: UnitSystem = _SI) -> Figure:
    """Measured surface torque against depth while rotating, with the modelled torque."""
    title = "Surface torque against bit depth"
    models = [m for m in _leading_zeros_dropped(data.models)
              if math.isfinite(_num(m["measured"].get("torque_Nm")))
              and math.isfinite(_num(m.get("bit_depth_m")))]
    states = _state_at(data.states, np.array([_num(m["t"]) for m in models]))
    # non-rotating samples read zero torque: drawn at 0 they would squash the curve, so only
    # rotating samples are drawn: a non-zero torque, in a rotating rig state when states exist
    # (a zero at a state change is the rotary stopping, not the string's torque)
    rotating = [m for m, s in zip(models, states, strict=True)
                if _num(m["measured"]["torque_Nm"]) > 0.0
                and (not data.states or s in ROTATING_STATES)]
    if not rotating:
        return Figure(title, None, "No torque figure: the string did not rotate in this "
                      f"recording ({len(models)} model frames, none in a rotating rig state).")
    models.sort(key=lambda m: _num(m["bit_depth_m"]))
    rotating.sort(key=lambda m: _num(m["bit_depth_m"]))
    depth = units.depth(np.array([_num(m["bit_depth_m"]) for m in models]))
    figure, axes = _figure()
    axes.plot(units.torque(np.array([_num(m["torque_Nm"].get("rotating")) for m in models])),
              depth, "-", color="k", lw=1.0, label="rotating off bottom (model)")
    axes.scatter(units.torque(np.array([_num(m["measured"]["torque_Nm"]) for m in rotating])),
                 units.depth(np.array([_num(m["bit_depth_m"]) for m in rotating])), s=5,
                 color="C3", label="measured while rotating")
    _depth_axis(axes, title, f"Torque [{units.label('torque')}]",
                f"Bit depth [{units.label('depth')} MD]")
    _legend(axes, fontsize=8)
    caption = (
        f"Measured surface torque [{units.label('torque')}] against bit depth "
        f"[{units.label('depth')} MD] of rotating samples only ({len(rotating)} of {len(models)} "
        "model frames: a non-zero torque in a rotating rig state; the others, not rotating, "
        "read zero torque and are left out), with the "
        "modelled off-bottom rotating torque at the monitor's friction factor.")
    return Figure(title, _save(figure, path), caption)


def drilling_figure(data: ReportData, path: Path, units: UnitSystem = _SI) -> Figure:
    """The drilling page (docs/drilling.md): weights on bit, drilling torque against the
    drilling curve, friction from the drilling windows, each against bit depth."""
    from tdmon.record.drilling_page import drilling_series, drilling_windows

    title = "Drilling: weight on bit, torque and friction against bit depth"
    series = drilling_series(data.models)
    if series.t.size == 0:
        return Figure(title, None, "No drilling figure: the recording holds no drilling frame.")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (wob, torque, friction) = plt.subplots(1, 3, figsize=(11, 6), dpi=110, sharey=True)
    depth = units.depth(series.bit_depth)
    estimated, std = series.wob_estimated, np.nan_to_num(series.wob_estimated_std)
    wob.fill_betweenx(depth, units.force(estimated - std), units.force(estimated + std),
                      color="C0", alpha=0.25, lw=0)
    wob.scatter(units.force(estimated), depth, s=4, color="C0",
                label="from the hook load (+/- 1 sd)")
    wob.scatter(units.force(series.wob_surface), depth, s=4, color="k", label="surface")
    if np.isfinite(series.wob_downhole).any():
        wob.scatter(units.force(series.wob_downhole), depth, s=4, color="C3",
                    label="downhole (MWD)")
    _depth_axis(wob, "Weight on bit", f"Weight on bit [{units.label('force')}]",
                f"Bit depth [{units.label('depth')} MD]")
    _legend(wob, fontsize=7)
    torque.scatter(units.torque(series.torque_measured), depth, s=4, color="C3",
                   label="measured")
    torque.plot(units.torque(series.torque_modelled), depth, "-", color="k", lw=1.0,
                label="drilling curve (model)")
    torque.set_title("Drilling torque")
    torque.set_xlabel(f"Surface torque [{units.label('torque')}]")
    torque.grid(True, alpha=0.3)
    _legend(torque, fontsize=7)
    window_depth, mu, mu_std = drilling_windows(data.estimates)
    if mu.size:
        friction.errorbar(mu, units.depth(window_depth), xerr=mu_std, fmt="o", color="C2",
                          ms=4, label="drilling windows")
        _legend(friction, fontsize=7)
    friction.set_title("Friction from drilling")
    friction.set_xlabel("Friction factor [-]")
    friction.grid(True, alpha=0.3)
    residual = series.hookload_residual[np.isfinite(series.hookload_residual)]
    centre = (f"{float(units.force(np.array([np.median(residual)]))[0]):+.1f} "
              f"{units.label('force')}" if residual.size else "not known")
    caption = (
        f"{series.t.size} drilling frames. Left: the weight on bit [{units.label('force')}] at "
        "the surface (the rig's), from the hook load through the measurement model with one "
        "standard deviation (band), and the MWD's where sent. Middle: the surface torque "
        f"[{units.label('torque')}] measured and the drilling curve (the model's torque at the "
        "frame's weight on bit plus the bit torque). Right: friction from each drilling "
        f"window's torque less the bit's ({mu.size} windows, +/- 1 sd). Median hook-load "
        f"residual against the drilling curve: {centre}.")
    return Figure(title, _save(figure, path), caption)


def _latest_profile(data: ReportData) -> dict[str, Any] | None:
    """The last friction profile: a ``profile`` message with ``mu`` (it may carry per-bin
    ``informed``), else the last ``profile`` estimate."""
    message = next((p for p in reversed(data.profiles) if p.get("mu")), None)
    if message is not None:
        return message
    estimate = next((e for e in reversed(data.estimates) if e.get("kind") == EstimateKind.PROFILE
                     and e.get("md_m") and e.get("mu_profile")), None)
    if estimate is None:
        return None
    return {"md_m": estimate["md_m"], "mu": estimate["mu_profile"],
            "mu_std": estimate.get("mu_profile_std"), "informed": estimate.get("informed"),
            "uninformed_reason": estimate.get("uninformed_reason")}


def _informed(profile: dict[str, Any], n: int) -> tuple[np.ndarray, str | None]:
    """Which profile points the data informed (all when the message does not say), and the
    message's reason for the others."""
    flags = profile.get("informed")
    if not isinstance(flags, list) or len(flags) != n:
        return np.ones(n, dtype=bool), None
    from tdmon.calib.profile import describe_information

    return np.array([bool(f) for f in flags]), describe_information(
        profile["md_m"], flags, profile.get("uninformed_reason"))


def _shown_depths(windows: Sequence[dict[str, Any]], md: np.ndarray | None,
                  informed: np.ndarray | None) -> tuple[float, float] | None:
    """The depth range [m MD] a friction figure shows: the windows' bit depths and the
    profile's informed points, with a margin; None when neither exists."""
    depths = [_num(e["bit_depth_m"]) for e in windows]
    if md is not None and informed is not None:
        depths += md[informed].tolist()
    finite = [d for d in depths if math.isfinite(d)]
    if not finite:
        return None
    low, high = min(finite), max(finite)
    margin = max(50.0, 0.1 * (high - low))
    return max(0.0, low - margin), high + margin


def friction_figure(data: ReportData, path: Path, units: UnitSystem = _SI) -> Figure:
    """Window estimates of mu against bit depth and the latest local friction profile, over
    the depths the data cover (not the whole well); the legend lists only what is drawn."""
    title = "Friction factor against depth"
    windows = [e for e in data.estimates if e.get("kind") == EstimateKind.WINDOW
               and math.isfinite(_num(e.get("bit_depth_m")))]
    profile = _latest_profile(data)
    md_m = mu = informed = None
    reason = None
    if profile is not None:
        md_m = np.array(profile["md_m"], dtype=float)
        mu = np.array([_num(v) for v in profile["mu"]])
        informed, reason = _informed(profile, md_m.size)
    span = _shown_depths(windows, md_m, informed)
    if span is None:
        why = ("no window estimate, and no point of the friction profile informed by data "
               f"({reason})" if profile is not None and reason else
               "no window estimate and no friction profile in the recording (back-calculation "
               "off or no steady window)")
        return Figure(title, None, f"No friction figure: {why}.")
    figure, axes = _figure(7.5, 6.0)
    notes = []
    if profile is not None and md_m is not None and mu is not None and informed is not None:
        inside = (md_m >= span[0]) & (md_m <= span[1])
        md = units.depth(md_m)
        calibrated = bool(profile.get("mu_std"))
        shown = np.where(informed & inside, mu, np.nan)
        if np.isfinite(shown).any():
            axes.plot(shown, md, color="k", lw=1.2, label="local friction profile"
                      if calibrated else "well file's friction")
            if calibrated:
                std = np.array([_num(v) for v in profile["mu_std"]])
                axes.fill_betweenx(md, shown - std, shown + std, color="k", alpha=0.15,
                                   label="profile ± 1 sd")
        prior = np.where(~informed & inside, mu, np.nan)
        if np.isfinite(prior).any():
            axes.plot(prior, md, color="0.65", lw=1.0, ls=":",
                      label="not informed by data (prior)")
        if not informed.all():
            notes.append("Profile points the data did not inform are drawn grey (dotted): "
                         + (reason or f"{int((~informed).sum())} of {informed.size}"))
    for i, operation in enumerate(sorted({str(e["operation"]) for e in windows})):
        chosen = [e for e in windows if e["operation"] == operation]
        axes.errorbar([_num(e["mu"]) for e in chosen],
                      units.depth(np.array([_num(e["bit_depth_m"]) for e in chosen])),
                      xerr=[_num(e.get("mu_std")) for e in chosen], fmt="o", ms=4,
                      color=f"C{i}", capsize=2, label=f"window, {operation.replace('_', ' ')}")
    shoe = _shoe(data)
    shoe_shown = shoe is not None and span[0] <= shoe <= span[1]
    if shoe is not None and shoe_shown:
        axes.axhline(float(units.depth(np.array([shoe]))[0]), color="0.4", lw=0.8, ls="--",
                     label="casing shoe")
    low, high = (float(units.depth(np.array([d]))[0]) for d in span)
    axes.set_ylim(low, high)
    _depth_axis(axes, title, "Friction factor mu [-]",
                f"Depth [{units.label('depth')} MD] (bit depth for windows)")
    _legend(axes, fontsize=8)
    caption = (
        f"Friction factor mu [-] against measured depth [{units.label('depth')} MD], "
        f"{low:.0f} to {high:.0f} {units.label('depth')} (the depths the data cover): dots are "
        "window estimates at the bit depth of their window (bars ± 1 sd), by operation; the "
        "line is the latest local friction profile along the string (band ± 1 sd)"
        + ("; dashed: the casing shoe" if shoe_shown else "") + "."
        + "".join(f" {note[0].upper()}{note[1:]}." for note in notes))
    return Figure(title, _save(figure, path), caption)


def mu_t_figure(data: ReportData, path: Path, units: UnitSystem = _SI,
                verdict: dict[str, Any] | None = None) -> Figure:
    """The mu(T) fit, drawn only when it is identifiable; else the verdict as a note."""
    title = "Temperature dependence of friction, mu(T)"
    from tdmon.record.digest import mu_t_verdict

    verdict = verdict or mu_t_verdict(data.estimates, data.wells[0] if data.wells else None)
    fits = [e for e in data.estimates if e.get("kind") == EstimateKind.MU_T]
    if verdict["status"] != "fit" or not fits:
        return Figure(title, None, "No mu(T) figure. " + verdict["words"])
    last = fits[-1]
    low, high = (_num(v) for v in last["temperature_C"])
    middle = _num(last.get("mu_at_temperature_C"))
    mu_middle, slope = _num(last.get("mu")), _num(last.get("slope_per_K"))
    interval = [_num(v) for v in last.get("slope_interval_per_K") or [slope, slope]]
    temperature = np.linspace(low, high, 50)
    figure, axes = _figure(6.0, 4.5)
    shown = units.temperature(temperature)
    axes.plot(shown, mu_middle + slope * (temperature - middle), "-", color="C0",
              label=f"{last.get('model')}")
    lines = np.array([mu_middle + s * (temperature - middle) for s in interval])
    axes.fill_between(shown, lines.min(axis=0), lines.max(axis=0), color="C0", alpha=0.2,
                      label="95 % interval of the slope")
    points = [(e, _num(e.get("mu_at_temperature_C"))) for e in fits]
    axes.errorbar([float(units.temperature(np.array([t]))[0]) for _, t in points],
                  [_num(e.get("mu")) for e, _ in points],
                  yerr=[_num(e.get("mu_std")) for e, _ in points], fmt=".", color="0.4",
                  capsize=2, label="successive updates (mu at the mid temperature)")
    axes.set_xlabel(f"Temperature [{units.label('temperature')}]")
    axes.set_ylabel("Friction factor mu [-]")
    axes.set_title(title)
    axes.grid(True, alpha=0.3)
    _legend(axes, fontsize=7)
    caption = (
        f"Friction factor mu [-] against annulus temperature [{units.label('temperature')}] "
        "over the range the windows saw: the calibrated law near the middle of the range "
        "(shaded: its slope's 95 % interval), grey dots the successive updates. "
        + verdict["words"])
    return Figure(title, _save(figure, path), caption)


def state_figure(data: ReportData, path: Path, units: UnitSystem = _SI) -> Figure:
    """Rig-state timeline (coloured spans) with the bit depth."""
    title = "Rig state and bit depth over time"
    if not data.states:
        return Figure(title, None, "No rig-state figure: the recording holds no rig states.")
    states = sorted(data.states, key=lambda s: _num(s["t"]))
    t0 = _num(states[0]["t"])
    times = np.array([_num(s["t"]) for s in states]) - t0
    end = times[-1] + (times[-1] - times[-2] if len(times) > 1 else 1.0)
    figure, (lanes, depth_axes) = _figure_pair()
    names = list(_STATE_COLOURS)
    for i, state in enumerate(states):
        stop = times[i + 1] if i + 1 < len(times) else end
        row = names.index(state["state"]) if state["state"] in names else len(names) - 1
        lanes.broken_barh([(times[i] / 3600, (stop - times[i]) / 3600)], (row - 0.4, 0.8),
                          color=_STATE_COLOURS.get(state["state"], "k"))
    lanes.set_yticks(range(len(names)), names, fontsize=7)
    lanes.set_title(f"Rig state from {_utc(t0)} UTC")
    lanes.grid(True, axis="x", alpha=0.3)
    # no line before the first bit depth came in (those states read 0 m)
    known = {id(s) for s in _leading_zeros_dropped(states)}
    depth = units.depth(np.array([_num(s.get("bit_depth_m")) if id(s) in known else math.nan
                                  for s in states]))
    depth_axes.plot(times / 3600, depth, color="k", lw=1.0)
    depth_axes.invert_yaxis()
    depth_axes.set_ylabel(f"Bit depth [{units.label('depth')}]")
    depth_axes.set_xlabel("Hours since start")
    depth_axes.grid(True, alpha=0.3)
    caption = (f"Top: the detected rig state against time [h since {_utc(t0)} UTC]; bottom: "
               f"bit depth [{units.label('depth')} MD] on the same time axis.")
    return Figure(title, _save(figure, path), caption)


def _figure_pair() -> tuple[Any, tuple[Any, Any]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (top, bottom) = plt.subplots(2, 1, figsize=(8, 5.5), dpi=110, sharex=True,
                                         height_ratios=[3, 2])
    return figure, (top, bottom)


# -- page -----------------------------------------------------------------------------------


def _table(header: Sequence[str] | None, rows: Sequence[Sequence[Any]],
           empty: str = "none") -> str:
    """An HTML table (``header`` None: a key-value table, no header row); a paragraph saying
    ``empty`` instead of a table without rows."""
    if not rows:
        return f"<p class='note'>{html.escape(empty)}</p>"
    head = "" if header is None else "<thead><tr>" + "".join(
        f"<th>{html.escape(str(h))}</th>" for h in header) + "</tr></thead>"
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows
    )
    return f"<table>{head}<tbody>{body}</tbody></table>"


def _loads_rows(data: ReportData, units: UnitSystem) -> list[tuple[str, ...]]:
    """Per rig state: model frames, bit-depth range, mean measured hook load and torque and the
    mean residuals (measured - model), in the display units."""
    models = [m for m in data.models if math.isfinite(_num(m.get("t")))]
    if not models:
        return []
    states = _state_at(data.states, np.array([_num(m["t"]) for m in models]))

    def column(rows: Sequence[dict[str, Any]], group: str, key: str) -> np.ndarray:
        return np.array([_num((m.get(group) or {}).get(key)) for m in rows])

    def mean(values: np.ndarray, digits: int) -> str:
        finite = values[np.isfinite(values)]
        return f"{finite.mean():.{digits}f}" if finite.size else "-"

    rows: list[tuple[str, ...]] = []
    for state in sorted(set(states)):
        chosen = [m for m, s in zip(models, states, strict=True) if s == state]
        depth = units.depth(np.array([_num(m.get("bit_depth_m")) for m in chosen]))
        finite = depth[np.isfinite(depth)]
        span = f"{finite.min():.1f} - {finite.max():.1f}" if finite.size else "-"
        rows.append((
            state, str(len(chosen)), span,
            mean(units.force(column(chosen, "measured", "hookload_N")), 1),
            mean(units.force(column(chosen, "residual", "hookload_N")), 1),
            mean(units.torque(column(chosen, "measured", "torque_Nm")), 2),
            mean(units.torque(column(chosen, "residual", "torque_Nm")), 2),
        ))
    return rows


_MAKERS: Final[tuple[tuple[str, Callable[..., Figure]], ...]] = (
    ("hookload_vs_depth.png", hookload_figure),
    ("torque_vs_depth.png", torque_figure),
    ("friction_vs_depth.png", friction_figure),
    ("mu_T.png", mu_t_figure),
    ("rig_state.png", state_figure),
    ("drilling.png", drilling_figure),
)


def write_report(
    paths: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    *,
    title: str | None = None,
    units: UnitSystem | None = None,
) -> ReportResult:
    """Write ``report.html``, the PNG figures, ``estimates.csv`` and ``summary.json`` (the
    digest, :func:`tdmon.record.digest.digest`) into ``out_dir`` (created when missing).

    ``units``: the display units of figures and tables (default SI: kN, kN m, m, degC).
    """
    units = units if units is not None else _SI
    if not paths:
        raise RecordError("no recording given for the report")
    data = load(paths)
    facts = digest(data)
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RecordError(f"cannot create report folder {out}: {exc.strerror or exc}") from exc
    figures: list[Figure] = []
    try:
        for name, maker in _MAKERS:
            if maker is mu_t_figure:
                figures.append(mu_t_figure(data, out / name, units, facts["mu_t"]))
            else:
                figures.append(maker(data, out / name, units))
        csv_path = out / "estimates.csv"
        windows = write_estimates_csv(data.estimates, csv_path)
        summary = summary_path(out)
        summary.write_text(json.dumps(facts, indent=2, allow_nan=False) + "\n",
                           encoding="utf-8")
        page = _page(paths, data, facts, figures, windows, title, units)
        html_path = out / "report.html"
        html_path.write_text(page, encoding="utf-8")
    except OSError as exc:
        raise RecordError(f"cannot write the report in {out}: {exc.strerror or exc}") from exc
    return ReportResult(html=html_path, csv=csv_path, summary=summary,
                        figures=[f.path for f in figures if f.path is not None])


def _e(value: Any) -> str:
    return html.escape(str(value))


def _run_section(paths: Sequence[str | os.PathLike[str]], data: ReportData,
                 facts: dict[str, Any], units: UnitSystem) -> list[str]:
    well, span, depth = facts["well"], facts["time_range"], bit_depth_span(data)
    rows = [("Well", well["name"] or "not recorded (no well file in the daemon file)")]
    if well["well_file"]:
        rows.append(("Well file", well["well_file"]))
    rows.append(("Daemon file", well["daemon_file"] or "not recorded"))
    rows.append(("Recording", ", ".join(str(p) for p in paths)))
    if span["first_t"] is not None:
        rows.append(("Rig time", f"{span['first_utc']} to {span['last_utc']} UTC "
                                 f"({span['duration_s'] / 60:.1f} min)"))
    if depth is not None:
        low, high = (float(units.depth(np.array([d]))[0]) for d in depth)
        rows.append(("Bit depth", f"{low:.1f} to {high:.1f} {units.label('depth')} MD"))
    if well["backcalc_method"]:
        rows.append(("Friction back-calculation",
                     _METHOD_WORDS.get(well["backcalc_method"], well["backcalc_method"])
                     + ", friction per window by a one-dimensional search over mu in [0, 1]"))
    if well["method"]:
        rows.append(("Modelled curves (broomstick)",
                     _METHOD_WORDS.get(well["method"], well["method"])))
    rows.append(("mu(T) law", well["mu_t_law"] or "none calibrated"))
    for section in well["sections"]:
        top, bottom = (float(units.depth(np.array([_num(section[k])]))[0])
                       for k in ("top_m", "bottom_m"))
        rows.append((f"Hole section ({section['kind']})",
                     f"{section.get('name') or section['kind']}: {top:.0f} to {bottom:.0f} "
                     f"{units.label('depth')} MD"
                     + (f", friction {section['friction']}" if section.get("friction") else "")))
    return ["<h2>Well and run</h2>", _table(None, rows)]


def _operations_section(facts: dict[str, Any]) -> list[str]:
    shares = facts["operations"]
    if not shares:
        return ["<h2>Operations seen</h2>", "<p>No rig state was recorded.</p>"]
    words = ", ".join(f"{state.replace('_', ' ')} {100 * share:.0f} %"
                      for state, share in shares.items())
    return ["<h2>Operations seen</h2>",
            f"<p>Share of rig time per rig state: {_e(words)}.</p>"]


def _friction_section(facts: dict[str, Any]) -> list[str]:
    rows = facts["friction"]
    parts = ["<h2>Friction factor per operation and hole section</h2>"]
    if not rows:
        return [*parts, "<p>No friction factor was back-calculated in this recording "
                "(calibration off, or no steady pick-up, slack-off or rotating window).</p>"]
    parts.append("<ul>" + "".join(f"<li>{_e(friction_words(r))}</li>" for r in rows) + "</ul>")
    parts.append(f"<p>{_e(facts['joint']['words'])}</p>")

    def text(value: float | None, digits: int) -> str:
        return "-" if value is None else f"{value:.{digits}f}"

    parts.append(_table(
        ("operation", "hole section", "windows", "not resolvable", "median mu",
         "sd between windows", "typical window sd", "range", "bit depth [m MD]"),
        [(r["operation"], r["section_words"], r["windows"], r.get("unresolved", 0),
          text(r["mu_median"], 3),
          text(r["mu_sd"], 3), text(r["mu_window_sd"], 4),
          f"{text(r['mu_min'], 3)} - {text(r['mu_max'], 3)}",
          f"{text(r['bit_depth_min_m'], 0)} - {text(r['bit_depth_max_m'], 0)}") for r in rows]))
    return parts


def _alarm_section(data: ReportData, facts: dict[str, Any]) -> list[str]:
    rows = facts["alarm_summary"]
    parts = ["<h2>Alarms</h2>"]
    if not rows:
        return [*parts, "<p>No alarm was raised.</p>"]
    items = []
    for r in rows:
        times = (f"at {r['first_utc']} UTC" if r["count"] == 1 else
                 f"{r['count']} times, first {r['first_utc']}, last {r['last_utc']} UTC")
        items.append(f"<li><b>{_e(r['severity'])}</b>: {_e(r['meaning'])} ({_e(r['kind'])}), "
                     f"{_e(times)}; last: &ldquo;{_e(r['last_message'])}&rdquo;</li>")
    parts.append("<ul>" + "".join(items) + "</ul>")
    parts.append("<details><summary>Every alarm (up to 200)</summary>" + _table(
        ("time (UTC)", "severity", "kind", "message"),
        [(_utc(_num(a.get("t"))) if math.isfinite(_num(a.get("t"))) else "-", a.get("severity"),
          a.get("kind"), a.get("message")) for a in data.alarms[:200]]) + "</details>")
    return parts


def _page(
    paths: Sequence[str | os.PathLike[str]],
    data: ReportData,
    facts: dict[str, Any],
    figures: Sequence[Figure],
    windows: int,
    title: str | None,
    units: UnitSystem,
) -> str:
    heading = _e(title or facts["well"]["name"] or Path(paths[0]).name)
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>tdmon report: {heading}</title>",
        "<style>body{font-family:sans-serif;max-width:1000px;margin:auto;padding:1em}"
        "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #ccc;"
        "padding:2px 8px;text-align:left}img{max-width:100%}figcaption{font-size:90%;"
        "color:#333;margin-bottom:1.5em}.note{color:#555;font-style:italic}"
        ".headline{font-size:110%;background:#f4f6fa;border-left:4px solid #369;"
        "padding:0.5em 1em}</style></head><body>",
        f"<h1>tdmon post-well report: {heading}</h1>",
        *_headline_section(facts),
        *_run_section(paths, data, facts, units),
        *_operations_section(facts),
        *_friction_section(facts),
        "<h2>mu(T) verdict</h2>", f"<p>{_e(facts['mu_t']['words'])}</p>",
        *_alarm_section(data, facts),
        *_figures_section(figures, units),
        *_loads_section(data, units),
        *_contents_section(data, windows),
        "</body></html>",
    ]
    return "\n".join(parts)


def _figures_section(figures: Sequence[Figure], units: UnitSystem) -> list[str]:
    """The drawn figures, numbered in order; a figure without data is a note saying why,
    unnumbered, so that the numbers do not skip."""
    parts = [f"<h2>Figures (units: {units.name})</h2>"]
    number = 0
    for figure in figures:
        if figure.path is None:
            parts.append(f"<h3>{_e(figure.title)}</h3><p class='note'>{_e(figure.text)}</p>")
            continue
        number += 1
        encoded = base64.b64encode(figure.path.read_bytes()).decode()
        parts.append(f"<figure><h3>{_e(figure.title)}</h3><img alt='{_e(figure.title)}' "
                     f"src='data:image/png;base64,{encoded}'><figcaption>Figure {number}. "
                     f"{_e(figure.text)}</figcaption></figure>")
    return parts


def _loads_section(data: ReportData, units: UnitSystem) -> list[str]:
    return [
        f"<h2>Loads per rig state (units: {units.name})</h2>",
        _table(("rig state", "model frames", f"bit depth [{units.label('depth')}]",
                f"measured hook load [{units.label('force')}]",
                f"hook load residual [{units.label('force')}]",
                f"measured torque [{units.label('torque')}]",
                f"torque residual [{units.label('torque')}]"), _loads_rows(data, units),
               empty="No model frames in the recording (no well file, or no bit depth "
                     "received): no loads to compare."),
    ]


def _contents_section(data: ReportData, windows: int) -> list[str]:
    return [
        "<h2>Recording contents</h2>",
        f"<p>Window estimates in <a href='estimates.csv'>estimates.csv</a> ({windows} rows); "
        "these numbers as JSON in <a href='summary.json'>summary.json</a>. Generated "
        f"{_utc(datetime.now(UTC).timestamp())} UTC.</p>",
        _table(("topic", "messages"), sorted(data.counts.items()),
               empty="The recording holds no messages."),
    ]


_PLANNED: Final = re.compile(r"^mu = ([0-9]*\.?[0-9]+)$")


def _planned_number(section: dict[str, Any]) -> float | None:
    """A hole section's planned friction factor when the well file gives one number."""
    match = _PLANNED.match(str(section.get("friction") or ""))
    return float(match.group(1)) if match else None


def _passed(sections: Sequence[dict[str, Any]], kind: str,
            deepest_bit_m: float | None) -> list[dict[str, Any]]:
    """The well file's sections of ``kind`` (``all``: every kind) the string lay in: those
    whose top is above the deepest bit depth of the windows."""
    return [s for s in sections
            if (kind == "all" or s.get("kind") == kind)
            and (deepest_bit_m is None or _num(s.get("top_m")) < deepest_bit_m)]


def _against_plan(mu: float, planned: Sequence[dict[str, Any]]) -> str:
    """``against the planned 0.25 (56 % below)``, or the plan's words when it is not one
    number, or that the well file plans none."""
    texts = sorted({str(s["friction"]) for s in planned if s.get("friction")})
    if not texts:
        return "the well file plans no friction there"
    numbers = {_planned_number(s) for s in planned if s.get("friction")}
    if len(numbers) == 1 and None not in numbers:
        plan = next(iter(numbers))
        assert plan is not None
        if plan <= 0.0:
            return f"against the planned {plan:g}"
        change = 100.0 * (mu - plan) / plan
        side = "above" if change > 0 else "below"
        return (f"against the planned {plan:g} ({abs(change):.0f} % {side})"
                if round(abs(change)) else f"as planned ({plan:g})")
    return "against the planned " + "; ".join(
        f"{s.get('name') or s['kind']}: {s['friction']}" for s in planned if s.get("friction"))


def headline(facts: dict[str, Any]) -> list[str]:
    """Sentences of what was found against what was planned, per operation and hole section:
    each friction row's median and windows against the planned friction of the sections the
    string lay in, the sections no window reached, the weight caveat and the alarms."""
    sections = facts["well"]["sections"]
    rows = [r for r in facts["friction"] if r["windows"] > 0]
    sentences = []
    for row in rows:
        operation = row["operation"].replace("_", "-")
        deepest = row["bit_depth_max_m"]
        planned = _passed(sections, row["section"], deepest)
        where = ("the whole string" if row["section"] == "all" else row["section_words"])
        bit_in = [s for s in planned if deepest is not None
                  and _num(s.get("top_m")) <= deepest < _num(s.get("bottom_m"))]
        if bit_in:
            where += f" (bit in the {bit_in[0].get('name') or bit_in[0]['kind']})"
        low, high = row["bit_depth_min_m"], row["bit_depth_max_m"]
        depths = ("" if low is None else f", bit at {low:.0f} m MD" if round(low) == round(high)
                  else f", bit at {low:.0f}-{high:.0f} m MD")
        sentences.append(
            f"{operation.capitalize()} friction {row['mu_median']:.3f} in {where}, "
            f"{row['windows']} window{'s' if row['windows'] != 1 else ''}{depths}, "
            f"{_against_plan(row['mu_median'], planned)}.")
    if not rows:
        sentences.append("No friction factor was back-calculated: the planned friction is "
                         "not checked by this recording.")
    deepest_bit = max((r["bit_depth_max_m"] for r in rows
                       if r["bit_depth_max_m"] is not None), default=None)
    unreached = [s for s in sections if rows and deepest_bit is not None
                 and _num(s.get("top_m")) >= deepest_bit]
    if unreached:
        names = ", ".join(f"{s.get('name') or s['kind']}"
                          + (f" (planned {s['friction']})" if s.get("friction") else "")
                          for s in unreached)
        sentences.append(f"No window reached {names}: its friction is not measured.")
    if rows and facts["joint"]["status"] == "not_identifiable":
        sentences.append("These friction factors assume the modelled string weight: weight "
                         "and friction could not be separated in this recording.")
    alarms = facts["alarm_summary"]
    critical = sum(a["count"] for a in alarms if a["severity"] == "critical")
    total = sum(a["count"] for a in alarms)
    sentences.append("No alarm." if not total else f"{total} alarm{'s' if total != 1 else ''}"
                     + (f", {critical} critical" if critical else "") + ".")
    return sentences


def _headline_section(facts: dict[str, Any]) -> list[str]:
    return ["<p class='headline' id='headline'>" + " ".join(_e(s) for s in headline(facts))
            + "</p>"]
