"""The fleet summary of a batch: what each replay found, as tables and one HTML page.

A :class:`FleetCollector` rides along each replay as an extra sink (no second reading of the
recording) and keeps the window estimates, the last friction profile, the alarms, the rig-state
time and the well's name. :func:`summary_tables` turns the outcomes into DataFrames:

``recordings``  one row per recording: well, status, the reason of a failure, counts, wall time
``windows``     every window estimate (well, recording, t, operation, section, mu, mu_std, ...)
``friction``    per operation and window section (cased/open/all), of the windows not flagged
                ``low_confidence``: n windows, mean mu, the
                spread (sd) and the standard error of the mean (sd / sqrt(n)), the median of
                the estimator's own mu_std; per recording (``level = "recording"``) and pooled
                over every recording of a well (``level = "well"``)
``sections``    per hole section of the well file: the mean of the last friction profile over
                the section's bins the windows informed and the mean of their standard
                deviations (the bins of one profile are correlated, so this is the cautious
                figure, not std / sqrt(bins)); ``informed`` counts those bins. A section no
                window informed keeps its row with ``mu`` NaN and ``reason`` saying why: its
                bins hold the well file's prior, not a result. Pooled per well by
                inverse-variance weighting over the recordings that informed the section
``states``      rig-state time [s] and share per recording and per well
``alarms``      alarm count per kind and severity, per recording and per well

pandas is imported by the functions that build frames, not with the module (the collector runs
in every replay of a batch and needs none).
"""

from __future__ import annotations

import html
import math
import statistics
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tdmon.record.sink import MessageSink
from tdmon.replay.driver import SummarySink
from tdmon.vocabulary import EstimateKind

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["TABLES", "FleetCollector", "HoleSectionSpan", "RecordingOutcome", "section_rows",
           "summary_tables", "write_html", "write_tables"]

#: The summary's tables, in the order written.
TABLES = ("recordings", "windows", "friction", "sections", "states", "alarms")


@dataclass(frozen=True)
class HoleSectionSpan:
    """A hole section of the well file: ``name`` (or ``"<kind> <i>"``), kind, top and bottom
    [m MD]."""

    name: str
    kind: str
    top: float
    bottom: float


@dataclass(frozen=True)
class RecordingOutcome:
    """One recording of a batch: what its replay found, or why it failed (``error``).

    Plain data (lists and dicts) so that it travels back from a worker process.
    """

    recording: str
    out: str | None
    error: str | None = None
    name: str = ""
    """The recording's name in the summary: its output file's, distinct within a batch."""
    well: str = ""
    messages_in: int = 0
    samples: int = 0
    rejected: int = 0
    wall_s: float = 0.0
    worker: str = ""
    blas_threads: int | None = None
    windows: list[dict[str, Any]] = field(default_factory=list)
    sections: list[dict[str, Any]] = field(default_factory=list)
    state_seconds: dict[str, float] = field(default_factory=dict)
    alarms: dict[tuple[str, str], int] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def label(self) -> str:
        return self.name or Path(self.recording).stem


class FleetCollector(MessageSink):
    """A sink keeping what the fleet summary needs from one replay."""

    topics = frozenset({"/tdmon/state", "/tdmon/estimate", "/tdmon/alarm", "/tdmon/well"})

    def __init__(self) -> None:
        self.states = SummarySink()
        self.windows: list[dict[str, Any]] = []
        self.profile: dict[str, Any] | None = None
        self.alarms: Counter[tuple[str, str]] = Counter()
        self.well = ""

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        if topic == "/tdmon/state":
            self.states.write(topic, log_time_ns, message)
        elif topic == "/tdmon/estimate":
            kind = message.get("kind")
            if kind == EstimateKind.WINDOW:
                self.windows.append({key: message.get(key) for key in (
                    "t", "operation", "section", "mu", "mu_std", "bit_depth_m",
                    "low_confidence")})
            elif kind == EstimateKind.PROFILE:
                self.profile = message
        elif topic == "/tdmon/alarm":
            self.alarms[(str(message.get("kind")), str(message.get("severity")))] += 1
        elif topic == "/tdmon/well":
            self.well = str(message.get("name") or "")

    def close(self) -> None:
        """Nothing to release."""


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and math.isfinite(value)


