"""The engineer's digest of flight recordings: which well and run, which operations, the
friction per operation and hole section with its uncertainty, the alarms, the mu(T) verdict.

One class, :class:`Digester`, computes these numbers message by message, in memory that does
not grow with the session's length (per frame it keeps two numbers' extremes and the rig state's
time and code; whole messages only of the window, mu(T) and joint estimates and the well);
:func:`digest` feeds it the messages of recordings read from disk, and ``tdmon replay`` hands
it the messages as the replay makes them (:class:`DigestSink`), so the summary needs no second
reading of the recording. The HTML report states these numbers in words and the summary JSON
(``tdmon report``'s ``summary.json``, ``tdmon replay --json``) carries them, so both say the
same (docs/recording.md, "Summary"). Everything is SI with the unit in the key; times are Unix
seconds with a UTC string beside.
"""

from __future__ import annotations

import json
import math
import os
from array import array
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from itertools import pairwise
from pathlib import Path
from typing import Any, Final

import numpy as np

from tdmon.calib.parameters import JOINT_PARAMETERS, EstimatedParameters, join_words
from tdmon.record.batch import encode_message
from tdmon.record.reader import read_messages, topic_counts
from tdmon.record.sink import MessageSink
from tdmon.vocabulary import ALARM_WORDS, AlarmKind, EstimateKind, Severity

__all__ = ["DigestSink", "Digester", "ReportData", "alarm_meaning", "digest", "load",
           "mu_t_verdict", "summarize", "utc"]

_TOPICS: Final = ("/tdmon/model", "/tdmon/estimate", "/tdmon/state", "/tdmon/alarm",
                  "/tdmon/profile", "/tdmon/well")
_SEVERITY_ORDER: Final[dict[str, int]] = {Severity.CRITICAL: 0, Severity.WARNING: 1,
                                           Severity.INFO: 2}
_SECTION_WORDS: Final = {"cased": "cased hole", "open": "open hole", "all": "whole string"}
_OPERATION_WORDS: Final = {"pick_up": "pick-up", "slack_off": "slack-off",
                           "rotating": "rotating off bottom", "on_bottom": "on bottom",
                           "reaming": "reaming", "back_reaming": "back-reaming"}
#: The estimates the digest reads whole (a few per window, none per frame).
_KEPT_ESTIMATES: Final = frozenset({EstimateKind.WINDOW, EstimateKind.MU_T, EstimateKind.JOINT})

@dataclass
class ReportData:
    """The messages a report needs, gathered in one pass over the recordings."""

    models: list[dict[str, Any]] = field(default_factory=list)
    estimates: list[dict[str, Any]] = field(default_factory=list)
    states: list[dict[str, Any]] = field(default_factory=list)
    alarms: list[dict[str, Any]] = field(default_factory=list)
    profiles: list[dict[str, Any]] = field(default_factory=list)
    wells: list[dict[str, Any]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    recordings: list[str] = field(default_factory=list)


def load(paths: Sequence[str | os.PathLike[str]], *, allow_unfinished: bool = False
         ) -> ReportData:
    """Read the topics the report uses from finished MCAP files (``allow_unfinished``: an
    unfinished one too, up to its last flush; else it is refused with a RecordError)."""
    data = ReportData(recordings=[str(p) for p in paths])
    buckets = {
        "/tdmon/model": data.models, "/tdmon/estimate": data.estimates,
        "/tdmon/state": data.states, "/tdmon/alarm": data.alarms,
        "/tdmon/profile": data.profiles, "/tdmon/well": data.wells,
    }
    for path in paths:
        for topic, n in topic_counts(path, allow_unfinished=allow_unfinished).items():
            data.counts[topic] = data.counts.get(topic, 0) + n
        for topic, _, message in read_messages(path, _TOPICS, allow_unfinished=allow_unfinished):
            buckets[topic].append(message)
    return data


def utc(t: float | None) -> str | None:
    """``YYYY-MM-DD HH:MM:SS`` UTC of a Unix time (None when not finite)."""
    if t is None or not math.isfinite(t):
        return None
    return datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%d %H:%M:%S")


def _num(value: Any) -> float:
    # numpy numbers too: a message the replay hands over may hold them (its recording holds
    # their Python values)
    if isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool):
        return float(value)
    return math.nan


def _rounded(value: float, digits: int = 4) -> float | None:
    return round(value, digits) if math.isfinite(value) else None


