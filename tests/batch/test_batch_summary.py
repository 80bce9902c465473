"""The fleet summary's arithmetic on hand-made outcomes (no cluster): friction statistics,
hole sections from a profile, pooled figures, state shares, the tables written and the page."""

from __future__ import annotations

import math
import re
import statistics
import sys
from pathlib import Path

import pandas as pd
import pytest

from tdmon.replay.batch import output_names
from tdmon.replay.batch_summary import (
    TABLES,
    HoleSectionSpan,
    RecordingOutcome,
    section_rows,
    summary_tables,
    write_html,
    write_tables,
)

SECTIONS = [HoleSectionSpan("casing", "cased", 0.0, 1000.0),
            HoleSectionSpan("open hole", "open", 1000.0, 2000.0)]


def _window(mu: float, operation: str = "pick_up", low: bool = False) -> dict[str, object]:
    return {"t": 0.0, "operation": operation, "section": "all", "mu": mu, "mu_std": 0.01,
            "bit_depth_m": 1500.0, "low_confidence": low}


def _outcomes() -> list[RecordingOutcome]:
    a = RecordingOutcome(
        recording="a.mcap", out="out/a.mcap", well="W1",
        windows=[_window(0.20), _window(0.24), _window(0.28), _window(0.9, low=True),
                 _window(0.30, "slack_off")],
        sections=[{"section": "casing", "kind": "cased", "top_m": 0.0, "bottom_m": 1000.0,
                   "bins": 2, "informed": 2, "mu": 0.20, "mu_std": 0.02, "reason": ""},
                  {"section": "open hole", "kind": "open", "top_m": 1000.0,
                   "bottom_m": 2000.0, "bins": 3, "informed": 0, "mu": math.nan,
                   "mu_std": math.nan, "reason": "no window reached this depth"}],
        state_seconds={"pick_up": 300.0, "in_slips": 100.0},
        alarms={("overpull", "warning"): 2})
    b = RecordingOutcome(
        recording="b.mcap", out="out/b.mcap", well="W1", windows=[_window(0.26)],
        sections=[{"section": "casing", "kind": "cased", "top_m": 0.0, "bottom_m": 1000.0,
                   "bins": 2, "informed": 1, "mu": 0.30, "mu_std": 0.04, "reason": ""},
                  {"section": "open hole", "kind": "open", "top_m": 1000.0,
                   "bottom_m": 2000.0, "bins": 3, "informed": 0, "mu": math.nan,
                   "mu_std": math.nan, "reason": "no window reached this depth"}],
        state_seconds={"pick_up": 100.0}, alarms={("overpull", "warning"): 1})
    broken = RecordingOutcome(recording="c.mcap", out=None, error="c.mcap: not an MCAP file")
    return [a, b, broken]


def test_section_rows_average_the_bins_inside_each_section() -> None:
    profile = {"md_m": [500.0, 900.0, 1100.0, 1900.0, 2500.0],
               "mu_profile": [0.2, 0.3, 0.4, float("nan"), 0.9],
               "mu_profile_std": [0.1, 0.3, 0.05, 0.05, 0.1]}
    rows = section_rows(profile, SECTIONS)
    assert [r["section"] for r in rows] == ["casing", "open hole"]
    assert rows[0]["bins"] == 2 and rows[0]["mu"] == pytest.approx(0.25)
    assert rows[0]["mu_std"] == pytest.approx(0.2)
    # the NaN bin is left out, the bin below the last section too
    assert rows[1]["bins"] == 1 and rows[1]["mu"] == pytest.approx(0.4)
    assert section_rows(None, SECTIONS) == []


def test_section_rows_show_no_prior_as_a_result() -> None:
    # the casing's first bin and every open-hole bin hold the prior (0.25, 0.30)
    profile = {"md_m": [500.0, 900.0, 1100.0, 1500.0],
               "mu_profile": [0.25, 0.18, 0.30, 0.30],
               "mu_profile_std": [0.10, 0.02, 0.10, 0.10],
               "informed": [False, True, False, False],
               "uninformed_reason": ["too little bit travel", None,
                                     "no window reached this depth",
                                     "no window reached this depth"]}
    casing, open_hole = section_rows(profile, SECTIONS)
    assert (casing["bins"], casing["informed"]) == (2, 1)
    assert casing["mu"] == pytest.approx(0.18) and casing["mu_std"] == pytest.approx(0.02)
    assert casing["reason"] == ""
    assert (open_hole["bins"], open_hole["informed"]) == (2, 0)
    assert math.isnan(open_hole["mu"]) and math.isnan(open_hole["mu_std"])
    assert open_hole["reason"] == "no window reached this depth"