def section_rows(profile: dict[str, Any] | None,
                 sections: Sequence[HoleSectionSpan]) -> list[dict[str, Any]]:
    """Friction per hole section from a profile estimate (``md_m``, ``mu_profile``,
    ``mu_profile_std``, ``informed``, ``uninformed_reason``).

    Per section: ``bins`` (finite bins whose centre lies in it), ``informed`` (those the
    windows informed), the mean friction and the mean standard deviation over the informed
    bins, and for a section with none the commonest ``reason`` its bins give; its ``mu`` and
    ``mu_std`` are then NaN: the bins hold the prior, which is no result. A profile without
    ``informed`` (older recordings) counts every bin as informed. A section without finite
    bins is left out.
    """
    if not profile:
        return []
    md = profile.get("md_m") or []
    mu = profile.get("mu_profile") or []
    std = profile.get("mu_profile_std") or []
    flags = profile.get("informed")
    if not isinstance(flags, list) or len(flags) != len(md):
        flags = [True] * len(md)
    reasons = profile.get("uninformed_reason")
    if not isinstance(reasons, list) or len(reasons) != len(md):
        reasons = [None] * len(md)
    rows = []
    for section in sections:
        inside = [(m, s, bool(known), why)
                  for depth, m, s, known, why in zip(md, mu, std, flags, reasons, strict=False)
                  if section.top <= depth < section.bottom and _finite(m) and _finite(s)]
        if not inside:
            continue
        informed = [(m, s) for m, s, known, _ in inside if known]
        why = Counter(str(w or "not informed") for _, _, known, w in inside if not known)
        rows.append({"section": section.name, "kind": section.kind, "top_m": section.top,
                     "bottom_m": section.bottom, "bins": len(inside),
                     "informed": len(informed),
                     "mu": statistics.fmean(m for m, _ in informed) if informed else math.nan,
                     "mu_std": (statistics.fmean(s for _, s in informed) if informed
                                else math.nan),
                     "reason": "" if informed else why.most_common(1)[0][0]})
    return rows


def _friction(windows: pd.DataFrame, keys: list[str]) -> pd.DataFrame:
    import pandas as pd

    columns = ["n", "mu_mean", "mu_sd", "mu_se", "mu_std_median", "mu_min", "mu_max"]
    confident = windows[~windows["low_confidence"].fillna(False).astype(bool)]
    if confident.empty:
        return pd.DataFrame(columns=[*keys, "operation", "section", *columns])
    grouped = confident.groupby([*keys, "operation", "section"], sort=True)
    table = grouped["mu"].agg(n="count", mu_mean="mean", mu_sd="std", mu_min="min",
                              mu_max="max")
    table["mu_se"] = table["mu_sd"] / table["n"] ** 0.5
    table["mu_std_median"] = grouped["mu_std"].median()
    return table[columns].reset_index()


def _pooled_sections(sections: pd.DataFrame) -> pd.DataFrame:
    """Inverse-variance mean of each hole section's friction over the well's recordings that
    informed it; a section none informed keeps NaN and its recordings' reasons."""
    import numpy as np

    known = sections["informed"] > 0
    weight = (1.0 / sections["mu_std"].clip(lower=1e-9) ** 2).where(known, 0.0)
    frame = sections.assign(_w=weight, _wm=(weight * sections["mu"]).where(known, 0.0),
                            _why=sections["reason"].where(~known, ""))
    grouped = frame.groupby(["well", "section", "kind", "top_m", "bottom_m"], sort=False)
    pooled = grouped.agg(recordings=("recording", "nunique"), bins=("bins", "sum"),
                         informed=("informed", "sum"), _w=("_w", "sum"), _wm=("_wm", "sum"),
                         reason=("_why", lambda why: "; ".join(sorted({w for w in why if w}))))
    informed = pooled["_w"] > 0
    pooled["mu"] = (pooled["_wm"] / pooled["_w"].where(informed)).astype(float)
    pooled["mu_std"] = (1.0 / np.sqrt(pooled["_w"].where(informed))).astype(float)
    pooled["reason"] = pooled["reason"].where(~informed, "")
    return pooled.drop(columns=["_w", "_wm"]).reset_index()


