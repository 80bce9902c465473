"""Post-well report from a real MCAP recording."""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path
from typing import Any

import pytest

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
    # the synthetic string never rotates: no torque axes, a note says why instead
    assert figures == ["friction_vs_depth.png", "hookload_vs_depth.png", "mu_T.png",
                       "rig_state.png"]
    assert "No torque figure: the string did not rotate" in page
    assert page.count("<figcaption>") == len(figures)
    # the drawn figures numbered 1, 2, 3, 4 (the torque note takes no number)
    assert re.findall(r"Figure (\d+)\.", page) == ["1", "2", "3", "4"]
    assert "<th></th>" not in page  # the key-value table has no empty header row
    assert "<p class='headline' id='headline'>" in page
    # the identifiable mu(T) fit is stated with its coefficients
    assert "mu(T) fitted from 1 updates: mu = 0.18 + 0.001 T (a = 0.18 ± 0.01" in page
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
    # no empty axes: every figure is replaced by its note (the drilling one's included),
    # unnumbered; no empty table
    assert page.count("</h3><p class='note'>") == 6 and "Figure 1." not in page
    assert "No model frames in the recording" in page and "<tbody></tbody>" not in page
    assert "No drilling figure: the recording holds no drilling frame." in page
    assert "No mu(T) figure. No mu(T) fit: no mu(T) calibration in this recording" in page


def _profile_recording(tmp_path: Path, informed: list[bool] | None) -> Path:
    md = [100.0 * i for i in range(1, 11)]
    profile: dict[str, object] = {"t": 10.0, "md_m": md, "mu": [0.2 + 0.01 * i for i in range(10)],
                                  "mu_std": [0.02] * 10}
    if informed is not None:
        profile |= {"informed": informed, "variance_ratio": [0.1] * 6 + [0.97] * 4,
                    "uninformed_reason": [None] * 6 + ["no window reached this depth"] * 4}
    with McapRecorder(tmp_path / "rec") as recorder:
        recorder.write("/tdmon/profile", 10, profile)
    return Path(recorder.stats.files[0])


def test_profile_bins_not_informed_by_data_are_greyed(tmp_path: Path,
                                                      monkeypatch: Any) -> None:
    import tdmon.record.report as report

    lines: dict[str, list[float]] = {}
    save = report._save

    limits: tuple[float, ...] = ()
    legend: list[str] = []

    def keep_lines(figure: Any, path: Path) -> Path:
        nonlocal limits
        for line in figure.axes[0].get_lines():
            lines[str(line.get_label())] = [float(x) for x in line.get_xdata()]
        limits = tuple(figure.axes[0].get_ylim())
        legend[:] = [t.get_text() for t in figure.axes[0].get_legend().get_texts()]
        return save(figure, path)

    monkeypatch.setattr(report, "_save", keep_lines)
    informed = [True] * 6 + [False] * 4
    out = tmp_path / "informed"
    report.write_report([_profile_recording(tmp_path / "a", informed)], out)
    page = (out / "report.html").read_text()
    assert ("Profile points the data did not inform are drawn grey (dotted): 6 of 10 points "
            "informed (variance ratio &lt; 0.5); not informed: 700-1000 m no window reached this "
            "depth") in page
    solid = lines["local friction profile"]
    assert [math.isnan(x) for x in solid] == [not f for f in informed]
    assert solid[:6] == pytest.approx([0.2 + 0.01 * i for i in range(6)])
    # the figure spans the informed 100-600 m with a 50 m margin, not the whole well: the
    # prior below (700-1000 m) is out of sight, so neither drawn nor in the legend
    assert limits == pytest.approx((650.0, 50.0))  # depth downwards
    assert "not informed by data (prior)" not in lines and "profile ± 1 sd" in legend
    # a profile message without the fields (older recordings): every point drawn, no note
    lines.clear()
    report.write_report([_profile_recording(tmp_path / "b", None)], tmp_path / "plain")
    assert not any(math.isnan(x) for x in lines["local friction profile"])
    assert "not informed" not in (tmp_path / "plain" / "report.html").read_text()


