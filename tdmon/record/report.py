"""Post-well report of flight recordings: an HTML page with figures and a CSV of estimates.

Figures follow the thesis's conventions: depth downwards on the vertical axis, loads on the
horizontal one, the broomstick band as one line per friction factor. Figures and tables are in
the display units of :mod:`tdmon.display` (SI: kN, kN m, m, degC; field: klbf, kft lbf, ft,
degF); ``estimates.csv`` stays SI, the unit in its column names. The page is self-contained
(PNG figures embedded as data URIs) and the PNGs are also written beside it.
"""

from __future__ import annotations

import base64
import csv
import html
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final

import numpy as np

from tdmon.display import UnitSystem, unit_system
from tdmon.errors import RecordError
from tdmon.record.reader import read_messages, topic_counts
from tdmon.vocabulary import EstimateKind, RigState

_TOPICS: Final = ("/tdmon/model", "/tdmon/estimate", "/tdmon/state", "/tdmon/alarm",
                  "/tdmon/profile")
_STATE_COLOURS: Final[dict[str, str]] = {
    RigState.IN_SLIPS: "#7f7f7f", RigState.PICK_UP: "#d62728", RigState.SLACK_OFF: "#1f77b4",
    RigState.ROTATING_OFF_BOTTOM: "#2ca02c", RigState.REAMING: "#9467bd",
    RigState.BACK_REAMING: "#8c564b", RigState.DRILLING: "#e377c2",
    RigState.CIRCULATING: "#17becf", RigState.STATIC: "#bcbd22", RigState.UNKNOWN: "#c7c7c7",
}
_CSV_FIELDS: Final = ("time_utc", "t", "kind", "operation", "mu", "mu_std", "bit_depth_m")
_SI: Final = unit_system("si")


@dataclass
class ReportData:
    """The messages a report needs, gathered in one pass over the recordings."""

    models: list[dict[str, Any]] = field(default_factory=list)
    estimates: list[dict[str, Any]] = field(default_factory=list)
    states: list[dict[str, Any]] = field(default_factory=list)
    alarms: list[dict[str, Any]] = field(default_factory=list)
    profiles: list[dict[str, Any]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)


@dataclass
class ReportResult:
    """Files written by :func:`write_report`."""

    html: Path
    csv: Path
    figures: list[Path]


def load(paths: Sequence[str | os.PathLike[str]]) -> ReportData:
    """Read the topics the report uses from finished MCAP files."""
    data = ReportData()
    buckets = {
        "/tdmon/model": data.models, "/tdmon/estimate": data.estimates,
        "/tdmon/state": data.states, "/tdmon/alarm": data.alarms,
        "/tdmon/profile": data.profiles,
    }
    for path in paths:
        for topic, n in topic_counts(path).items():
            data.counts[topic] = data.counts.get(topic, 0) + n
        for topic, _, message in read_messages(path, _TOPICS):
            buckets[topic].append(message)
    return data


