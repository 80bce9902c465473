"""OPC UA: engineering units and data values in tdmon's payload (pure), the [sources.opcua]
section's mistakes, and the source against a real asyncua server on a loopback port (node
ids, browse paths and namespace URIs, a node that is not there, certificates and user names,
`tdmon publish --opcua` serving a bundled replay)."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import subprocess
import sys
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest

from tdmon.channels import CHANNEL_UNITS, ChannelSpec
from tdmon.config.daemon import OpcUaConfig, parse_daemon_config
from tdmon.errors import ConfigError, IngestError
from tdmon.ingest.decode import Decoder
from tdmon.ingest.opcua import (
    UNECE_NAMESPACE,
    UNECE_UNITS,
    eu_unit,
    is_good,
    unece_code,
    unit_id,
    value_message,
)
from tdmon.ingest.opcua_server import SERVED_UNITS, OpcUaRigServer
from tdmon.ingest.opcua_source import OpcUaSource
from tdmon.ingest.publish import recording_messages
from tdmon.ingest.types import RawMessage, Rejected, Sample
from tdmon.ingest.wits0_server import Step, session_steps
from tdmon.units import conversion

REPO = Path(__file__).resolve().parents[2]
REPLAY = REPO / "replays" / "trip-out-tight-spot.mcap"
T0 = 1_700_000_000.0


# -- engineering units -------------------------------------------------------------------------

def test_unit_ids_are_unece_codes_packed_in_bytes() -> None:
    # values from the OPC Foundation's UNECE-to-OPC UA table: kN is B47 = 4338743, metre MTR =
    # 5067858, newton metre NU = 20053, foot FOT = 4607828, psi PS = 20563
    assert unit_id("B47") == 4338743 and unit_id("MTR") == 5067858
    assert unit_id("NU") == 20053 and unit_id("FOT") == 4607828 and unit_id("PS") == 20563
    assert all(unece_code(unit_id(code)) == code for code in UNECE_UNITS)
    assert unece_code(0) is None and unece_code(0x0A4142) is None  # a control character


def test_engineering_units_to_channel_units() -> None:
    # the code wins over a display name it contradicts; a code not in the table, or another
    # namespace, leaves the display name, rewritten for pint
    assert eu_unit(UNECE_NAMESPACE, unit_id("B47"), "tonnes") == "kN"
    assert eu_unit(UNECE_NAMESPACE, unit_id("XYZ"), "kN·m") == "kN*m"
    assert eu_unit("urn:vendor:units", unit_id("B47"), "klbf") == "klbf"
    assert eu_unit(None, None, "°F") == "degF"
    assert eu_unit(None, None, "m³/h") == "m**3/h"
    assert eu_unit(None, None, "  ") is None
    # every unit of the table converts to its channel's SI unit by the factor expected
    rpm = conversion(UNECE_UNITS["RPM"], "rad/s")[0]
    assert rpm == pytest.approx(2 * 3.141592653589793 / 60, rel=1e-12)
    assert conversion(UNECE_UNITS["L2"], "m**3/s")[0] == pytest.approx(1e-3 / 60, rel=1e-12)
    assert conversion(UNECE_UNITS["PS"], "Pa")[0] == pytest.approx(6894.757293168, rel=1e-9)
    assert conversion(UNECE_UNITS["FAH"], "degC") == pytest.approx((5 / 9, -160 / 9), rel=1e-12)


# -- data values as payloads -------------------------------------------------------------------

def _decoder() -> Decoder:
    return Decoder("rig/T", [ChannelSpec("hookload", "hookload"),
                             ChannelSpec("torque", "torque", unit="kN*m")])


def _stamp(t: float) -> datetime:
    return datetime.fromtimestamp(t, UTC)


def test_a_good_value_decodes_to_si_at_its_source_time() -> None:
    raw = value_message("rig/T/hookload", "ns=2;s=HKLD", 1234.5, 0, "Good", _stamp(T0 + 1),
                        _stamp(T0 + 2), T0 + 3, "kN")
    assert raw.source == "opcua" and raw.topic == "rig/T/hookload"
    body = json.loads(raw.payload)
    assert body["time_from"] == "source" and body["source_time"] == "2023-11-14T22:13:21Z"
    sample = _decoder().decode(raw)
    assert isinstance(sample, Sample)
    assert sample.t == T0 + 1 and sample.value == pytest.approx(1_234_500.0, rel=1e-15)


@pytest.mark.parametrize(("source", "server", "t", "time_from"), [
    (None, T0 + 2, T0 + 2, "server"),
    # OPC UA's null time (1601-01-01) is no time
    (datetime(1601, 1, 1, tzinfo=UTC), None, T0 + 3, "receive"),
])
def test_missing_source_timestamps_fall_back_and_say_so(
        source: datetime | None, server: float | None, t: float, time_from: str) -> None:
    raw = value_message("rig/T/hookload", "n", 1.0, 0, "Good", source,
                        None if server is None else _stamp(server), T0 + 3, "kN")
    body = json.loads(raw.payload)
    assert body["t"] == t and body["time_from"] == time_from and body["source_time"] is None


@pytest.mark.parametrize(("value", "status", "name", "reason"), [
    (None, 0x808C0000, "BadSensorFailure",
     "OPC UA status BadSensorFailure (0x808C0000) from node ns=2;s=HKLD"),
    (12.0, 0x40920000, "UncertainSubstituteValue",
     "OPC UA status UncertainSubstituteValue (0x40920000) from node ns=2;s=HKLD"),
    ("12 kN", 0, "Good", "node ns=2;s=HKLD: value '12 kN' (str) is not a number"),
    (True, 0, "Good", "node ns=2;s=HKLD: value True (bool) is not a number"),
    (float("nan"), 0, "Good", "node ns=2;s=HKLD: value nan is not finite"),
])
def test_values_not_good_are_rejected_with_the_reason(value: Any, status: int, name: str,
                                                      reason: str) -> None:
    raw = value_message("rig/T/hookload", "ns=2;s=HKLD", value, status, name, _stamp(T0),
                        None, T0, "kN")
    json.loads(raw.payload)  # plain JSON, whatever the value
    rejected = _decoder().decode(raw)
    assert isinstance(rejected, Rejected) and rejected.reason == reason
    assert is_good(status) == (status == 0)


def test_a_node_without_a_unit_takes_the_configured_one() -> None:
    raw = value_message("rig/T/torque", "n", 20.0, 0, "Good", _stamp(T0), None, T0, None)
    sample = _decoder().decode(raw)
    assert isinstance(sample, Sample) and sample.value == pytest.approx(20_000.0, rel=1e-15)


# -- the section's mistakes --------------------------------------------------------------------

def _config(tmp_path: Path, **section: Any) -> OpcUaConfig:
    data = {"prefix": "rig/T", "sources": {"opcua": {
        "endpoint": "opc.tcp://127.0.0.1:4840", "nodes": {"hookload": "ns=2;s=HKLD"},
        **section}}}
    config = parse_daemon_config(data, tmp_path / "daemon.toml").sources.opcua
    assert config is not None
    return config


@pytest.mark.parametrize(("section", "key", "reason"), [
    ({"endpoint": "tcp://127.0.0.1:4840"}, "sources.opcua.endpoint", "not an OPC UA endpoint"),
    ({"nodes": {"hookload": "ns=2,s=HKLD"}}, "sources.opcua.nodes.hookload.node",
     "not a NodeId"),
    ({"nodes": {"hookload": {"path": "Rig//HKLD"}}}, "sources.opcua.nodes.hookload.path",
     "not a browse path"),
    ({"nodes": {"hookload": {"node": "i=1", "path": "2:Rig"}}}, "sources.opcua.nodes.hookload",
     "one of node"),
    ({"nodes": {"hooklaod": "i=1"}}, "sources.opcua.nodes", "unknown channel 'hooklaod'"),
    ({"nodes": {}}, "sources.opcua.nodes", "at least 1"),
    ({"security_policy": "Basic256Sha256"}, "sources.opcua.security_mode", "give both as None"),
    ({"security_policy": "Basic256Sha256", "security_mode": "Sign"},
     "sources.opcua.certificate", "needs the client's certificate"),
    ({"password": "x"}, "sources.opcua.username", "password needs a username"),
    ({"username": "u", "password_env": "TDMON_TEST_NOT_SET"}, "sources.opcua.password_env",
     "TDMON_TEST_NOT_SET is not set"),
    ({"username": "u", "password_file": "pw.txt"}, "sources.opcua.password_file",
     "no such file"),
    ({"publishing_interval": 1}, "sources.opcua.publishing_interval", "has no unit"),
])
def test_section_mistakes_name_the_key(tmp_path: Path, section: dict[str, Any], key: str,
                                       reason: str) -> None:
    with pytest.raises(ConfigError) as error:
        _config(tmp_path, **section)
    assert error.value.key == key and reason in error.value.reason, error.value


def test_section_paths_are_relative_to_the_file(tmp_path: Path) -> None:
    for name in ("client.der", "client.pem", "server.der"):
        (tmp_path / name).write_bytes(b"x")
    config = _config(tmp_path, security_policy="Aes256_Sha256_RsaPss",
                     security_mode="SignAndEncrypt", certificate="client.der",
                     private_key="client.pem", server_certificate="server.der",
                     publishing_interval="250 ms", nodes={"torque": {"path": "/2:Rig/2:TQ/",
                                                                      "unit": "kN*m"}})
    assert config.certificate == tmp_path / "client.der"
    assert config.publishing_interval == 0.25
    assert config.nodes["torque"].path == "2:Rig/2:TQ"


def test_one_rig_only(tmp_path: Path) -> None:
    data = {"prefix": "fleet", "rigs": [{"prefix": "fleet/a"}], "sources": {"opcua": {
        "endpoint": "opc.tcp://127.0.0.1:4840", "nodes": {"hookload": "i=1"}}}}
    with pytest.raises(ConfigError, match="one rig's"):
        parse_daemon_config(data, tmp_path / "daemon.toml")


# -- the source against a real server ----------------------------------------------------------

async def _take(source: OpcUaSource, count: int, timeout: float = 30.0) -> list[RawMessage]:
    async with asyncio.timeout(timeout):
        return [await anext(source) for _ in range(count)]


def _bodies(messages: list[RawMessage]) -> dict[str, list[dict[str, Any]]]:
    out: dict[str, list[dict[str, Any]]] = {}
    for message in messages:
        out.setdefault(message.topic.rsplit("/", 1)[-1], []).append(json.loads(message.payload))
    return out


async def test_node_ids_browse_paths_namespace_uris_and_missing_nodes() -> None:
    async with OpcUaRigServer("127.0.0.1", 0, channels=("hookload", "torque", "rpm")) as server:
        config = OpcUaConfig(endpoint=server.endpoint, publishing_interval=0.05, nodes={
            "hookload": {"node": server.node_id("hookload")},
            "torque": {"path": "2:Rig/2:torque"},
            "rpm": {"node": "nsu=urn:tdmon:rig-simulator;s=Rig.rpm"},
            "wob": {"node": "ns=2;s=Rig.wob"},            # not served
            "bit_depth": {"path": "2:Rig/2:bit_depth"}})  # no such path
        topics = {channel: f"rig/T/{channel}" for channel in
                  ("hookload", "torque", "rpm", "wob", "bit_depth")}
        async with OpcUaSource(config, topics) as source:
            await asyncio.wait_for(server.wait_for_subscribers(1), 30)
            for k in range(3):  # the same values again: every step still comes
                await server.write(Step(T0 + k, {"hookload": 1e6, "torque": 2e4, "rpm": 3.0}))
            # 2 node errors, 3 first values (BadWaitingForInitialData), 3 x 3 steps
            got = _bodies(await _take(source, 2 + 3 + 9))
        # no configured node there at all: nothing to subscribe to is an error
        config = OpcUaConfig(endpoint=server.endpoint, nodes={"hookload": {"path": "2:Nope"}})
        with pytest.raises(IngestError, match="none of the configured nodes was found"):
            async with OpcUaSource(config, {"hookload": "rig/T/hookload"}):
                pass
    assert "BadNoMatch" in got["bit_depth"][0]["error"]
    assert got["wob"][0]["error"] == ("node ns=2;s=Rig.wob: the server refused to monitor it: "
                                      "BadNodeIdUnknown")
    for channel, value, unit in (("hookload", 1000.0, "kN"), ("torque", 20.0, "kN*m"),
                                 ("rpm", 3.0 * 60 / (2 * 3.141592653589793),
                                  "rpm")):
        first, *steps = got[channel]
        assert first["status"] == "BadWaitingForInitialData" and "error" in first
        assert [s["t"] for s in steps] == [T0, T0 + 1, T0 + 2]
        assert all(s["unit"] == unit and s["status"] == "Good" and "error" not in s
                   for s in steps)
        assert [s["value"] for s in steps] == pytest.approx([value] * 3, rel=1e-14)


async def test_nobody_listening_is_an_ingest_error(free_tcp_port: Callable[[], int]) -> None:
    config = OpcUaConfig(endpoint=f"opc.tcp://127.0.0.1:{free_tcp_port()}", timeout=2,
                         nodes={"hookload": {"node": "ns=2;s=x"}})
    with pytest.raises(IngestError, match=r"cannot connect: .*Connect call failed"):
        async with OpcUaSource(config, {"hookload": "rig/T/hookload"}):
            pass


async def _certificates(folder: Path) -> None:
    """Self-signed application certificates of a server, an impostor and a client (asyncua's
    generator, as an integrator's tool would make them)."""
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    for name, use in (("server", ExtendedKeyUsageOID.SERVER_AUTH),
                      ("impostor", ExtendedKeyUsageOID.SERVER_AUTH),
                      ("client", ExtendedKeyUsageOID.CLIENT_AUTH)):
        await setup_self_signed_certificate(folder / f"{name}-key.pem",
                                            folder / f"{name}-cert.der",
                                            f"urn:tdmon:test:{name}", socket.gethostname(),
                                            [use], {})


async def test_signed_and_encrypted_with_a_user_name_and_the_mistakes(tmp_path: Path) -> None:
    """A server offering only Basic256Sha256 SignAndEncrypt to one user: the source reads it
    with the client's certificate and a password file, with or without the server's
    certificate given; a wrong password, no security and the wrong server certificate are
    connection errors with the reason."""
    await _certificates(tmp_path)
    (tmp_path / "password").write_text("s3cret\n")
    topics = {"hookload": "rig/T/hookload"}
    async with OpcUaRigServer("127.0.0.1", 0, channels=("hookload",),
                              certificate=tmp_path / "server-cert.der",
                              private_key=tmp_path / "server-key.pem",
                              users={"driller": "s3cret"}) as server:

        def config(**changes: Any) -> OpcUaConfig:
            settings: dict[str, Any] = {
                "endpoint": server.endpoint, "security_policy": "Basic256Sha256",
                "security_mode": "SignAndEncrypt", "certificate": tmp_path / "client-cert.der",
                "private_key": tmp_path / "client-key.pem",
                "server_certificate": tmp_path / "server-cert.der", "username": "driller",
                "password_file": tmp_path / "password", "publishing_interval": 0.05,
                "timeout": 3.0, "nodes": {"hookload": {"node": server.node_id("hookload")}}}
            return OpcUaConfig(**{**settings, **changes})

        async with OpcUaSource(config(), topics) as source:
            await asyncio.wait_for(server.wait_for_subscribers(1), 30)
            await server.write(Step(T0, {"hookload": 654_321.0}))
            _, value = await _take(source, 2)
        assert json.loads(value.payload)["value"] == pytest.approx(654.321, rel=1e-14)
        # the server's certificate need not be given: the endpoint's is taken
        async with OpcUaSource(config(server_certificate=None), topics) as source:
            [value] = await _take(source, 1)
        assert json.loads(value.payload)["value"] == pytest.approx(654.321, rel=1e-14)
        for changes, reason in (
                ({"password": "wrong", "password_file": None}, "BadUserAccessDenied"),
                ({"security_policy": "None", "security_mode": "None"}, "No matching endpoints"),
                # a server not holding the certificate given cannot read us: no answer
                ({"server_certificate": tmp_path / "impostor-cert.der"}, "not the server's")):
            with pytest.raises(IngestError, match="cannot connect") as error:
                async with OpcUaSource(config(**changes), topics):
                    pass
            assert reason in str(error.value)


# -- `tdmon publish --opcua` -------------------------------------------------------------------

def test_every_channel_is_served_in_a_unit_that_converts_from_its_own() -> None:
    """A channel added to tdmon.channels without a served unit made `publish --opcua` fail."""
    assert set(SERVED_UNITS) == set(CHANNEL_UNITS)
    for channel, (unit, code, _) in SERVED_UNITS.items():
        factor = conversion(CHANNEL_UNITS[channel][0], unit)
        assert factor is not None and code in UNECE_UNITS, channel


def test_publish_serves_a_replay_to_a_subscriber(free_tcp_port: Callable[[], int]) -> None:
    """The simulator in its own process, the source here: every step of the first 300 of the
    replay, each channel's SI value back through the served unit, at the step's time."""
    port = free_tcp_port()
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen(
        [sys.executable, "-m", "tdmon", "publish", str(REPLAY), "--opcua",
         f"opc.tcp://127.0.0.1:{port}", "--speed", "100", "--limit", "300",
         "--opcua-linger", "1"], stderr=subprocess.PIPE, env=env, text=True)
    steps = list(session_steps(recording_messages(REPLAY)))[:300]
    channels = sorted({channel for step in steps for channel in step.values})
    expected = sum(len(step.values) for step in steps) + len(channels)  # + the first values
    try:
        assert process.stderr is not None
        assert "serving OPC UA on" in process.stderr.readline()
        config = OpcUaConfig(endpoint=f"opc.tcp://127.0.0.1:{port}", publishing_interval=0.1,
                             queue_size=1000,
                             nodes={channel: {"path": f"2:Rig/2:{channel}"}
                                    for channel in channels})

        async def read() -> list[RawMessage]:
            async with OpcUaSource(config, {c: f"rig/T/{c}" for c in channels}) as source:
                return await _take(source, expected, timeout=120)

        received = asyncio.run(read())
        assert process.wait(60) == 0
        assert "served 300 time steps" in process.stderr.read()
    finally:
        process.kill()
        process.wait()
    decoder = Decoder("rig/T", [ChannelSpec(c, c) for c in channels])
    samples = [decoder.decode(raw) for raw in received]
    good = [s for s in samples if isinstance(s, Sample)]
    assert len(good) == expected - len(channels)
    for channel in channels:
        got = [(s.t, s.value) for s in good if s.channel == channel]
        want = [(step.t, step.values[channel]) for step in steps if channel in step.values]
        assert [t for t, _ in got] == [t for t, _ in want], channel
        assert [v for _, v in got] == pytest.approx([v for _, v in want], rel=1e-12), channel


async def test_without_asyncua_the_daemon_does_not_start(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from tdmon.daemon.build import build_daemon
    from tdmon.daemon.steps.monitor import GridLoadModel

    monkeypatch.setitem(sys.modules, "asyncua", None)  # what an install without it gives
    config = parse_daemon_config({"prefix": "rig/T", "sources": {"opcua": {
        "endpoint": "opc.tcp://127.0.0.1:4840", "nodes": {"hookload": "i=1"}}}},
        tmp_path / "daemon.toml")
    model = GridLoadModel.from_function(
        lambda depths, mu: (depths, depths, depths, depths), [0.0, 1000.0], 0.25, (0.1,))
    with pytest.raises(ConfigError) as error:
        async with build_daemon(config, model=model):
            pass
    assert error.value.key == "sources.opcua"
    assert "pip install 'tdmon[opcua]'" in error.value.reason


@pytest.mark.parametrize(("args", "message"), [
    (["--opcua", "opc.tcp://127.0.0.1:4840", "--speed", "max"],
     "--opcua needs --speed N (real time x N): OPC UA has no flow control"),
    (["--opcua", "tcp://127.0.0.1:4840"], "--opcua 'tcp://127.0.0.1:4840': expected "
                                          "opc.tcp://HOST:PORT"),
    (["--opcua", "opc.tcp://127.0.0.1:4840", "--wits0", "tcp://127.0.0.1:5001"],
     "give one of --wits0 and --opcua"),
])
def test_publish_mistakes_are_one_line(capsys: pytest.CaptureFixture[str], args: list[str],
                                       message: str) -> None:
    from tdmon.cli import main

    assert main(["publish", str(REPLAY), *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
