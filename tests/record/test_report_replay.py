"""The engineer's report and summary of a real replay: the numbers on the page and in the JSON
are the recording's own (well name from the well file, friction medians of the recorded
window estimates, the mu(T) verdict of the last mu(T) estimate)."""

from __future__ import annotations

import json
import statistics
import tomllib
from pathlib import Path
from typing import Any

import pytest

from tdmon.cli import main
from tdmon.record.reader import read_messages

REPO = Path(__file__).resolve().parents[2]
REPLAY = REPO / "replays" / "trip-out-tight-spot.mcap"
CONFIG = REPO / "config" / "daemon" / "replay-sim-trip-out.toml"
WELL = REPO / "replays" / "scenarios" / "wells" / "example-7-1-glydril.toml"


@pytest.fixture(scope="module")
def replayed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """The simulated trip out through the daemon, and the ``tdmon replay --json`` summary."""
    import io
    from contextlib import redirect_stdout

    out = tmp_path_factory.mktemp("replay") / "trip-out.mcap"
    printed = io.StringIO()
    with redirect_stdout(printed):
        code = main(["replay", str(REPLAY), "--config", str(CONFIG), "--out", str(out),
                     "--json", "--no-progress"])
    assert code == 0
    return out, json.loads(printed.getvalue())


def _windows(path: Path) -> list[dict[str, Any]]:
    return [m for _, _, m in read_messages(path, ["/tdmon/estimate"]) if m["kind"] == "window"]


def test_summary_json_carries_the_engineers_numbers(replayed: tuple[Path, dict[str, Any]]
                                                    ) -> None:
    out, summary = replayed
    with open(WELL, "rb") as handle:
        well_name = tomllib.load(handle)["well"]["name"]
    assert summary["well"]["name"] == well_name
    assert summary["well"]["daemon_file"] == CONFIG.name
    assert summary["well"]["backcalc_method"] == "soft-string"
    assert [s["kind"] for s in summary["well"]["sections"]] == ["cased", "open"]
    assert summary["run"]["recordings"] == [str(out)]
    # time and depth ranges: those of the recorded states and model frames
    frames = [m for topic, _, m in read_messages(out, ["/tdmon/state", "/tdmon/model"])]
    times = [m["t"] for m in frames]
    depths = [m["bit_depth_m"] for m in frames if m.get("bit_depth_m") is not None]
    assert summary["time_range"]["first_t"] == min(times)
    assert summary["time_range"]["last_t"] == max(times)
    assert summary["time_range"]["duration_s"] == pytest.approx(25 * 60, abs=2.0)
    assert summary["depth_range_m"] == {"min": round(min(depths), 2),
                                        "max": round(max(depths), 2)}
    # friction per operation and section: the recorded windows' median and spread
    windows = _windows(out)
    pick_up = [w["mu"] for w in windows if w["operation"] == "pick_up"]
    [row] = [r for r in summary["friction"] if r["operation"] == "pick_up"]
    assert row["windows"] == len(pick_up) > 50
    assert row["mu_median"] == round(statistics.median(pick_up), 4)
    assert row["mu_sd"] == round(statistics.stdev(pick_up), 4)
    assert row["section"] == "all"  # the trip stays below the shoe (2500 m): whole string
    # alarms: the warnings first, with their times
    kinds = [(a["severity"], a["kind"]) for a in summary["alarm_summary"]]
    assert kinds[0][0] == "warning" and ("info", "window_rejected") in kinds
    assert sum(a["count"] for a in summary["alarm_summary"]) == sum(summary["alarms"].values())
    # mu(T): 0.2 K of temperature range cannot identify a slope, and says so
    verdict = summary["mu_t"]
    assert verdict["status"] == "not_identifiable"
    low, high = verdict["temperature_range_C"]
    assert high - low < 10.0
    assert verdict["reason"] == (f"the temperature range seen, {high - low:.1f} K, is narrower "
                                 "than the 10 K needed")
    assert verdict["estimates"] == summary["estimates"]["mu_T"]
    # friction and weight together: the simulated string weighs what the well file says
    joint = [m for _, _, m in read_messages(out, ["/tdmon/estimate"]) if m["kind"] == "joint"]
    together = summary["joint"]
    assert together["estimates"] == len(joint) > 20
    assert together["identifiable"] == sum(bool(m["identifiable"]) for m in joint) > 0
    assert together["status"] == "identifiable"
    assert abs(together["weight_factor"] - 1.0) < 0.01
    assert abs(together["weight_factor"] - 1.0) < 3 * together["weight_factor_std"] + 0.002


