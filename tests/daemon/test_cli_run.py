"""``tdmon run`` and ``tdmon publish`` as a user runs them: real processes, real signals."""

from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import paho.mqtt.client as mqtt
import pytest
import zenoh

from tdmon.cli import main

ROOT = Path(__file__).resolve().parents[2]
VOLVE_HEADER = ("time_utc,hole_depth_m,bit_depth_m,hookload_kN,surface_torque_kNm,surface_rpm,"
                "bit_rpm,flow_in_Lpm,flow_out_Lpm,spp_bar,wob_kN,rop_mph,rig_activity_code,"
                "block_pos_comp_m,block_pos_uncomp_m,rig_heave_m,bit_depth_5s_m")


@pytest.fixture
def volve_csv(tmp_path: Path) -> Path:
    """100 rows in the layout of the Volve F-4 logs (data/volve-f4): 9 mapped
    channels each, a pull of 0.5 m per 15 s row."""
    rows = [VOLVE_HEADER]
    for i in range(100):
        minute, second = divmod(15 * i, 60)
        hour, minute = divmod(minute, 60)
        rows.append(f"2016-10-04T{17 + hour:02d}:{minute:02d}:{second:02d}Z,3510,"
                    f"{2500 - 0.5 * i:.1f},{1600 + i % 5},0.0052,0.23,0.23,0,36,-0.4,5.4,0,7,"
                    f"{12 + 0.5 * (i % 20):.1f},12.8,-0.08,2500")
    path = tmp_path / "volve-layout.csv"
    path.write_text("\n".join(rows) + "\n")
    return path
TDMON = [sys.executable, "-m", "tdmon"]


def _zenoh_config(folder: Path, port: int, extra: str = "") -> Path:
    path = folder / "daemon.toml"
    path.write_text(f"""
prefix = "rig/F4"
well = "{ROOT / 'config/wells/volve-f4.toml'}"
[sources.zenoh]
listen = ["tcp/127.0.0.1:{port}"]
[channels.hookload]
unit = "kN"
[publish]
zenoh = true
[rig_state]
in_slips_hookload = "800 kN"
{extra}
""")
    return path


def _wait_for(path: Path, text: str, timeout: float = 20) -> None:
    deadline = time.monotonic() + timeout
    while text not in path.read_text():
        assert time.monotonic() < deadline, f"'{text}' never appeared: {path.read_text()}"
        time.sleep(0.05)