def digest(data: ReportData) -> dict[str, Any]:
    """The engineer's numbers of recordings read with :func:`load` (:meth:`Digester.digest`)."""
    digester = Digester()
    for topic, messages in (("/tdmon/well", data.wells), ("/tdmon/state", data.states),
                            ("/tdmon/model", data.models), ("/tdmon/estimate", data.estimates),
                            ("/tdmon/alarm", data.alarms)):
        for message in messages:
            digester.add(topic, message)
    return digester.digest(data.recordings, data.counts)


def _as_recorded(message: dict[str, Any]) -> dict[str, Any]:
    """``message`` as a recording gives it back: its JSON bytes (NaN and infinities as null,
    numpy values as Python ones) read again."""
    recorded: dict[str, Any] = json.loads(encode_message(message)[0])
    return recorded


class _AlarmGroup:
    """The alarms of one kind and severity: count, first and last finite time, the latest."""

    __slots__ = ("count", "first", "last", "latest_message", "latest_t")

    def __init__(self, message: dict[str, Any]) -> None:
        self.count = 0
        self.first, self.last = math.inf, -math.inf
        self.latest_t = -math.inf
        self.latest_message = _as_recorded(message).get("message")

    def add(self, message: dict[str, Any]) -> None:
        self.count += 1
        t = _num(message.get("t"))
        if math.isfinite(t):
            self.first, self.last = min(self.first, t), max(self.last, t)
            if t > self.latest_t:  # the first of equal times stays, as ``max`` keeps it
                self.latest_t = t
                self.latest_message = _as_recorded(message).get("message")


class Digester:
    """The digest's figures gathered one message at a time; :meth:`digest` gives them.

    Memory: per rig-state message a time and a code (12 bytes: the time shares are summed
    over the messages in time order, as they were when read from a file); per model message
    nothing but the running extremes of time and bit depth; the alarms per kind and severity
    as a count, a time range and the latest's text; whole messages only of the well and of the
    window, mu(T) and joint estimates (a few per window). Every figure is the one the
    recording read back gives (:func:`_as_recorded`).
    """

    def __init__(self) -> None:
        self.well: dict[str, Any] | None = None
        self.estimates: list[dict[str, Any]] = []
        self._t_range = [math.inf, -math.inf]
        self._depth_range = [math.inf, -math.inf]
        self._state_t = array("d")
        self._state_code = array("I")
        self._state_names: dict[str, int] = {}
        self._alarms: dict[tuple[str, str], _AlarmGroup] = {}

    def add(self, topic: str, message: dict[str, Any]) -> None:
        """Take one message of ``topic`` (others than the digest's are ignored)."""
        if topic == "/tdmon/state":
            t = _num(message.get("t"))
            if math.isfinite(t):
                self._state_t.append(t)
                self._state_code.append(self._state_names.setdefault(
                    str(message.get("state")), len(self._state_names)))
            self._extend(t, _num(message.get("bit_depth_m")))
        elif topic == "/tdmon/model":
            self._extend(_num(message.get("t")), _num(message.get("bit_depth_m")))
        elif topic == "/tdmon/estimate":
            if message.get("kind") in _KEPT_ESTIMATES:
                self.estimates.append(_as_recorded(message))
        elif topic == "/tdmon/alarm":
            key = (str(message.get("kind")), str(message.get("severity")))
            group = self._alarms.get(key)
            if group is None:
                group = self._alarms[key] = _AlarmGroup(message)
            group.add(message)
        elif topic == "/tdmon/well" and self.well is None:
            self.well = _as_recorded(message)

    def _extend(self, t: float, depth: float) -> None:
        if math.isfinite(t):
            times = self._t_range
            times[0], times[1] = min(times[0], t), max(times[1], t)
        if math.isfinite(depth):
            depths = self._depth_range
            depths[0], depths[1] = min(depths[0], depth), max(depths[1], depth)

    def alarm_rows(self) -> list[dict[str, Any]]:
        """The alarms taken so far, as :func:`alarm_rows` gives them."""
        return _alarm_rows(self._alarms)

    def digest(self, recordings: Sequence[str], counts: dict[str, int]) -> dict[str, Any]:
        """The engineer's numbers (JSON-ready, SI, no NaN) of the messages taken so far;
        ``recordings`` and ``counts`` (messages per topic) describe the run.

        Keys: ``well`` (name, files, methods, hole sections, mu(T) law; from the ``well``
        message), ``run`` (recordings), ``time_range``, ``depth_range_m`` (bit depth),
        ``operations`` (share of rig time per rig state), ``friction`` (one row per operation
        and hole section), ``alarm_summary`` (one row per kind and severity, most important
        first), ``mu_t`` (the verdict), ``joint`` (friction and weight factor together) and
        ``notes`` (the daemon's notes, e.g. why the mu(T) calibration is off).
        """
        well = self.well or {}
        names = list(self._state_names)
        return {
            "well": {
                "name": well.get("name"), "well_file": well.get("file", well.get("well_file")),
                "daemon_file": well.get("daemon_file"), "method": well.get("method"),
                "backcalc_method": well.get("backcalc_method"),
                "mu_t_law": well.get("mu_t_law"), "sections": well.get("sections", []),
            },
            "run": {"recordings": list(recordings),
                    "messages": int(sum(counts.values()))},
            "time_range": _time_range(*self._t_range),
            "depth_range_m": _depth_range(*self._depth_range),
            "operations": _state_shares(zip(self._state_t, (names[c] for c in self._state_code),
                                            strict=True)),
            "friction": friction_rows(self.estimates),
            "alarm_summary": self.alarm_rows(),
            "mu_t": mu_t_verdict(self.estimates, well),
            "joint": joint_verdict(self.estimates),
            "notes": [str(n) for n in well.get("notes", [])],
        }


