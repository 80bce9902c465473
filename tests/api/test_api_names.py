"""The API's names: exported, cheap to import, ``tdmon.replay`` callable while its modules stay
importable, mistakes as TdmonError."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
from pathlib import Path

import pytest

import tdmon
from tdmon.errors import IngestError, ModelError, RecordError

REPO = Path(__file__).resolve().parents[2]
WELL = REPO / "replays" / "scenarios" / "wells" / "example-7-1-glydril.toml"


def test_import_tdmon_loads_no_heavy_library() -> None:
    code = ("import sys, json, tdmon\n"
            "heavy = ('pandas', 'numpy', 'numba', 'distributed', 'pydantic', 'tdmon.api')\n"
            "before = [m for m in heavy if m in sys.modules]\n"
            "tdmon.read_recording, tdmon.replay, tdmon.batch, tdmon.load_well\n"
            "after = [m for m in heavy if m in sys.modules]\n"
            "print(json.dumps([before, after]))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, cwd=REPO, env={"PYTHONPATH": str(REPO)})
    before, after = json.loads(done.stdout)
    assert before == []
    assert after == ["tdmon.api"]  # the names resolved, still no pandas, numba or Dask


def test_all_names_resolve() -> None:
    assert set(tdmon.__all__) == {"Recording", "WellFile", "__version__", "batch",
                                  "evaluate_loads", "load_well", "read_recording", "replay"}
    for name in tdmon.__all__:
        assert getattr(tdmon, name) is not None
    assert set(tdmon.__all__) <= set(dir(tdmon))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        _ = tdmon.nope  # type: ignore[attr-defined]


def test_replay_is_callable_and_a_package_at_once(tmp_path: Path) -> None:
    import tdmon.replay.driver  # sets the package as tdmon.replay, as any import of it does

    assert callable(tdmon.replay)
    assert tdmon.replay.driver.replay is not None  # type: ignore[attr-defined]
    with pytest.raises(IngestError, match=r"none\.mcap: replay not found"):
        tdmon.replay(tmp_path / "none.mcap", tmp_path / "out.mcap")


def test_read_recording_refuses_what_is_not_a_recording(tmp_path: Path) -> None:
    text = tmp_path / "x.mcap"
    text.write_text("time,hookload\n")
    with pytest.raises(RecordError, match=r"x\.mcap"):
        tdmon.read_recording(text)
    with pytest.raises(RecordError, match="as a list"):
        tdmon.read_recording(REPO / "replays" / "trip-in-noisy.mcap",
                             topics="/tdmon/raw")  # type: ignore[arg-type]


def test_read_only_some_topics() -> None:
    recording = tdmon.read_recording(REPO / "replays" / "trip-in-noisy.mcap",
                                     topics=["/truth/state"])
    assert recording.raw.empty and recording.counts["/tdmon/raw"] == 965
    assert recording.topics == ("/truth/state",)
    assert len(recording["/truth/state"]) == recording.counts["/truth/state"]


def test_evaluate_loads_mistakes_and_shapes() -> None:
    well = tdmon.load_well(WELL)
    with pytest.raises(ModelError, match="unknown operation 'pickup'"):
        tdmon.evaluate_loads(well, 3000.0, operation="pickup")
    with pytest.raises(ModelError):
        tdmon.evaluate_loads(well, 99_000.0)
    table = tdmon.evaluate_loads(well.model, [3000.0, 4000.0], mu=0.2)  # a bare Well
    assert len(table) == 2 * 5 and set(table["operation"]) == {
        "static", "rotating", "pick_up", "slack_off", "on_bottom"}
    # pick-up above static above slack-off, at each depth in the inclined hole
    wide = table.pivot(index="bit_depth_m", columns="operation", values="hookload_N")
    assert ((wide["pick_up"] > wide["static"]) & (wide["static"] > wide["slack_off"])).all()


def test_replay_from_inside_a_running_event_loop(tmp_path: Path) -> None:
    # as in a notebook: asyncio.run would refuse to nest, so the replay gets a thread of its own
    async def notebook_cell() -> object:
        return tdmon.replay(REPO / "replays" / "trip-in-noisy.mcap", tmp_path / "out.mcap",
                            recorder="inline")

    result = asyncio.run(notebook_cell())
    assert result.messages_in == 965  # type: ignore[attr-defined]
    assert tdmon.read_recording(tmp_path / "out.mcap").counts["/tdmon/raw"] == 965
