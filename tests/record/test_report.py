"""Post-well report from a real MCAP recording."""

from __future__ import annotations

import csv
from pathlib import Path

from tdmon.cli import main
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import RecordedMessage


def test_report_html_figures_and_csv(tmp_path: Path, stream: list[RecordedMessage]) -> None:
    with McapRecorder(tmp_path / "rec") as recorder:
        for item in stream:
            recorder.write(*item)
    [mcap] = recorder.stats.files
    out = tmp_path / "report"
    assert main(["report", str(mcap), "--out", str(out), "--title", "Synthetic trip"]) == 0
    page = (out / "report.html").read_text()
    assert "Synthetic trip" in page
    figures = sorted(p.name for p in out.glob("*.png"))
    assert figures == ["friction_vs_depth.png", "hookload_vs_depth.png", "mu_T.png",
                       "rig_state.png", "torque_vs_depth.png"]
    assert page.count("data:image/png;base64,") == len(figures)
    for png in out.glob("*.png"):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with open(out / "estimates.csv") as table:
        rows = list(csv.DictReader(table))
    windows = [m.message for m in stream
               if m.topic == "/tdmon/estimate" and m.message["kind"] == "window"]
    assert len(rows) == len(windows)
    assert [float(r["mu"]) for r in rows] == [w["mu"] for w in windows]
    assert {r["operation"] for r in rows} == {"pick_up", "slack_off"}
    assert rows[0]["time_utc"].startswith("2016-10-04")


def test_report_of_a_recording_without_model_data(tmp_path: Path) -> None:
    with McapRecorder(tmp_path / "rec") as recorder:
        recorder.write("/tdmon/alarm", 1, {"t": 1.0, "kind": "k", "severity": "info",
                                           "message": "<b>escaped</b>"})
    out = tmp_path / "report"
    assert main(["report", str(recorder.stats.files[0]), "--out", str(out)]) == 0
    page = (out / "report.html").read_text()
    assert "&lt;b&gt;escaped&lt;/b&gt;" in page
    assert list(out.glob("*.png")) == []