def _utc(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%d %H:%M:%S")


def _num(value: Any) -> float:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    return math.nan


def _legend(axes: Any, **options: Any) -> None:
    # an empty recording leaves a panel without labelled lines: no legend then (matplotlib warns)
    if axes.get_legend_handles_labels()[0]:
        axes.legend(**options)


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
    figure.savefig(path)
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


def hookload_figure(data: ReportData, path: Path, units: UnitSystem = _SI) -> Path | None:
    """Measured hook load against bit depth over the broomstick band."""
    models = [m for m in data.models if math.isfinite(_num(m.get("bit_depth_m")))]
    if not models:
        return None
    models.sort(key=lambda m: _num(m["bit_depth_m"]))
    depth = units.depth(np.array([_num(m["bit_depth_m"]) for m in models]))
    figure, axes = _figure()
    band_mu = models[-1].get("band", {}).get("mu", [])
    for i, mu in enumerate(band_mu):
        for column, style in (("pick_up_N", "-"), ("slack_off_N", "--")):
            load = np.array([
                _num(m["band"][column][i]) if i < len(m["band"].get(column, [])) else math.nan
                for m in models
            ])
            label = f"mu = {mu:.2f}" if column == "pick_up_N" else None
            axes.plot(units.force(load), depth, style, color=f"C{i}", lw=0.9, label=label)
    rotating = np.array([_num(m["hookload_N"].get("rotating")) for m in models])
    axes.plot(units.force(rotating), depth, ":", color="k", lw=1.0, label="rotating (model)")
    measured = np.array([_num(m["measured"].get("hookload_N")) for m in models])
    times = np.array([_num(m["t"]) for m in models])
    states = _state_at(data.states, times)
    for state in sorted(set(states)):
        mask = np.array([s == state for s in states])
        axes.scatter(units.force(measured[mask]), depth[mask], s=5, color=_STATE_COLOURS.get(
            state, "k"), label=f"measured, {state}", zorder=3)
    _depth_axis(axes, "Hook load against depth (broomstick: solid pick-up, dashed slack-off)",
                f"Hook load [{units.label('force')}]", f"Bit depth [{units.label('depth')} MD]")
    _legend(axes, fontsize=7, loc="best")
    return _save(figure, path)


def torque_figure(data: ReportData, path: Path, units: UnitSystem = _SI) -> Path | None:
    """Measured surface torque against depth with the modelled rotating torque."""
    models = [m for m in data.models if math.isfinite(_num(m["measured"].get("torque_Nm")))]
    if not models:
        return None
    models.sort(key=lambda m: _num(m["bit_depth_m"]))
    depth = units.depth(np.array([_num(m["bit_depth_m"]) for m in models]))
    figure, axes = _figure()
    axes.plot(units.torque(np.array([_num(m["torque_Nm"].get("rotating")) for m in models])),
              depth, "-", color="k", lw=1.0, label="rotating (model)")
    axes.scatter(units.torque(np.array([_num(m["measured"]["torque_Nm"]) for m in models])),
                 depth, s=5, color="C3", label="measured")
    _depth_axis(axes, "Surface torque against depth", f"Torque [{units.label('torque')}]",
                f"Bit depth [{units.label('depth')} MD]")
    _legend(axes, fontsize=8)
    return _save(figure, path)


def friction_figure(data: ReportData, path: Path, units: UnitSystem = _SI) -> Path | None:
    """Window estimates of mu against bit depth, and the latest local friction profile."""
    windows = [e for e in data.estimates if e.get("kind") == EstimateKind.WINDOW
               and math.isfinite(_num(e.get("bit_depth_m")))]
    profile = next((e for e in reversed(data.estimates) if e.get("kind") == EstimateKind.PROFILE
                    and "md_m" in e and "mu_profile" in e), None)
    if profile is None:
        profile = next(({"md_m": p["md_m"], "mu_profile": p["mu"], "mu_profile_std":
                         p.get("mu_std"), "informed": p.get("informed"),
                         "uninformed_reason": p.get("uninformed_reason")}
                        for p in reversed(data.profiles) if "mu" in p), None)
    if not windows and profile is None:
        return None
    figure, axes = _figure(6.0, 6.0)
    if profile is not None:
        md = units.depth(np.array(profile["md_m"], dtype=float))
        mu = np.array([_num(v) for v in profile["mu_profile"]])
        informed = profile.get("informed")
        if informed is not None and len(informed) == mu.size:
            # an uninformed bin still holds the prior: drawn faint, not as a result
            known = np.asarray(informed, dtype=bool)
            axes.plot(np.where(known, np.nan, mu), md, color="0.6", lw=1.0, ls=":",
                      label="profile, not informed (prior)")
            mu = np.where(known, mu, np.nan)
            from tdmon.calib.profile import describe_information

            figure.text(0.01, 0.005, describe_information(profile["md_m"], informed,
                                                          profile.get("uninformed_reason")),
                        fontsize=6, wrap=True, va="bottom")
        axes.plot(mu, md, color="k", lw=1.2, label="local friction profile")
        if profile.get("mu_profile_std"):
            std = np.array([_num(v) for v in profile["mu_profile_std"]])
            axes.fill_betweenx(md, mu - std, mu + std, color="k", alpha=0.15, label="± 1 std")
    for i, operation in enumerate(sorted({str(e["operation"]) for e in windows})):
        chosen = [e for e in windows if e["operation"] == operation]
        axes.errorbar([_num(e["mu"]) for e in chosen],
                      units.depth(np.array([_num(e["bit_depth_m"]) for e in chosen])),
                      xerr=[_num(e.get("mu_std")) for e in chosen], fmt="o", ms=4,
                      color=f"C{i}", capsize=2, label=f"window, {operation}")
    _depth_axis(axes, "Friction factor against depth", "Friction factor mu [-]",
                f"Depth [{units.label('depth')} MD] (bit depth for windows)")
    _legend(axes, fontsize=8)
    return _save(figure, path)


def mu_t_figure(data: ReportData, path: Path, units: UnitSystem = _SI) -> Path | None:
    """The mu(T) fits: the fitted points and, where the estimate carries it, the curve."""
    fits = [e for e in data.estimates if e.get("kind") == EstimateKind.MU_T]
    if not fits:
        return None
    figure, axes = _figure(6.0, 4.5)
    for i, fit in enumerate(fits[-3:]):
        params = ", ".join(f"{k} = {_num(v):.4g}" for k, v in (fit.get("params") or {}).items())
        label: str | None = f"{fit.get('model', 'mu(T)')} ({_utc(_num(fit['t']))})" + (
            f": {params}" if params else "")
        if fit.get("temperature_C") and fit.get("mu_points"):
            axes.plot(_temperatures(fit["temperature_C"], units), fit["mu_points"], "o",
                      color=f"C{i}", label=label)
            label = None
        if fit.get("fit_temperature_C") and fit.get("fit_mu"):
            axes.plot(_temperatures(fit["fit_temperature_C"], units), fit["fit_mu"], "-",
                      color=f"C{i}", label=label)
        elif fit.get("temperature_C") and (line := _linear(fit)) is not None:
            # the law is in degC (its parameters say so): evaluate there, show in the units
            temperature = np.linspace(min(fit["temperature_C"]), max(fit["temperature_C"]), 50)
            intercept, slope = line
            axes.plot(units.temperature(temperature), intercept + slope * temperature, "-",
                      color=f"C{i}")
    axes.set_xlabel(f"Temperature [{units.label('temperature')}]")
    axes.set_ylabel("Friction factor mu [-]")
    axes.set_title("Temperature dependence of friction, mu(T)")
    axes.grid(True, alpha=0.3)
    _legend(axes, fontsize=7)
    return _save(figure, path)


def _temperatures(values: Sequence[Any], units: UnitSystem) -> np.ndarray:
    return units.temperature(np.array([_num(v) for v in values]))


def _linear(fit: dict[str, Any]) -> tuple[float, float] | None:
    # Only the linear family can be drawn without the model layer; the others need
    # fit_temperature_C/fit_mu in the message (docs/recording.md).
    params = fit.get("params") or {}
    if fit.get("model") == "linear" and "mu0" in params and "slope_per_C" in params:
        return _num(params["mu0"]), _num(params["slope_per_C"])
    return None


def state_figure(data: ReportData, path: Path, units: UnitSystem = _SI) -> Path | None:
    """Rig-state timeline (coloured spans) with the bit depth."""
    if not data.states:
        return None
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
    depth = units.depth(np.array([_num(s.get("bit_depth_m")) for s in states]))
    depth_axes.plot(times / 3600, depth, color="k", lw=1.0)
    depth_axes.invert_yaxis()
    depth_axes.set_ylabel(f"Bit depth [{units.label('depth')}]")
    depth_axes.set_xlabel("Hours since start")
    depth_axes.grid(True, alpha=0.3)
    return _save(figure, path)


def _figure_pair() -> tuple[Any, tuple[Any, Any]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (top, bottom) = plt.subplots(2, 1, figsize=(8, 5.5), dpi=110, sharex=True,
                                         height_ratios=[3, 2])
    return figure, (top, bottom)


# -- page -----------------------------------------------------------------------------------


def _table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _summary_rows(data: ReportData) -> list[tuple[str, str, str, str]]:
    rows = []
    windows = [e for e in data.estimates if e.get("kind") == EstimateKind.WINDOW]
    for operation in sorted({str(e["operation"]) for e in windows}):
        mu = np.array([_num(e["mu"]) for e in windows if e["operation"] == operation])
        rows.append((operation, str(len(mu)), f"{np.nanmean(mu):.3f}", f"{np.nanstd(mu):.3f}"))
    return rows


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


def write_report(
    paths: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    *,
    title: str | None = None,
    units: UnitSystem | None = None,
) -> ReportResult:
    """Write ``report.html``, the PNG figures and ``estimates.csv`` into ``out_dir``.

    ``units``: the display units of figures and tables (default SI: kN, kN m, m, degC).
    """
    units = units if units is not None else _SI
    if not paths:
        raise RecordError("no recording given for the report")
    data = load(paths)
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RecordError(f"cannot create report folder {out}: {exc.strerror or exc}") from exc
    makers = (
        ("hookload_vs_depth.png", "Hook load and the broomstick band", hookload_figure),
        ("torque_vs_depth.png", "Surface torque", torque_figure),
        ("friction_vs_depth.png", "Friction factor against depth", friction_figure),
        ("mu_T.png", "mu(T) fit", mu_t_figure),
        ("rig_state.png", "Rig-state timeline", state_figure),
    )
    figures: list[tuple[str, Path]] = []
    try:
        for name, caption, maker in makers:
            made = maker(data, out / name, units)
            if made is not None:
                figures.append((caption, made))
        csv_path = out / "estimates.csv"
        windows = write_estimates_csv(data.estimates, csv_path)
        page = _page(paths, data, figures, windows, title, units)
        html_path = out / "report.html"
        html_path.write_text(page, encoding="utf-8")
    except OSError as exc:
        raise RecordError(f"cannot write the report in {out}: {exc.strerror or exc}") from exc
    return ReportResult(html=html_path, csv=csv_path, figures=[path for _, path in figures])


def _page(
    paths: Sequence[str | os.PathLike[str]],
    data: ReportData,
    figures: Sequence[tuple[str, Path]],
    windows: int,
    title: str | None,
    units: UnitSystem,
) -> str:
    heading = html.escape(title or Path(paths[0]).name)
    times = [_num(m.get("t")) for m in data.models + data.states]
    times = [t for t in times if math.isfinite(t)]
    span = f"{_utc(min(times))} to {_utc(max(times))} UTC" if times else "no timed data"
    severities: dict[str, int] = {}
    for alarm in data.alarms:
        severities[str(alarm.get("severity"))] = severities.get(str(alarm.get("severity")), 0) + 1
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>tdmon report: {heading}</title>",
        "<style>body{font-family:sans-serif;max-width:1000px;margin:auto;padding:1em}"
        "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #ccc;"
        "padding:2px 8px;text-align:left}img{max-width:100%}</style></head><body>",
        f"<h1>tdmon post-well report: {heading}</h1>",
        f"<p>Recordings: {html.escape(', '.join(str(p) for p in paths))}<br>Data: {span}<br>"
        f"Generated {_utc(datetime.now(UTC).timestamp())} UTC. Window estimates in "
        f"<a href='estimates.csv'>estimates.csv</a> ({windows} rows).</p>",
        "<h2>Messages per topic</h2>",
        _table(("topic", "messages"), sorted(data.counts.items())),
        "<h2>Friction per operation (window estimates)</h2>",
        _table(("operation", "windows", "mean mu", "std mu"), _summary_rows(data)),
        f"<h2>Loads per rig state (units: {units.name})</h2>",
        _table(("rig state", "model frames", f"bit depth [{units.label('depth')}]",
                f"measured hook load [{units.label('force')}]",
                f"hook load residual [{units.label('force')}]",
                f"measured torque [{units.label('torque')}]",
                f"torque residual [{units.label('torque')}]"), _loads_rows(data, units)),
    ]
    for caption, path in figures:
        encoded = base64.b64encode(path.read_bytes()).decode()
        parts.append(f"<h2>{html.escape(caption)}</h2><img alt='{html.escape(caption)}' "
                     f"src='data:image/png;base64,{encoded}'>")
    parts.append("<h2>Alarms</h2>")
    parts.append("<p>" + (", ".join(f"{k}: {v}" for k, v in sorted(severities.items()))
                          or "none") + "</p>")
    parts.append(_table(("time (UTC)", "severity", "kind", "message"), [
        (_utc(_num(a.get("t"))), a.get("severity"), a.get("kind"), a.get("message"))
        for a in data.alarms[:200]
    ]))
    parts.append("</body></html>")
    return "\n".join(parts)
