"""Sources and sinks from the builder tables; the checks across sections as config errors."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from daemon_support import CollectSink, linear_model, make_config

from tdmon.config.daemon import (
    DaemonConfig,
    McapSourceConfig,
    PublishConfig,
    SourcesConfig,
    ZenohConfig,
)
from tdmon.daemon.build import build_daemon
from tdmon.daemon.daemon import SourceSpec
from tdmon.daemon.pipeline import Stats
from tdmon.daemon.sinks import PUBLISHERS, SINKS, usable_cores
from tdmon.daemon.sources import SOURCES
from tdmon.daemon.wiring import Entry, Table, Wiring, wire
from tdmon.errors import ConfigError, IngestError
from tdmon.ingest.mcap_source import McapSource
from tdmon.ingest.mqtt import MqttPublisher
from tdmon.ingest.zenoh_io import ZenohPublisher, ZenohSource
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import is_finished
from tdmon.record.writer_process import RecorderProcess

MCAP = {"mcap": {"path": "replay.mcap"}}
MQTT = {"mqtt": {"host": "127.0.0.1", "port": 1883, "client_id": "t"}}


@pytest.mark.parametrize(("data", "key", "reason"), [
    ({"sources": MCAP, "publish": {"zenoh": True}},
     "publish.zenoh", "true needs [sources.zenoh]; give a table with endpoints"),
    ({"sources": MCAP, "publish": {"mqtt": True}},
     "publish.mqtt", "true needs [sources.mqtt]; give a table with the broker"),
    ({"sources": MCAP, "rerun": {"mode": "file"}},
     "rerun.path", "mode 'file' needs a path for the .rrd file"),
])
def test_checks_across_sections_name_file_key_and_reason(
        tmp_path: Path, data: dict[str, Any], key: str, reason: str) -> None:
    with pytest.raises(ConfigError) as caught:
        make_config(data, tmp_path)
    assert (caught.value.file, caught.value.key, caught.value.reason) == (
        str(tmp_path / "test-daemon.toml"), key, reason)
    assert str(caught.value) == f"{tmp_path / 'test-daemon.toml'}: {key}: {reason}"


def test_what_the_checks_allow(tmp_path: Path) -> None:
    config = make_config({"sources": MQTT, "publish": {"mqtt": True},
                          "rerun": {"mode": "live"}}, tmp_path)
    assert config.publish.mqtt is True and config.rerun.path is None
    config = make_config({"sources": MCAP, "publish": {"mqtt": MQTT["mqtt"]},
                          "rerun": {"mode": "file", "path": "views.rrd"}}, tmp_path)
    assert config.rerun.path == Path("views.rrd")


def test_every_config_section_has_a_row() -> None:
    # a section added to the config without a builder would be silently ignored
    assert list(SOURCES) == ["zenoh", "mqtt", "mcap", "wits0", "opcua"]  # the start order
    assert set(SOURCES) == set(SourcesConfig.model_fields)
    assert set(PUBLISHERS) == {"mqtt", "zenoh"} <= set(PublishConfig.model_fields)
    assert list(SINKS) == ["recorder", "rerun"]
    assert set(SINKS) <= set(DaemonConfig.model_fields)


@pytest.mark.parametrize(("process", "cores", "expected"), [
    ("auto", {0}, McapRecorder), ("auto", {0, 1}, RecorderProcess),
    ("child", {0}, RecorderProcess), ("inline", {0, 1, 2, 3}, McapRecorder)])
async def test_where_the_recorder_writes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                         process: str, cores: set[int],
                                         expected: type) -> None:
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: cores)
    config = make_config({"sources": MCAP, "recorder": {
        "enabled": True, "output": "recordings", "process": process}}, tmp_path)
    async with build_daemon(config, model=linear_model()) as built:
        [recorder] = built.sinks
        assert type(recorder) is expected
        assert recorder.folder == tmp_path / "recordings"
        built.pipeline.close_sinks()
    assert [p.suffix for p in (tmp_path / "recordings").iterdir()] == [".mcap"]


async def test_sources_and_sinks_in_table_order(tmp_path: Path) -> None:
    config = make_config({"sources": {**MQTT, **MCAP}, "publish": {"mqtt": True},
                          "recorder": {"enabled": True, "output": "recordings"}}, tmp_path)
    probe = CollectSink()
    async with build_daemon(config, model=linear_model(), extra_sinks=[probe]) as built:
        daemon = built.daemon
        recorder, caller, publisher = built.sinks
        # [recorder] process = "auto": in a child process where two cores are free
        assert isinstance(recorder, RecorderProcess if usable_cores() > 1 else McapRecorder)
        assert recorder.folder == tmp_path / "recordings"
        assert caller is probe
        assert isinstance(publisher, MqttPublisher)
        assert publisher.config is config.sources.mqtt  # publish.mqtt = true: the source's
        assert daemon.publishers == [publisher]
        assert [(s.name, s.finite) for s in daemon.sources] == [("mqtt", False), ("mcap", True)]
        assert not daemon.stop_when_sources_done  # the MQTT source never ends
        replay = daemon.sources[1].open()
        assert isinstance(replay, McapSource)
        assert replay.path == tmp_path / "replay.mcap" and replay.speed is None
        built.pipeline.close_sinks()
    assert is_finished(recorder.stats.files[0])


async def test_publish_zenoh_true_shares_the_sources_session(
        tmp_path: Path, free_tcp_port: Any) -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    shared = make_config({"sources": {"zenoh": {"listen": [endpoint]}},
                          "publish": {"zenoh": True}}, tmp_path)
    own = make_config({"sources": {"zenoh": {"listen": [endpoint]}},
                       "publish": {"zenoh": {"connect": [endpoint]}}}, tmp_path)
    for config, same in ((shared, True), (own, False)):
        async with build_daemon(config, model=linear_model()) as built:
            source = built.daemon.sources[0].open()
            (publisher,) = built.sinks
            assert isinstance(source, ZenohSource) and isinstance(publisher, ZenohPublisher)
            assert (source.session is publisher.session) is same
            assert built.daemon.publishers == []  # zenoh needs no supervised connection


async def test_a_failed_build_finishes_the_recording(tmp_path: Path) -> None:
    config = make_config({"sources": {"zenoh": {"listen": ["tcp/256.1.1.1:7447"]}},
                          "recorder": {"enabled": True, "output": "recordings"}}, tmp_path)
    with pytest.raises(IngestError, match="cannot open session"):
        async with build_daemon(config, model=linear_model()):
            pytest.fail("built a daemon on an unusable endpoint")
    (recording,) = (tmp_path / "recordings").glob("*.mcap")
    assert is_finished(recording)


async def test_a_new_source_is_one_row(tmp_path: Path) -> None:
    config = make_config({"sources": MCAP}, tmp_path)

    async def tagged(wiring: Wiring, section: McapSourceConfig) -> None:
        path = wiring.config.resolve(section.path)
        wiring.sources.append(SourceSpec(f"tagged {path.name}", lambda: McapSource(path)))

    async def never(wiring: Wiring, section: ZenohConfig) -> None:
        raise AssertionError("built a section that is not configured")

    table: Table = {"tagged": Entry(lambda c: c.sources.mcap, tagged),
             "absent": Entry(lambda c: c.sources.zenoh, never)}
    wiring = Wiring(config, Stats())
    await wire(table, wiring)
    assert [spec.name for spec in wiring.sources] == ["tagged replay.mcap"]
    assert wiring.sinks == [] and wiring.connected == []