class DigestSink(MessageSink):
    """A :class:`Digester` riding along a replay as a sink (``digester`` holds the figures)."""

    topics = frozenset(_TOPICS) - {"/tdmon/profile"}

    def __init__(self) -> None:
        self.digester = Digester()

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        self.digester.add(topic, message)


def _time_range(first: float, last: float) -> dict[str, Any]:
    if first > last:
        return {"first_t": None, "last_t": None, "first_utc": None, "last_utc": None,
                "duration_s": None}
    return {"first_t": first, "last_t": last, "first_utc": utc(first), "last_utc": utc(last),
            "duration_s": round(last - first, 3)}


def _depth_range(shallowest: float, deepest: float) -> dict[str, float | None]:
    if shallowest > deepest:
        return {"min": None, "max": None}
    return {"min": round(shallowest, 2), "max": round(deepest, 2)}


def _state_shares(states: Iterable[tuple[float, str]]) -> dict[str, float]:
    """Share of rig time in each state, from the rig-time intervals between state messages
    (``(t, state)`` of each, t finite; a state message is sent on a change and at least every
    second)."""
    timed = sorted(states, key=lambda item: item[0])
    spent: dict[str, float] = {}
    for (t, state), (t_next, _) in pairwise(timed):
        spent[state] = spent.get(state, 0.0) + t_next - t
    total = sum(spent.values())
    if total <= 0.0:
        return {}
    return {state: round(seconds / total, 4)
            for state, seconds in sorted(spent.items(), key=lambda kv: -kv[1])}