def summary_tables(outcomes: Sequence[RecordingOutcome]) -> dict[str, pd.DataFrame]:
    """The summary's tables (see the module's docstring) from the batch's outcomes."""
    import pandas as pd

    recordings = pd.DataFrame([{
        "recording": o.label, "path": o.recording, "well": o.well,
        "status": "ok" if o.ok else "failed",
        "error": o.error or "", "messages_in": o.messages_in, "samples": o.samples,
        "rejected": o.rejected, "windows": len(o.windows), "alarms": sum(o.alarms.values()),
        "wall_s": round(o.wall_s, 3), "worker": o.worker, "blas_threads": o.blas_threads,
        "out": o.out or "",
    } for o in outcomes])
    done = [o for o in outcomes if o.ok]
    windows = pd.DataFrame([{"well": o.well, "recording": o.label, **row}
                            for o in done for row in o.windows],
                           columns=["well", "recording", "t", "operation", "section", "mu",
                                    "mu_std", "bit_depth_m", "low_confidence"])
    friction = pd.concat([
        _friction(windows, ["well", "recording"]).assign(level="recording"),
        _friction(windows, ["well"]).assign(level="well", recording=""),
    ], ignore_index=True)
    sections = pd.DataFrame([{"well": o.well, "recording": o.label, **row}
                             for o in done for row in o.sections],
                            columns=["well", "recording", "section", "kind", "top_m",
                                     "bottom_m", "bins", "informed", "mu", "mu_std", "reason"])
    if not sections.empty:
        sections = pd.concat([sections.assign(level="recording", recordings=1),
                              _pooled_sections(sections).assign(level="well", recording="")],
                             ignore_index=True)
    states = _states(done)
    alarms = pd.DataFrame([{"well": o.well, "recording": o.label, "kind": kind,
                            "severity": severity, "count": count}
                           for o in done for (kind, severity), count in sorted(o.alarms.items())],
                          columns=["well", "recording", "kind", "severity", "count"])
    if not alarms.empty:
        per_well = alarms.groupby(["well", "kind", "severity"], as_index=False)["count"].sum()
        alarms = pd.concat([alarms.assign(level="recording"),
                            per_well.assign(level="well", recording="")], ignore_index=True)
    return {"recordings": recordings, "windows": windows, "friction": friction,
            "sections": sections, "states": states, "alarms": alarms}


def _states(done: Sequence[RecordingOutcome]) -> pd.DataFrame:
    import pandas as pd

    rows = []
    for o in done:
        total = sum(o.state_seconds.values())
        rows += [{"well": o.well, "recording": o.label, "state": state, "seconds": seconds,
                  "share": seconds / total if total > 0 else math.nan, "level": "recording"}
                 for state, seconds in sorted(o.state_seconds.items())]
    frame = pd.DataFrame(rows, columns=["well", "recording", "state", "seconds", "share",
                                        "level"])
    if frame.empty:
        return frame
    per_well = frame.groupby(["well", "state"], as_index=False)["seconds"].sum()
    per_well["share"] = per_well["seconds"] / per_well.groupby("well")["seconds"].transform("sum")
    return pd.concat([frame, per_well.assign(level="well", recording="")], ignore_index=True)


def write_tables(tables: dict[str, pd.DataFrame], folder: Path) -> list[Path]:
    """Write each table as Parquet (pyarrow, installed with tdmon's rerun-sdk) or, without
    pyarrow, as CSV; returns the files written."""
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        parquet = False
    else:
        parquet = True
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name in TABLES:
        path = folder / f"{name}.{'parquet' if parquet else 'csv'}"
        if parquet:
            tables[name].to_parquet(path, index=False)
        else:
            tables[name].to_csv(path, index=False)
        written.append(path)
    return written


_STYLE = """
body { font-family: sans-serif; margin: 2em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 90%; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: right; }
th { background: #eee; } td:first-child, th:first-child { text-align: left; }
tr.failed td { background: #fdd; }
tr.uninformed td { color: #888; background: #f6f6f6; }
"""


def _table(frame: pd.DataFrame, columns: list[str], formats: dict[str, str] | None = None) -> str:
    if frame.empty:
        return "<p>none</p>"
    return frame[columns].to_html(index=False, na_rep="-", border=0, formatters={
        column: (lambda value, f=f: "-" if value != value else format(value, f))
        for column, f in (formats or {}).items()})


def _pivot(frame: pd.DataFrame, column: str, value: str, fmt: str) -> str:
    if frame.empty:
        return "<p>none</p>"
    table = frame.pivot_table(index="recording", columns=column, values=value, aggfunc="sum")
    return table.to_html(na_rep="-", border=0, float_format=lambda v: format(v, fmt))