def _until(predicate: Callable[[], bool], what: str, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


@contextlib.contextmanager
def _zenoh_status(port: int) -> Iterator[dict[str, Any]]:
    """The latest ``status`` the daemon listening on ``port`` published (rig/F4)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    session = zenoh.open(conf)
    latest: dict[str, Any] = {}
    subscriber = session.declare_subscriber(
        "rig/F4/tdmon/status", lambda s: latest.update(json.loads(s.payload.to_bytes())))
    try:
        yield latest
    finally:
        subscriber.undeclare()
        session.close()


@contextlib.contextmanager
def _mqtt_status(port: int) -> Iterator[dict[str, Any]]:
    """The latest ``status`` the daemon published on the broker at ``port`` (rig/F4)."""
    latest: dict[str, Any] = {}
    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="status-watch")
    client.on_connect = lambda c, *_: c.subscribe("rig/F4/tdmon/status", qos=0)
    client.on_message = lambda _c, _u, m: latest.update(json.loads(m.payload))
    client.connect("127.0.0.1", port)
    client.loop_start()
    try:
        yield latest
    finally:
        client.loop_stop()
        client.disconnect()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_run_publish_and_stop_with_a_signal(tmp_path: Path, sig: signal.Signals,
                                            free_tcp_port: Callable[[], int],
                                            volve_csv: Path) -> None:
    port = free_tcp_port()
    config = _zenoh_config(tmp_path, port, f"""
[recorder]
enabled = true
output = "{tmp_path / 'rec'}"
""")
    log = tmp_path / "daemon.log"
    with log.open("w") as err:
        daemon = subprocess.Popen([*TDMON, "run", "--config", str(config)],
                                  stderr=err, stdout=subprocess.DEVNULL)
        try:
            _wait_for(log, "daemon running")
            with _zenoh_status(port) as status:
                published = subprocess.run(
                    [*TDMON, "publish", str(volve_csv), "--config", str(config), "--limit",
                     "900"], capture_output=True, text=True, timeout=60)
                assert published.returncode == 0, published.stderr
                assert "published 900 messages" in published.stderr
                # the daemon has them all (was: a 0.5 s pause)
                _until(lambda: status.get("samples_in") == 900, "900 samples counted")
            daemon.send_signal(sig)
            assert daemon.wait(30) == 0, log.read_text()
        finally:
            if daemon.poll() is None:
                daemon.kill()
    text = log.read_text()
    assert "stopped: 900 samples, 0 rejected, 0 dropped" in text
    assert "Traceback" not in text
    recordings = list((tmp_path / "rec").glob("*.mcap"))
    assert recordings, "the recorder wrote nothing"
    from tdmon.record.reader import read_messages

    samples = [m for path in recordings for m in read_messages(path)
               if m.topic == "/tdmon/sample"]
    assert len(samples) == 900  # finished and flushed on the signal


def test_publish_over_mqtt_to_the_daemon(mosquitto: Any, tmp_path: Path,
                                         volve_csv: Path) -> None:
    config = tmp_path / "mqtt.toml"
    config.write_text(f"""
prefix = "rig/F4"
[sources.mqtt]
port = {mosquitto.port}
client_id = "tdmon-cli"
[publish]
mqtt = true
""")
    log = tmp_path / "daemon.log"
    with log.open("w") as err, _mqtt_status(mosquitto.port) as status:
        daemon = subprocess.Popen([*TDMON, "run", "--config", str(config)], stderr=err)
        try:
            _wait_for(log, "daemon running")
            # subscribed (was: a 0.5 s pause), then every sample counted (was: 1 s)
            _until(lambda: status.get("connections", {}).get("mqtt") == "connected",
                   "the daemon's subscription")
            published = subprocess.run(
                [*TDMON, "publish", str(volve_csv), "--mqtt", f"127.0.0.1:{mosquitto.port}",
                 "--prefix", "rig/F4", "--limit", "500", "--speed", "max"],
                capture_output=True, text=True, timeout=60)
            assert published.returncode == 0, published.stderr
            _until(lambda: status.get("samples_in") == 500, "500 samples counted")
            daemon.send_signal(signal.SIGTERM)
            assert daemon.wait(30) == 0
        finally:
            if daemon.poll() is None:
                daemon.kill()
    assert "stopped: 500 samples, 0 rejected, 0 dropped" in log.read_text()


@pytest.mark.parametrize(("body", "expected"), [
    ('prefix = "rig/F4"\n[sources.zenoh]\nlisten = ["tcp/127.0.0.1:1"]\nbogus = 1\n',
     "bogus: unknown key"),
    ('prefix = "rig/F4"\n[sources.mqtt]\nport = 99999\n', "sources.mqtt.port"),
    ('prefix = "rig/F4"\n[sources.mqtt]\n[channels.hookload]\nunit = "blorp"\n',
     "channels.hookload.unit: unknown unit 'blorp'"),
    ('prefix = "rig/F4"\n[sources.mqtt]\n[align]\nstale_timeout = "5 kg"\n',
     "align.stale_timeout"),
    ('prefix = "rig/F4"\nwell = "nowhere.toml"\n[sources.mqtt]\n', "well: file not found"),
    ('prefix = "rig/F4"\n[sources]\n', "sources: configure at least one source"),
    ('prefix = "rig/F4"\n[sources.mqtt\n', "not valid TOML"),
    ('prefix = "rig/F4"\n[sources.mqtt]\n[channels.weather]\n', "unknown channel 'weather'"),
])
def test_config_mistakes_are_one_line_and_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], body: str, expected: str) -> None:
    config = tmp_path / "bad.toml"
    config.write_text(body)
    assert main(["run", "--config", str(config)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert str(config) in err and expected in err, err


def test_missing_config_file(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "--config", "/nonexistent/d.toml"]) == 2
    assert "no such file" in capsys.readouterr().err


def test_publish_mistakes(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                          free_tcp_port: Callable[[], int], volve_csv: Path) -> None:
    assert main(["publish", str(volve_csv)]) == 2
    assert "say where to publish" in capsys.readouterr().err
    assert main(["publish", str(volve_csv), "--mqtt", "127.0.0.1:1", "--columns", "x=y:kN"]) == 2
    assert "unknown channel 'x'" in capsys.readouterr().err
    port = free_tcp_port()  # nothing listens there
    assert main(["publish", str(volve_csv), "--mqtt", f"127.0.0.1:{port}", "--limit", "1"]) == 2
    assert "cannot connect" in capsys.readouterr().err


def test_shipped_configs_are_valid() -> None:
    from tdmon.config.daemon import load_daemon_config

    for name in ("zenoh-local.toml", "mqtt-local.toml"):
        config = load_daemon_config(ROOT / "config" / "daemon" / name)
        assert config.well is not None and config.resolve(config.well).exists()
    zenoh = load_daemon_config(ROOT / "config/daemon/zenoh-local.toml").sources.zenoh
    assert zenoh is not None and zenoh.mode == "peer" and not zenoh.scouting
    assert all("127.0.0.1" in endpoint for endpoint in zenoh.listen)