def friction_rows(estimates: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Window friction per operation and hole section.

    ``mu_median`` is the median of the windows' friction factors, ``mu_sd`` their spread
    (sample standard deviation between windows; None for one window), ``mu_window_sd`` the
    median of the windows' own standard deviations (the measurement's uncertainty), and the
    bit-depth range the windows cover. ``unresolved`` counts the windows that could not
    resolve friction above the sensor's uncertainty (they publish none: docs/hookload.md) and
    ``resolution`` gives the last one's reason; a group of such windows alone has no friction.
    """
    windows = [e for e in estimates if e.get("kind") == EstimateKind.WINDOW
               and (math.isfinite(_num(e.get("mu"))) or e.get("resolvable") is False)]
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for window in windows:
        key = (str(window.get("operation")), str(window.get("section", "all")))
        groups.setdefault(key, []).append(window)
    rows = []
    for (operation, section), group in sorted(groups.items()):
        chosen = [e for e in group if math.isfinite(_num(e.get("mu")))]
        unresolved = [e for e in group if not math.isfinite(_num(e.get("mu")))]
        mu = np.array([_num(e["mu"]) for e in chosen])
        own = np.array([_num(e.get("mu_std")) for e in chosen])
        depth = np.array([_num(e.get("bit_depth_m")) for e in group])
        own, depth = own[np.isfinite(own)], depth[np.isfinite(depth)]
        some = mu.size > 0
        rows.append({
            "operation": operation, "section": section,
            "section_words": _SECTION_WORDS.get(section, section),
            "windows": int(mu.size),
            "mu_median": _rounded(float(np.median(mu))) if some else None,
            "mu_mean": _rounded(float(mu.mean())) if some else None,
            "mu_sd": _rounded(float(mu.std(ddof=1))) if mu.size > 1 else None,
            "mu_window_sd": _rounded(float(np.median(own))) if own.size else None,
            "mu_min": _rounded(float(mu.min())) if some else None,
            "mu_max": _rounded(float(mu.max())) if some else None,
            "bit_depth_min_m": _rounded(float(depth.min()), 1) if depth.size else None,
            "bit_depth_max_m": _rounded(float(depth.max()), 1) if depth.size else None,
            "low_confidence": int(sum(bool(e.get("low_confidence")) for e in chosen)),
            "unresolved": len(unresolved),
            "resolution": unresolved[-1].get("resolution") if unresolved else None,
        })
    return rows


def friction_words(row: dict[str, Any]) -> str:
    """One sentence for a :func:`friction_rows` row."""
    operation = _OPERATION_WORDS.get(row["operation"], row["operation"].replace("_", " "))
    where = row["section_words"]
    depth = ""
    if row["bit_depth_min_m"] is not None:
        depth = (f", bit at {row['bit_depth_min_m']:.0f} m MD" if
                 row["bit_depth_min_m"] == row["bit_depth_max_m"] else
                 f", bit from {row['bit_depth_min_m']:.0f} to {row['bit_depth_max_m']:.0f} m MD")
    n = row["windows"]
    unresolved = row.get("unresolved") or 0
    if n == 0:
        return (f"{operation.capitalize()}, {where}: no friction published "
                f"({unresolved} window{'s' if unresolved != 1 else ''}{depth}): "
                f"{row.get('resolution') or 'not resolvable'}.")
    spread = ("" if row["mu_sd"] is None else
              f"; the windows scatter by {row['mu_sd']:.3f} (1 sd) between "
              f"{row['mu_min']:.3f} and {row['mu_max']:.3f}")
    own = ("" if row["mu_window_sd"] is None else
           f"; a single window is uncertain by about {row['mu_window_sd']:.4f} (1 sd)")
    left = ("" if not unresolved else
            f"; {unresolved} more window{'s' if unresolved != 1 else ''} could not resolve "
            "friction above the sensor's uncertainty")
    return (f"{operation.capitalize()}, {where}: friction factor {row['mu_median']:.3f} "
            f"(median of {n} window{'s' if n != 1 else ''}{depth}){spread}{own}{left}.")


def alarm_rows(alarms: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per alarm kind and severity: count, first and last time, the last message;
    critical first, then warnings, then information, more frequent first."""
    digester = Digester()
    for alarm in alarms:
        digester.add("/tdmon/alarm", alarm)
    return digester.alarm_rows()


def _alarm_rows(groups: dict[tuple[str, str], _AlarmGroup]) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for (kind, severity), group in groups.items():
        first, last = ((group.first, group.last) if group.first <= group.last
                       else (None, None))
        rows.append({
            "kind": kind, "severity": severity, "count": group.count,
            "meaning": alarm_meaning(kind),
            "first_t": first, "last_t": last, "first_utc": utc(first), "last_utc": utc(last),
            "last_message": group.latest_message,
        })
    rows.sort(key=lambda r: (_SEVERITY_ORDER.get(r["severity"], 3), -r["count"], r["kind"]))
    return rows


def alarm_meaning(kind: str) -> str:
    """An alarm kind in a drilling engineer's words (`tdmon.vocabulary.ALARM_WORDS`); a kind
    this tdmon does not know (a newer daemon's recording) in its own words."""
    try:
        return ALARM_WORDS[AlarmKind(kind)]
    except ValueError:
        return kind.replace("_", " ")