def _recordings_html(recordings: pd.DataFrame) -> str:
    head = ("<tr><th>recording</th><th>well</th><th>status</th><th>messages</th>"
            "<th>windows</th><th>alarms</th><th>wall [s]</th><th>reason</th></tr>")
    rows = []
    for row in recordings.itertuples(index=False):
        css = ' class="failed"' if row.status != "ok" else ""
        cells = [row.recording, row.well, row.status, row.messages_in, row.windows, row.alarms,
                 f"{row.wall_s:.1f}", row.error]
        rows.append(f"<tr{css}>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells)
                    + "</tr>")
    return f"<table>{head}{''.join(rows)}</table>"


def _sections_html(sections: pd.DataFrame, leading: list[str]) -> str:
    """Friction per hole section: informed rows with their figures, uninformed ones greyed
    with the reason instead of the prior's number."""
    if sections.empty:
        return "<p>none</p>"
    header = [*leading, "bins", "informed", "mu", "mu_std", "note"]
    head = "<tr>" + "".join(f"<th>{html.escape(name)}</th>" for name in header) + "</tr>"
    rows = []
    for row in sections.to_dict("records"):
        cells = [format(row[k], ".0f") if k in ("top_m", "bottom_m") else row[k]
                 for k in leading]
        cells += [row["bins"], row["informed"]]
        if row["informed"] > 0:
            cells += [format(row["mu"], ".3f"), format(row["mu_std"], ".3f"), ""]
            css = ""
        else:
            cells += ["-", "-", f"not informed by data (prior only): {row['reason']}"]
            css = ' class="uninformed"'
        rows.append(f"<tr{css}>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells)
                    + "</tr>")
    return f"<table>{head}{''.join(rows)}</table>"


def write_html(tables: dict[str, pd.DataFrame], path: Path, title: str = "tdmon batch") -> Path:
    """One self-contained page: the recordings (failures with their reason), then per well
    the friction per operation and per hole section with their uncertainty (a section no
    window informed greyed, with the reason, not its prior), the rig-state shares and the
    alarms."""
    recordings = tables["recordings"]
    failed = int((recordings["status"] != "ok").sum()) if not recordings.empty else 0
    parts = [f"<h1>{html.escape(title)}</h1>",
             f"<p>{len(recordings)} recordings, {failed} failed.</p>",
             "<h2>Recordings</h2>", _recordings_html(recordings)]
    wells = sorted(set(recordings.loc[recordings["status"] == "ok", "well"])) \
        if not recordings.empty else []
    mu = {"mu_mean": ".3f", "mu_sd": ".3f", "mu_se": ".4f", "mu_std_median": ".4f",
          "mu_min": ".3f", "mu_max": ".3f", "mu": ".3f", "mu_std": ".3f",
          "top_m": ".0f", "bottom_m": ".0f"}
    for well in wells:
        def of(name: str, level: str | None = None, well: str = well) -> pd.DataFrame:
            frame = tables[name]
            if frame.empty:
                return frame
            chosen = frame[frame["well"] == well]
            return chosen if level is None else chosen[chosen["level"] == level]

        parts += [f"<h2>Well: {html.escape(well or '(unnamed)')}</h2>",
                  "<h3>Friction per operation (window estimates)</h3>",
                  "<p>Pooled over the well's recordings: mean, spread (sd), standard error of "
                  "the mean (se) and the estimator's median own uncertainty.</p>",
                  _table(of("friction", "well"), ["operation", "section", "n", "mu_mean",
                                                  "mu_sd", "mu_se", "mu_std_median", "mu_min",
                                                  "mu_max"], mu),
                  "<p>Per recording:</p>",
                  _table(of("friction", "recording"), ["recording", "operation", "section",
                                                       "n", "mu_mean", "mu_sd", "mu_se"], mu),
                  "<h3>Friction per hole section (last profile)</h3>",
                  "<p>Over the profile's bins the windows informed (<i>informed</i> of "
                  "<i>bins</i>); a section none informed holds the well file's prior, which "
                  "is no result: greyed, with the reason.</p>",
                  _sections_html(of("sections", "well"), ["section", "kind", "top_m",
                                                          "bottom_m", "recordings"]),
                  "<p>Per recording:</p>",
                  _sections_html(of("sections", "recording"), ["recording", "section"]),
                  "<h3>Rig-state shares</h3>", _pivot(of("states", "recording"), "state",
                                                      "share", ".1%"),
                  "<h3>Alarms</h3>", _pivot(of("alarms", "recording"), "kind", "count", ".0f")]
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}"
            f"</title><style>{_STYLE}</style></head><body>{''.join(parts)}</body></html>\n")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(page, encoding="utf-8")
    return path