def test_report_page_names_the_well_and_states_the_friction(
        replayed: tuple[Path, dict[str, Any]], tmp_path: Path) -> None:
    out, summary = replayed
    report = tmp_path / "new" / "report"  # missing parents are created
    assert main(["report", str(out), "--out", str(report)]) == 0
    page = (report / "report.html").read_text()
    assert f"<h1>tdmon post-well report: {summary['well']['name']}</h1>" in page
    assert CONFIG.name in page and "soft string (3D Johancsik" in page
    pick_up = [w["mu"] for w in _windows(out) if w["operation"] == "pick_up"]
    assert (f"Pick-up, whole string: friction factor {statistics.median(pick_up):.3f} "
            f"(median of {len(pick_up)} windows") in page
    assert "mu(T) not identifiable: the temperature range seen" in page
    assert summary["joint"]["words"] in page
    assert "No mu(T) figure." in page and not (report / "mu_T.png").exists()
    # plain words: the top of the string is "at surface", no solver language
    assert "rotating torque at surface is 94 % of the make-up torque limit" in page
    assert "bracket" not in page and "at 0 m" not in page
    # the torque figure leaves the non-rotating (zero-torque) frames out and says so
    states = sorted((m["t"], m["state"]) for _, _, m in read_messages(out, ["/tdmon/state"]))
    models = [m for _, _, m in read_messages(out, ["/tdmon/model"])
              if m["measured"].get("torque_Nm") is not None]
    rotating = 0
    for model in models:
        state = max(((t, s) for t, s in states if t <= model["t"]), default=(0, "unknown"))[1]
        rotating += state in ("rotating_off_bottom", "reaming", "back_reaming", "drilling") and (
            model["measured"]["torque_Nm"] > 0.0)
    assert 0 < rotating < len(models) / 5
    assert f"of rotating samples only ({rotating} of {len(models)} model frames" in page
    # summary.json beside the page: the same numbers as tdmon replay --json
    written = json.loads((report / "summary.json").read_text())
    for key in ("well", "time_range", "depth_range_m", "friction", "alarm_summary", "mu_t",
                "joint"):
        assert written[key] == summary[key], key


def test_summarize_recording_adds_the_same_numbers(replayed: tuple[Path, dict[str, Any]]
                                                   ) -> None:
    """The demo's summary of a live daemon's recording: the replay's counts and the same
    engineer's numbers as ``tdmon replay --json``."""
    from tdmon.replay.driver import summarize_recording

    out, summary = replayed
    recorded = summarize_recording(out)
    assert recorded["windows"] == summary["windows"] and recorded["alarms"] == summary["alarms"]
    for key in ("well", "time_range", "depth_range_m", "friction", "alarm_summary", "mu_t",
                "joint"):
        assert recorded[key] == summary[key], key


def test_well_message_context_meets_its_schema(replayed: tuple[Path, dict[str, Any]]) -> None:
    import jsonschema

    from tdmon.record.schemas import WELL

    out, _ = replayed
    [well] = [m for _, _, m in read_messages(out, ["/tdmon/well"])]
    jsonschema.validate(well, WELL)
    assert well["sections"][0] == {"name": "9-5/8 in casing", "kind": "cased", "top_m": 0.0,
                                   "bottom_m": 2500.0, "friction": "mu = 0.18 + 0.001 T"}
    assert well["mu_t_mode"] == "family" and well["mu_t_law"] == "mu = 0.23 + 0.0013 T"
    # a section without its required keys is refused: the schema is not a blank cheque
    broken = {**well, "sections": [{"kind": "cased"}]}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(broken, WELL)