def mu_t_verdict(estimates: Sequence[dict[str, Any]], well: dict[str, Any] | None = None
                 ) -> dict[str, Any]:
    """The mu(T) verdict from the last ``mu_T`` estimate: a fit with its coefficients, or why
    there is none (``status``: ``"fit"``, ``"not_identifiable"`` or ``"none"``)."""
    fits = [e for e in estimates if e.get("kind") == EstimateKind.MU_T]
    well = well or {}
    if not fits:
        notes = [str(n) for n in well.get("notes", [])]
        reason = ("; ".join(notes) if notes else
                  "no mu(T) calibration in this recording (calibration off, no [temperature] "
                  "table in the well file, or no window reached it)")
        return {"status": "none", "estimates": 0, "reason": reason, "words": "No mu(T) fit: "
                + reason + "."}
    last = fits[-1]
    params = {k: _num(v) for k, v in (last.get("params") or {}).items()}
    params_std = {k: _num(v) for k, v in (last.get("params_std") or {}).items()}
    temperature = [_num(v) for v in (last.get("temperature_C") or [])]
    verdict: dict[str, Any] = {
        "status": "fit" if last.get("identifiable") else "not_identifiable",
        "estimates": len(fits), "t": _num(last.get("t")), "model": last.get("model"),
        "params": {k: _rounded(v, 6) for k, v in params.items()},
        "params_std": {k: _rounded(v, 6) for k, v in params_std.items()},
        "temperature_range_C": [_rounded(v, 2) for v in temperature],
        "slope_per_K": _rounded(_num(last.get("slope_per_K")), 6),
        "slope_interval_per_K": [_rounded(_num(v), 6)
                                 for v in last.get("slope_interval_per_K") or []],
        "reason": last.get("identifiability"),
    }
    coefficients = ", ".join(
        f"{k} = {v:.4g} ± {params_std.get(k, math.nan):.2g}" for k, v in params.items())
    if verdict["status"] == "fit":
        verdict["words"] = (f"mu(T) fitted from {len(fits)} updates: {last.get('model')} "
                            f"({coefficients}; T in degC); {last.get('identifiability')}.")
    else:
        verdict["words"] = (f"mu(T) not identifiable: {last.get('identifiability')} "
                            f"(last of {len(fits)} updates; its coefficients, not to be used as "
                            f"a law: {coefficients}).")
    return verdict


def joint_verdict(estimates: Sequence[dict[str, Any]],
                  parameters: EstimatedParameters = JOINT_PARAMETERS) -> dict[str, Any]:
    """Friction and the parameters estimated beside it (``joint`` estimates,
    docs/back-calculation.md; the string weight): how often the data separated them, and the
    last estimate that did (else the last one, with why they could not be separated). Each
    parameter's value and standard deviation under its name, its words from its declaration
    (:mod:`tdmon.calib.parameters`)."""
    joint = [e for e in estimates if e.get("kind") == EstimateKind.JOINT]
    # the parameters the recording's rig estimated (its hook-load sensor's), friction and
    # the string weight when there is no estimate at all
    parameters = EstimatedParameters(tuple(
        p for k, p in enumerate(parameters)
        if k < 2 or (joint and p.name in joint[-1])))
    friction, nouns = parameters.friction, parameters.nouns()
    together = join_words([friction.noun, *(p.noun for p in parameters.others)])
    if not joint:
        return {"status": "none", "estimates": 0,
                "words": f"No joint estimate of {together} in this recording "
                         "(calibration off, or no window)."}
    separated = [e for e in joint if e.get("identifiable")]
    last = (separated or joint)[-1]
    verdict: dict[str, Any] = {
        "status": "identifiable" if separated else "not_identifiable",
        "estimates": len(joint), "identifiable": len(separated), "t": _num(last.get("t")),
        "bit_depth_m": _rounded(_num(last.get("bit_depth_m")), 1),
        "operation": last.get("operation"),
    }
    for parameter in parameters:
        verdict[parameter.name] = _rounded(_num(last.get(parameter.name)))
        verdict[parameter.std_field] = _rounded(_num(last.get(parameter.std_field)))
    for i, j in parameters.pairs():
        field = parameters.correlation_field(i, j)
        verdict[field] = _rounded(_num(last.get(field)), 3)
    verdict["reason"] = last.get("identifiability")
    if separated:
        read = []
        for parameter in parameters.others:
            value = _num(last.get(parameter.name))
            text = parameter.text(value, _num(last.get(parameter.std_field)))
            reading = parameter.read(value)
            read.append(text if reading is None else f"{reading} ({text})")
        verdict["words"] = (
            f"{together[:1].upper()}{together[1:]} separated in {len(separated)} of "
            f"{len(joint)} updates; the last at {_num(last.get('bit_depth_m')):.0f} m MD: "
            f"{friction.text(_num(last.get('mu')), _num(last.get('mu_std')))} with "
            f"{join_words(read)}.")
    else:
        verdict["words"] = (
            f"{together[:1].upper()}{together[1:]} could not be separated ({len(joint)} "
            f"updates): {last.get('identifiability')}; the {friction.label}s above assume the "
            f"modelled {nouns}.")
    return verdict


def summary_path(out_dir: str | os.PathLike[str]) -> Path:
    """Where ``tdmon report`` writes the digest: ``summary.json`` beside ``report.html``."""
    return Path(out_dir) / "summary.json"


def summarize(paths: Sequence[str | os.PathLike[str]], *, allow_unfinished: bool = False
              ) -> dict[str, Any]:
    """:func:`digest` of recordings read from disk (the summary JSON's engineer's part)."""
    return digest(load(paths, allow_unfinished=allow_unfinished))
