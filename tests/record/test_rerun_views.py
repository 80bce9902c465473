"""Rerun views: a real .rrd built from a real MCAP recording, read back with RrdReader."""

from __future__ import annotations

import socket
from collections import defaultdict
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from tdmon.cli import main
from tdmon.errors import RecordError
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import RecordedMessage, read_messages
from tdmon.record.rerun_views import RerunViews, build_rrd


@pytest.fixture(autouse=True)
def strict_rerun() -> Iterator[None]:
    """Invalid archetype arguments raise instead of only warning."""
    import rerun as rr

    rr.set_strict_mode(True)
    yield
    rr.set_strict_mode(False)


def _rows(path: Path) -> tuple[dict[str, int], dict[str, set[str]]]:
    reader = RrdReader(path)
    [recording] = reader.recordings()
    assert recording.application_id == "tdmon"
    assert len(reader.blueprints()) == 1
    rows: dict[str, int] = defaultdict(int)
    timelines: dict[str, set[str]] = defaultdict(set)
    for chunk in reader.stream().to_chunks():
        if chunk.is_static:
            timelines[chunk.entity_path].add("static")
            continue
        rows[chunk.entity_path] += chunk.num_rows
        timelines[chunk.entity_path].update(chunk.timeline_names)
    return dict(rows), dict(timelines)


def _count(stream: list[RecordedMessage], topic: str, **match: object) -> int:
    return sum(
        1 for m in stream if m.topic == topic and all(m.message.get(k) == v
                                                      for k, v in match.items())
    )


def test_views_from_a_flight_recording(tmp_path: Path, stream: list[RecordedMessage]) -> None:
    with McapRecorder(tmp_path / "rec") as recorder:
        for item in stream:
            recorder.write(*item)
    [mcap] = recorder.stats.files
    rrd = tmp_path / "views.rrd"
    assert main(["view", str(mcap), "--rrd", str(rrd), "--no-progress"]) == 0
    rows, timelines = _rows(rrd)

    models = _count(stream, "/tdmon/model")
    windows = _count(stream, "/tdmon/estimate", kind="window")
    pick_up_windows = _count(stream, "/tdmon/estimate", kind="window", operation="pick_up")
    for entity in ("hookload_kN/measured", "hookload_kN/model/pick_up",
                   "hookload_kN/band/pick_up_mu_0_20", "torque_kNm/measured",
                   "torque_kNm/model/rotating"):
        assert rows[f"/{entity}"] == models, entity
        assert timelines[f"/{entity}"] == {"time", "static"}
        assert rows[f"/vs_depth/{entity}"] == models
        assert timelines[f"/vs_depth/{entity}"] == {"bit_depth_cm", "static"}
    assert rows["/friction/pick_up"] == pick_up_windows
    assert rows["/friction/pick_up"] + rows["/friction/slack_off"] == windows
    assert rows["/alarms"] == _count(stream, "/tdmon/alarm")
    assert rows["/rejected"] == _count(stream, "/tdmon/rejected")
    assert rows["/rig_state"] == 2  # one trip out, one trip in: two state changes
    assert rows["/samples/hookload"] == _count(stream, "/tdmon/sample", channel="hookload")
    # Profiles: one /tdmon/profile message plus one profile estimate.
    assert rows["/profile/friction"] == 2
    assert rows["/profile/temperature_C"] == 1
    assert timelines["/well/trajectory"] == {"static"}
    assert rows["/well/friction"] == 2
    assert rows["/well/string"] >= 1 and rows["/well/bit"] == rows["/well/string"]


def test_sink_survives_bad_messages_and_needs_a_target(tmp_path: Path) -> None:
    with pytest.raises(RecordError):
        RerunViews()
    views = RerunViews(tmp_path / "bad.rrd")
    views.write("/tdmon/model", 1, {"t": 1.0})  # nothing usable but no crash
    views.write("/tdmon/alarm", 2, {"t": 1.0})  # missing fields: skipped, counted
    views.write("/tdmon/unknown", 3, {})
    views.close()
    views.close()
    assert views.stats.skipped == 2
    rows, _ = _rows(tmp_path / "bad.rrd")
    assert "/alarms" not in rows


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def test_live_viewer_server_binds_loopback_only(tmp_path: Path) -> None:
    port = _free_port()
    stats = build_rrd(
        [("/tdmon/alarm", 1, {"t": 1.0, "kind": "k", "severity": "info", "message": "m"})],
        tmp_path / "a.rrd",
    )
    assert stats.logged == 1
    views = RerunViews(live_port=port)
    try:
        assert views.grpc_uri is not None and "127.0.0.1" in views.grpc_uri
        with socket.create_connection(("127.0.0.1", port), timeout=5):
            pass
        import psutil

        listening = [c.laddr for c in psutil.net_connections("tcp")
                     if c.status == psutil.CONN_LISTEN and c.laddr.port == port]
        assert listening and all(addr.ip == "127.0.0.1" for addr in listening)
    finally:
        views.close()