def test_report_refuses_an_unfinished_recording(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    source = Path(__file__).resolve().parents[2] / "replays" / "trip-in-noisy.mcap"
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(source.read_bytes()[: source.stat().st_size // 2])
    assert main(["report", str(cut), "--out", str(tmp_path / "report")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tdmon recover" in err[0], err
    assert not (tmp_path / "report").exists()


def _joint(t: float, mu: float, w: float, identifiable: bool, verdict: str) -> dict[str, Any]:
    return {"t": t, "kind": "joint", "operation": "pick_up", "mu": mu, "mu_std": 0.0052,
            "bit_depth_m": 2391.6, "weight_factor": w, "weight_factor_std": 0.0041,
            "correlation": -0.4123, "identifiable": identifiable, "identifiability": verdict}


def test_joint_verdict_in_the_words_it_always_had() -> None:
    """The summary's and report's sentence on friction and weight, now made from the
    parameters' declaration, says what it said before the declaration."""
    from tdmon.record.digest import joint_verdict

    assert joint_verdict([])["words"] == ("No joint estimate of friction and string weight in "
                                          "this recording (calibration off, or no window).")
    pick_up = "pick-up only: weight and friction not separable, friction given at the prior weight"
    alone = joint_verdict([_joint(1.0, 0.21, 1.01, False, pick_up)])
    assert alone["words"] == (f"Friction and string weight could not be separated (1 updates): "
                              f"{pick_up}; the friction factors above assume the modelled string "
                              "weight.")
    estimates = [_joint(1.0, 0.21, 1.01, False, pick_up),
                 _joint(2.0, 0.2134, 0.9766, True, "identifiable"),
                 _joint(3.0, 0.3, 1.2, False, pick_up)]
    verdict = joint_verdict(estimates)
    assert verdict == {
        "status": "identifiable", "estimates": 3, "identifiable": 1, "t": 2.0,
        "bit_depth_m": 2391.6, "operation": "pick_up", "mu": 0.2134, "mu_std": 0.0052,
        "weight_factor": 0.9766, "weight_factor_std": 0.0041, "correlation": -0.412,
        "reason": "identifiable",
        "words": "Friction and string weight separated in 1 of 3 updates; the last at 2392 m "
                 "MD: friction factor 0.213 ± 0.005 with the string 2.3 % lighter than "
                 "modelled (weight factor 0.977 ± 0.004)."}
    assert list(verdict) == ["status", "estimates", "identifiable", "t", "bit_depth_m",
                             "operation", "mu", "mu_std", "weight_factor", "weight_factor_std",
                             "correlation", "reason", "words"]


def _facts(friction: list[dict[str, Any]], joint: str = "not_identifiable",
           alarms: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    sections = [{"name": "9-5/8 in casing", "kind": "cased", "top_m": 0.0, "bottom_m": 2630.0,
                 "friction": "mu = 0.25"},
                {"name": "8-1/2 in open hole", "kind": "open", "top_m": 2630.0,
                 "bottom_m": 3510.0, "friction": "mu = 0.3"}]
    return {"well": {"sections": sections}, "friction": friction,
            "joint": {"status": joint}, "alarm_summary": alarms or []}


def _row(operation: str, section: str, mu: float, windows: int, low: float,
         high: float) -> dict[str, Any]:
    words = {"cased": "cased hole", "open": "open hole", "all": "whole string"}[section]
    return {"operation": operation, "section": section, "section_words": words,
            "windows": windows, "mu_median": mu, "bit_depth_min_m": low,
            "bit_depth_max_m": high}


def test_the_headline_sets_what_was_found_against_the_plan() -> None:
    from tdmon.record.report import headline

    found = headline(_facts([_row("pick_up", "cased", 0.117, 32, 2120.0, 2570.0)]))
    assert found == [
        "Pick-up friction 0.117 in cased hole (bit in the 9-5/8 in casing), 32 windows, bit at "
        "2120-2570 m MD, against the planned 0.25 (53 % below).",
        "No window reached 8-1/2 in open hole (planned mu = 0.3): its friction is not "
        "measured.",
        "These friction factors assume the modelled string weight: weight and friction could "
        "not be separated in this recording.",
        "No alarm."]
    # the whole string in both sections, planned differently: both plans named
    found = headline(_facts([_row("slack_off", "all", 0.30, 1, 3000.0, 3000.0)], "identifiable",
                            [{"severity": "critical", "count": 2},
                             {"severity": "warning", "count": 1}]))
    assert found == [
        "Slack-off friction 0.300 in the whole string (bit in the 8-1/2 in open hole), 1 window, "
        "bit at 3000 m MD, against the planned 9-5/8 in casing: mu = 0.25; 8-1/2 in open hole: "
        "mu = 0.3.", "3 alarms, 2 critical."]
    assert headline(_facts([]))[0].startswith("No friction factor was back-calculated")


def test_bit_depth_rows_before_the_first_reading_are_left_out() -> None:
    from tdmon.record.report import ReportData, bit_depth_span

    data = ReportData()
    data.states = [{"t": float(t), "bit_depth_m": depth}
                   for t, depth in enumerate([0.0] * 6 + [2117.7, 2300.0, 2573.9, 0.5])]
    # the six leading 0 m rows came before any bit depth; a late 0.5 m is a reading
    assert bit_depth_span(data) == (0.5, 2573.9)
    data.states = data.states[:9]
    assert bit_depth_span(data) == (2117.7, 2573.9)
