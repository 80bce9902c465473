"""The worked example of docs/api.md, run as it stands, and its numbers checked.

Its ``python`` blocks are executed in order in one namespace (``__name__ == "__main__"``, so
the batch block runs) from a folder that links the repository's ``replays`` and ``config``.
The checks: the DataFrames hold exactly the MCAP file's messages, the window friction is near
the simulation's truth and the expectations' range, the loads are the command line's figures,
the batch reports the missing file and finishes the other.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Any

import pytest

from tdmon.cli import main
from tdmon.record.reader import read_messages, topic_counts

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "api.md"


def _blocks() -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", DOC.read_text(), flags=re.S | re.M)


@pytest.fixture(scope="module")
def example(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    folder = tmp_path_factory.mktemp("api-example")
    for name in ("replays", "config"):
        (folder / name).symlink_to(REPO / name)
    namespace: dict[str, Any] = {"__name__": "__main__"}
    cwd = Path.cwd()
    os.chdir(folder)
    try:
        for block in _blocks():
            exec(compile(block, str(DOC), "exec"), namespace)
    finally:
        os.chdir(cwd)
    namespace["folder"] = folder
    return namespace


def test_the_doc_has_the_five_parts() -> None:
    text = "\n".join(_blocks())
    for call in ("tdmon.replay(", "tdmon.read_recording(", "tdmon.load_well(",
                 "tdmon.evaluate_loads(", "tdmon.batch("):
        assert call in text


def test_frames_hold_every_message_of_the_recording(example: dict[str, Any]) -> None:
    recording = example["recording"]
    counts = topic_counts(example["folder"] / "out" / "trip-out.mcap")
    assert dict(recording.counts) == counts
    for topic, count in counts.items():
        assert len(recording[topic]) == count, topic
    assert counts["/tdmon/sample"] == example["result"].samples == 7700
    first = next(read_messages(example["folder"] / recording.path, "/tdmon/estimate")).message
    row = recording.estimates.iloc[0]
    assert (row["kind"], row["mu"], row["t"]) == (first["kind"], first["mu"], first["t"])
    assert row["time"].timestamp() == pytest.approx(first["t"], abs=1e-6)


def test_window_friction_near_the_truth_and_the_expectations(example: dict[str, Any]) -> None:
    # replays/expectations/trip-out-tight-spot.toml: pick-up windows within 0.02 (median) of
    # /truth/friction, and 0.26-0.30 below the anomaly (4110-4230 m)
    assert example["error"].median() < 0.02
    assert len(example["windows"]) >= 50
    assert 0.26 <= example["below_anomaly"]["mu"].mean() <= 0.30
    kinds = set(example["recording"].alarms["kind"])
    assert {"friction_jump", "limit_makeup_torque"} <= kinds


def _cli_loads(capsys: pytest.CaptureFixture[str], *extra: str) -> dict[str, Any]:
    well = REPO / "replays" / "scenarios" / "wells" / "example-7-1-glydril.toml"
    capsys.readouterr()
    assert main(["model", "loads", "--well", str(well), "--json", *extra]) == 0
    return json.loads(capsys.readouterr().out)  # type: ignore[no-any-return]


def test_loads_are_the_command_lines(example: dict[str, Any],
                                     capsys: pytest.CaptureFixture[str]) -> None:
    at_4000 = example["at_4000"].set_index("operation")
    cli = _cli_loads(capsys, "--bit-depth", "4000", "--mu", "0.25")
    for operation, hookload in cli["hookload_N"].items():
        assert at_4000.loc[operation, "hookload_N"] == pytest.approx(hookload, rel=1e-12)
    assert at_4000.loc["rotating", "surface_torque_Nm"] == pytest.approx(
        cli["torque_Nm"]["rotating"], rel=1e-12)
    loads = example["loads"].set_index("bit_depth_m")
    for depth in (2000, 3000, 4000):  # the well file's own friction, mu(T) per section
        cli = _cli_loads(capsys, "--bit-depth", str(depth))
        assert loads.loc[float(depth), "hookload_N"] == pytest.approx(
            cli["hookload_N"]["pick_up"], rel=1e-12)
    assert list(loads["operation"].unique()) == ["pick_up"]


def test_batch_reports_the_missing_file(example: dict[str, Any]) -> None:
    ok, missing = example["done"].outcomes
    assert ok.ok and ok.messages_in == 965
    assert missing.error is not None and "replay not found" in missing.error
    well = example["tables"]["friction"].query("level == 'well'")
    assert well["n"].sum() == sum(1 for w in ok.windows if not w["low_confidence"])
    assert (example["folder"] / "out" / "batch" / "summary.html").is_file()
