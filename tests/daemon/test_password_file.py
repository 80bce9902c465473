"""``password_file`` end to end: the daemon logs in to a real TLS broker with the password read
from a file next to its configuration."""

from __future__ import annotations

import ssl
import time
from pathlib import Path
from typing import Any

import aiomqtt
from daemon_support import make_config, payload, running, wait_until


async def test_password_from_a_file(tls_mosquitto: tuple[Any, Path, str, str],
                                    tmp_path: Path) -> None:
    broker, ca_file, user, password = tls_mosquitto
    secret = tmp_path / "mqtt.pw"
    secret.write_text(password + "\n")
    secret.chmod(0o600)
    config = make_config({"sources": {"mqtt": {
        "port": broker.port, "client_id": "tdmon-pwfile", "username": user,
        "password_file": "mqtt.pw", "tls": {"ca_file": str(ca_file)},
    }}}, tmp_path)
    async with running(config, connected=("mqtt",)) as (built, sink):
        context = ssl.create_default_context(cafile=str(ca_file))
        async with aiomqtt.Client("127.0.0.1", broker.port, username=user, password=password,
                                  tls_context=context, identifier="rig-pwfile") as rig:
            await rig.publish("rig/T1/hookload", payload(time.time(), 1200.0), qos=1)
        await wait_until(lambda: built.stats.samples_in == 1, 30, "sample over TLS")
    assert sink["sample"][0]["value"] == 1.2e6
