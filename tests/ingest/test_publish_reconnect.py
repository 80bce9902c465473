"""``tdmon publish`` as a rig runs it, against a real mosquitto: it rides out a broker restart
(reconnects, sends the unacknowledged messages again, in order, and finishes), stops cleanly
on ``kill -INT`` even when started with SIGINT ignored (a background job), and takes its
password from a file or the environment."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import paho.mqtt.client as mqtt
import pytest

from tdmon.cli.run import read_password_file
from tdmon.errors import TdmonError

TDMON = [sys.executable, "-m", "tdmon"]


def _csv(folder: Path, rows: int, step: float) -> Path:
    path = folder / "rig.csv"
    path.write_text("TIME,HKLD\n" + "".join(f"{1.7e9 + i * step:.3f},{i}\n"
                                            for i in range(rows)))
    return path


def _publish_cmd(csv: Path, port: int, *extra: str) -> list[str]:
    return [*TDMON, "publish", str(csv), "--mqtt", f"127.0.0.1:{port}", "--prefix", "rig/P1",
            "--columns", "hookload=HKLD:kN", "--time-column", "TIME", *extra]


class Subscriber:
    """A persistent QoS 1 session on rig/P1/#, keeping every payload in arrival order (paho
    reconnects it by itself after a broker restart)."""

    def __init__(self, port: int) -> None:
        self.values: list[float] = []
        self._lock = threading.Lock()
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="rig-watch",
                                  clean_session=False)
        self.subscribed = threading.Event()
        self.client.on_connect = lambda c, *_: c.subscribe("rig/P1/#", qos=1)
        self.client.on_subscribe = lambda *_: self.subscribed.set()
        self.client.on_message = self._on_message
        self.client.reconnect_delay_set(0.1, 1)
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()
        # the subscription is in place: the broker's SUBACK came (was: a 0.3 s pause)
        assert self.subscribed.wait(60), "no SUBACK from the broker"

    def _on_message(self, _c: Any, _u: Any, message: mqtt.MQTTMessage) -> None:
        with self._lock:
            self.values.append(json.loads(message.payload)["value"])

    def snapshot(self) -> list[float]:
        with self._lock:
            return list(self.values)

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()


def _wait(predicate: Any, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def test_publish_rides_out_a_broker_restart(mosquitto: Any, tmp_path: Path) -> None:
    rows = 120
    csv = _csv(tmp_path, rows, 0.05)  # 20 messages/s at --speed 1: 6 s
    watch = Subscriber(mosquitto.port)
    try:
        err = (tmp_path / "publish.err").open("w")
        publisher = subprocess.Popen(_publish_cmd(csv, mosquitto.port, "--speed", "1"),
                                     stderr=err, stdout=subprocess.DEVNULL)
        err.close()
        try:
            _wait(lambda: len(watch.snapshot()) >= 30, 30, "the first messages")
            mosquitto.restart()  # SIGTERM (store written), start again on the same port
            assert publisher.wait(60) == 0, (tmp_path / "publish.err").read_text()
        finally:
            if publisher.poll() is None:
                publisher.kill()
                publisher.wait(10)
        _wait(lambda: set(watch.snapshot()) >= set(map(float, range(rows))), 30,
              "every message at the subscriber")
    finally:
        watch.close()
    log = (tmp_path / "publish.err").read_text()
    assert "broker lost" in log and "reconnected" in log and f"published {rows} messages" in log
    values = watch.snapshot()
    # at least once, in order: dropping repeats leaves 0, 1, 2, ... exactly
    firsts = list(dict.fromkeys(values))
    assert firsts == [float(i) for i in range(rows)]
    print(f"{rows} published over a broker restart: {len(values)} received, "
          f"{len(values) - rows} twice")


def test_kill_int_stops_a_publish_started_with_sigint_ignored(mosquitto: Any,
                                                               tmp_path: Path) -> None:
    csv = _csv(tmp_path, 600, 0.1)  # 10 messages/s at --speed 1: a minute
    watch = Subscriber(mosquitto.port)
    try:
        err = (tmp_path / "publish.err").open("w")
        # what a shell does to a background job when job control is off
        publisher = subprocess.Popen(
            _publish_cmd(csv, mosquitto.port, "--speed", "1"), stderr=err,
            stdout=subprocess.DEVNULL,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
        err.close()
        try:
            _wait(lambda: len(watch.snapshot()) >= 10, 30, "the first messages")
            publisher.send_signal(signal.SIGINT)
            assert publisher.wait(20) == 130
        finally:
            if publisher.poll() is None:
                publisher.kill()
                publisher.wait(10)
        log = (tmp_path / "publish.err").read_text()
        line = next(x for x in log.splitlines() if "stopped by SIGINT" in x)
        delivered = int(line.split(": ")[2].split(" of ")[0])
        # what the broker acknowledged reaches the subscriber (was: a 0.5 s pause)
        _wait(lambda: len(set(watch.snapshot())) >= delivered, 60, "the delivered messages")
        received = len(set(watch.snapshot()))
    finally:
        watch.close()
    assert "Traceback" not in log
    assert line.endswith("messages delivered on rig/P1/...") and " of 600 " in line
    assert 10 <= delivered < 600
    assert received == delivered  # the summary counts what the broker acknowledged


def test_password_from_a_file_or_the_environment(
        tls_mosquitto: tuple[Any, Path, str, str], tmp_path: Path) -> None:
    broker, ca, user, password = tls_mosquitto
    csv = _csv(tmp_path, 5, 0.1)
    secret = tmp_path / "password"
    secret.write_text(password + "\n")
    secret.chmod(0o600)
    base = [*_publish_cmd(csv, broker.port, "--username", user, "--ca-file", str(ca))]
    env = {k: v for k, v in os.environ.items() if k != "TDMON_MQTT_PASSWORD"}

    ok = subprocess.run([*base, "--password-file", str(secret)], capture_output=True,
                        text=True, timeout=60, env=env)
    assert ok.returncode == 0, ok.stderr
    assert "published 5 messages" in ok.stderr and "warning" not in ok.stderr

    by_env = subprocess.run(base, capture_output=True, text=True, timeout=60,
                            env={**env, "TDMON_MQTT_PASSWORD": password})
    assert by_env.returncode == 0, by_env.stderr

    named = subprocess.run([*base, "--password-env", "RIG_PW"], capture_output=True, text=True,
                           timeout=60, env={**env, "RIG_PW": password})
    assert named.returncode == 0, named.stderr

    unset = subprocess.run([*base, "--password-env", "RIG_PW"], capture_output=True, text=True,
                           timeout=60, env=env)
    assert unset.returncode == 2
    assert unset.stderr.strip().splitlines()[-1] == (
        "tdmon: error: --password-env: environment variable RIG_PW is not set")

    wrong = tmp_path / "wrong"
    wrong.write_text("nope\n")
    wrong.chmod(0o600)
    refused = subprocess.run([*base, "--password-file", str(wrong)], capture_output=True,
                             text=True, timeout=60, env=env)
    assert refused.returncode == 2 and "check username and password" in refused.stderr


def test_password_file_rules(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "pw"
    path.write_text("s3cret\nignored\n")
    path.chmod(0o644)
    assert read_password_file(path, "--password-file") == "s3cret"
    assert "readable by others (chmod 600" in capsys.readouterr().err
    path.chmod(0o600)
    assert read_password_file(path, "--password-file") == "s3cret"
    assert capsys.readouterr().err == ""
    path.write_text("")
    with pytest.raises(TdmonError, match="is empty"):
        read_password_file(path, "--password-file")
    with pytest.raises(TdmonError, match="--password-file: cannot read"):
        read_password_file(tmp_path / "missing", "--password-file")
