"""TLS with a password file: the right credentials work, a wrong password backs off cleanly."""

from __future__ import annotations

import ssl
import time
from pathlib import Path
from typing import Any

import aiomqtt
from daemon_support import make_config, payload, running, wait_until


async def test_tls_with_password(tls_mosquitto: tuple[Any, Path, str, str],
                                 tmp_path: Path) -> None:
    broker, ca_file, user, password = tls_mosquitto
    config = make_config({"sources": {"mqtt": {
        "port": broker.port, "client_id": "tdmon-tls", "username": user,
        "password": password, "tls": {"ca_file": str(ca_file)},
    }}}, tmp_path)
    async with running(config, connected=("mqtt",)) as (built, sink):
        context = ssl.create_default_context(cafile=str(ca_file))
        async with aiomqtt.Client("127.0.0.1", broker.port, username=user, password=password,
                                  tls_context=context, identifier="rig-tls") as rig:
            await rig.publish("rig/T1/hookload", payload(time.time(), 1200.0), qos=1)
        await wait_until(lambda: built.stats.samples_in == 1, 10, "sample over TLS")
    assert sink["sample"][0]["value"] == 1.2e6


async def test_wrong_password_is_a_clear_error_with_backoff(
        tls_mosquitto: tuple[Any, Path, str, str], tmp_path: Path) -> None:
    broker, ca_file, user, _ = tls_mosquitto
    config = make_config({"sources": {"mqtt": {
        "port": broker.port, "client_id": "tdmon-badpw", "username": user,
        "password": "wrong", "tls": {"ca_file": str(ca_file)},
    }}}, tmp_path)
    states: list[str] = []
    async with running(config) as (built, sink):
        def retried_twice() -> bool:
            states.append(built.daemon.connections.get("mqtt", ""))
            return sum(1 for s in set(states) if s.startswith("retrying")) >= 2

        await wait_until(retried_twice, 10, "two backoff rounds")
        assert built.daemon.queue is not None  # still running
    failures = [s for s in states if s.startswith("retrying")]
    assert any("not authorised" in s.lower() or "not authorized" in s.lower()
               for s in failures), failures
    assert all("check username and password" in s for s in failures), failures
    assert sink["status"][-1]["connections"]["mqtt"] == "closed"


async def test_untrusted_certificate_is_reported(
        tls_mosquitto: tuple[Any, Path, str, str], tmp_path: Path) -> None:
    broker, _, user, password = tls_mosquitto
    config = make_config({"sources": {"mqtt": {
        "port": broker.port, "username": user, "password": password,
        "tls": {},  # system CAs only: the test CA is not trusted
    }}}, tmp_path)
    async with running(config) as (built, _):
        await wait_until(lambda: built.daemon.connections.get("mqtt", "").startswith(
            "retrying"), 10, "a TLS failure")
        assert "certificate" in built.daemon.connections["mqtt"].lower()
