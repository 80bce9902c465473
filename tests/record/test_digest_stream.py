"""The digest gathered while messages are made (``tdmon replay``'s summary) is the digest of
the recording they make, read back from disk."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from tdmon.record.digest import Digester, DigestSink, alarm_rows, summarize
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import topic_counts


def _messages() -> list[tuple[str, dict[str, Any]]]:
    """A small run with what the in-memory messages hold and the recording does not: numpy
    numbers, NaN, state messages out of time order, alarms with equal and missing times."""
    out: list[tuple[str, dict[str, Any]]] = [
        ("/tdmon/well", {"name": "W-1", "file": "w.toml", "sections": [{"kind": "cased"}],
                         "notes": ["mu(T) off"]}),
        ("/tdmon/well", {"name": "second, ignored"}),
    ]
    states = ["static", "pick_up", "pick_up", "slack_off", "static", "pick_up"]
    for k, state in enumerate(states):
        t = 100.0 + 1.5 * k
        out.append(("/tdmon/state", {"t": np.float64(t), "state": state, "steady": True,
                                     "bit_depth_m": 1000.0 + k}))
        out.append(("/tdmon/model", {"t": t, "bit_depth_m": np.float32(1000.25 + k),
                                     "hookload": math.nan}))
    # a late state message (its time before the last one's), and one without a time
    out.append(("/tdmon/state", {"t": 103.25, "state": "slack_off", "bit_depth_m": None}))
    out.append(("/tdmon/state", {"t": math.nan, "state": "static", "bit_depth_m": 900.0}))
    for k, (operation, mu) in enumerate([("pick_up", 0.21), ("pick_up", np.float32(0.23)),
                                         ("slack_off", 0.19), ("slack_off", math.nan)]):
        out.append(("/tdmon/estimate", {
            "t": 101.0 + k, "kind": "window", "operation": operation, "section": "open",
            "mu": mu, "mu_std": 0.01 * (k + 1), "bit_depth_m": 1000.0 + k,
            "low_confidence": k == 1, "resolvable": not (isinstance(mu, float)
                                                         and math.isnan(mu)),
            "resolution": "too little load change"}))
    out.append(("/tdmon/estimate", {"t": 104.0, "kind": "profile", "md_m": [1.0, 2.0]}))
    out.append(("/tdmon/estimate", {"t": 105.0, "kind": "mu_T", "identifiable": False,
                                    "model": "linear", "params": {"a": np.float64(0.2)},
                                    "params_std": {"a": math.inf},
                                    "identifiability": "one temperature"}))
    out.append(("/tdmon/estimate", {"t": 106.0, "kind": "joint", "identifiable": True,
                                    "mu": 0.2, "mu_std": 0.01, "bit_depth_m": 1003.0,
                                    "operation": "pick_up", "identifiability": "separated"}))
    for t, kind, severity, text in [(101.0, "band", "warning", "first"),
                                    (103.0, "band", "warning", "latest"),
                                    (103.0, "band", "warning", "same time, later"),
                                    (math.nan, "band", "warning", "no time"),
                                    (102.0, "sensor_stale", "critical", "stale"),
                                    (math.nan, "friction_jump", "info", "never timed")]:
        out.append(("/tdmon/alarm", {"t": t, "kind": kind, "severity": severity,
                                     "message": text}))
    return out


def test_digest_while_recording_is_the_digest_read_back(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    sink = DigestSink()
    with McapRecorder(path=path, overwrite=True) as recorder:
        for n, (topic, message) in enumerate(_messages()):
            recorder.write(topic, 10**9 * (n + 1), message)
            if topic in sink.topics:
                sink.write(topic, 10**9 * (n + 1), message)
    streamed = sink.digester.digest([str(path)], topic_counts(path))
    assert streamed == summarize([path])
    # the figures themselves: states summed in time order (static 1.5 + 1.5 s, pick-up 1.5 +
    # 0.25 s, slack-off 1.25 + 1.5 s of 7.5 s), the well the first one, the latest alarm the
    # first of two at the same time, the NaN window counted as unresolved
    assert list(streamed["operations"].items()) == [("static", 0.4), ("slack_off", 0.3667),
                                                     ("pick_up", 0.2333)]
    assert streamed["well"]["name"] == "W-1" and streamed["notes"] == ["mu(T) off"]
    assert streamed["time_range"]["first_t"] == 100.0
    assert streamed["time_range"]["duration_s"] == 7.5
    assert streamed["depth_range_m"] == {"min": 900.0, "max": 1005.25}
    band = next(r for r in streamed["alarm_summary"] if r["kind"] == "band")
    assert (band["count"], band["first_t"], band["last_message"]) == (4, 101.0, "latest")
    assert [r["kind"] for r in streamed["alarm_summary"]] == ["sensor_stale", "band",
                                                               "friction_jump"]
    friction = {r["operation"]: r for r in streamed["friction"]}
    assert friction["slack_off"]["unresolved"] == 1
    assert friction["pick_up"]["mu_max"] == round(float(np.float32(0.23)), 4)
    assert streamed["mu_t"]["status"] == "not_identifiable"
    assert streamed["joint"]["status"] == "identifiable"


def test_memory_does_not_follow_the_frames() -> None:
    digester = Digester()
    for k in range(20_000):
        digester.add("/tdmon/model", {"t": float(k), "bit_depth_m": 1000.0 + k % 7})
        digester.add("/tdmon/state", {"t": float(k), "state": "pick_up" if k % 2 else "static",
                                      "bit_depth_m": 1000.0})
    assert digester.estimates == [] and digester.well is None
    shares = digester.digest([], {})["operations"]
    assert shares == {"static": 0.5, "pick_up": 0.5}


def test_alarm_rows_of_no_alarms() -> None:
    assert alarm_rows([]) == []