def test_reading_back_the_same_messages(tmp_path: Path, stream: list[RecordedMessage]) -> None:
    with McapRecorder(tmp_path) as recorder:
        for item in stream[:200]:
            recorder.write(*item)
    stats = build_rrd(read_messages(recorder.stats.files[0]), tmp_path / "b.rrd")
    assert stats.messages == 200


def test_rerun_is_imported_lazily(run_child: Callable[..., dict[str, object]]) -> None:
    result = run_child(
        "import json, sys\n"
        "import tdmon.cli, tdmon.record.rerun_views, tdmon.record.mcap_recorder\n"
        "tdmon.cli.build_parser()\n"
        "print(json.dumps({'rerun': 'rerun' in sys.modules}))\n"
    )
    assert result == {"rerun": False}


def test_live_views_leave_the_users_rerun_settings_alone(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    # `rerun analytics disable` writes <config>/rerun/analytics.json: a live sink must not
    home, config = tmp_path / "home", tmp_path / "config"
    home.mkdir()
    config.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(config))
    views = RerunViews(tmp_path / "live.rrd", live_port=_free_port())
    views.close()
    assert (tmp_path / "live.rrd").stat().st_size > 0
    assert sorted(p.name for p in config.rglob("*")) == []
    assert sorted(p.name for p in home.rglob("*")) == []


def test_uninformed_profile_bins_are_left_out_and_explained(tmp_path: Path) -> None:
    # the middle point is informed; the others still hold the prior (0.30, 0.31)
    message = {"t": 1.0, "md_m": [100.0, 200.0, 300.0], "mu": [0.30, 0.25, 0.31],
               "mu_std": [0.1, 0.02, 0.1], "variance_ratio": [1.0, 0.04, 1.0],
               "informed": [False, True, False],
               "uninformed_reason": ["no side force", None, "no window reached this depth"]}
    path = tmp_path / "profile.rrd"
    build_rrd([("/tdmon/profile", 1, message)], path)
    values: dict[str, object] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        batch = chunk.to_record_batch()
        for name in ("BarChart:values", "TextDocument:text"):
            if name in batch.schema.names:
                values[chunk.entity_path] = batch.column(name).to_pylist()[0][0]
    bars = values["/profile/friction"]
    assert isinstance(bars, dict) and bars["buffer"] == [0.0, 0.25, 0.0]
    assert values["/profile/note"] == (
        "Local friction: 1 of 3 points informed (variance ratio < 0.5); not informed: "
        "100 m no side force; 300 m no window reached this depth")


def _view_origins(path: Path) -> set[str]:
    reader = RrdReader(path)
    origins: set[str] = set()
    for chunk in reader.stream(store=reader.blueprints()[0]).to_chunks():
        batch = chunk.to_record_batch()
        for column in batch.schema.names:
            if column.endswith(":space_origin"):
                origins.update(str(v[0]) for v in batch.column(column).to_pylist() if v)
    return origins


def test_every_logged_entity_has_a_view(tmp_path: Path,
                                         stream: list[RecordedMessage]) -> None:
    extra = [("/tdmon/estimate", 10**18, {"t": 1e9, "kind": "mu_T", "operation": "pick_up",
                                          "mu": 0.2, "mu_std": 0.01, "model": "linear",
                                          "params": {"mu_0": 0.2, "slope_per_K": 0.001}}),
             ("/tdmon/status", 10**18, {"t": 1e9, "samples_in": 10, "rejected": 0,
                                        "dropped": 0, "lag_s": 0.1, "connections": {}})]
    rrd = tmp_path / "all.rrd"
    stats = build_rrd([*stream, *extra], rrd)
    origins = _view_origins(rrd)
    assert {"/friction_mu_T", "/bit_depth_m", "/rig_state"} <= origins
    rows, _ = _rows(rrd)
    logged = set(rows) | {f"/{e}" for e in stats.entities}
    assert "/friction_mu_T/slope_per_K" in logged and "/bit_depth_m" in logged
    # an entity is shown when a view's origin is it or one of its parents
    unseen = sorted(entity for entity in logged if not any(
        entity == origin or entity.startswith(origin.rstrip("/") + "/") for origin in origins))
    assert unseen == []