def test_friction_statistics_per_recording_and_pooled_per_well() -> None:
    tables = summary_tables(_outcomes())
    friction = tables["friction"].set_index(["level", "recording", "operation"])
    a = friction.loc[("recording", "a", "pick_up")]
    assert a["n"] == 3  # the low-confidence 0.9 is left out
    assert a["mu_mean"] == pytest.approx(0.24)
    assert a["mu_sd"] == pytest.approx(statistics.stdev([0.20, 0.24, 0.28]))
    assert a["mu_se"] == pytest.approx(statistics.stdev([0.20, 0.24, 0.28]) / math.sqrt(3))
    pooled = friction.loc[("well", "", "pick_up")]
    assert pooled["n"] == 4 and pooled["mu_mean"] == pytest.approx(0.245)
    assert friction.loc[("well", "", "slack_off")]["n"] == 1


def test_sections_pool_by_inverse_variance() -> None:
    sections = summary_tables(_outcomes())["sections"]
    pooled = sections[sections["level"] == "well"].set_index("section")
    casing = pooled.loc["casing"]
    w1, w2 = 1 / 0.02**2, 1 / 0.04**2
    assert casing["mu"] == pytest.approx((0.20 * w1 + 0.30 * w2) / (w1 + w2))
    assert casing["mu_std"] == pytest.approx(1 / math.sqrt(w1 + w2))
    assert casing["recordings"] == 2
    assert (casing["bins"], casing["informed"]) == (4, 3)
    # no recording informed the open hole: no figure, the reason instead
    open_hole = pooled.loc["open hole"]
    assert (open_hole["bins"], open_hole["informed"]) == (6, 0)
    assert math.isnan(open_hole["mu"]) and math.isnan(open_hole["mu_std"])
    assert open_hole["reason"] == "no window reached this depth"


def test_states_alarms_and_failures() -> None:
    tables = summary_tables(_outcomes())
    states = tables["states"]
    per_recording = states[(states["level"] == "recording") & (states["recording"] == "a")]
    assert per_recording.set_index("state")["share"].to_dict() == pytest.approx(
        {"pick_up": 0.75, "in_slips": 0.25})
    well = states[states["level"] == "well"].set_index("state")["share"]
    assert well.to_dict() == pytest.approx({"pick_up": 0.8, "in_slips": 0.2})
    alarms = tables["alarms"]
    assert alarms[alarms["level"] == "well"]["count"].tolist() == [3]
    recordings = tables["recordings"].set_index("recording")
    assert recordings.loc["c", "status"] == "failed"
    assert recordings.loc["c", "error"] == "c.mcap: not an MCAP file"
    assert recordings.loc["a", "windows"] == 5


def test_tables_written_as_parquet_or_csv_and_the_page(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    tables = summary_tables(_outcomes())
    written = write_tables(tables, tmp_path / "parquet")
    assert [p.name for p in written] == [f"{name}.parquet" for name in TABLES]
    back = pd.read_parquet(tmp_path / "parquet" / "friction.parquet")
    assert back["n"].sum() == tables["friction"]["n"].sum()
    with monkeypatch.context() as patch:
        patch.setitem(sys.modules, "pyarrow", None)  # as if pyarrow were not installed
        written = write_tables(tables, tmp_path / "csv")
    assert [p.suffix for p in written] == [".csv"] * len(TABLES)
    assert len(pd.read_csv(tmp_path / "csv" / "recordings.csv")) == 3
    page = write_html(tables, tmp_path / "summary.html").read_text()
    assert "3 recordings, 1 failed" in page and "c.mcap: not an MCAP file" in page
    assert "Well: W1" in page and "0.245" in page  # the pooled pick-up friction
    # the open hole's rows are greyed with the reason, and no prior's figure is shown
    uninformed = re.findall(r'<tr class="uninformed">(.*?)</tr>', page)
    assert len(uninformed) == 3  # pooled, and one per recording
    assert all("no window reached this depth" in row and "0.3" not in row
               for row in uninformed)


def test_output_names_are_distinct() -> None:
    names = output_names([Path("a/x.mcap"), Path("b/x.mcap"), Path("b/y.mcap"),
                          Path("c/x.mcap")])
    assert names == ["x.mcap", "x-2.mcap", "y.mcap", "x-3.mcap"]
