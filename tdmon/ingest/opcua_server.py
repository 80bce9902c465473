"""Play a rig's drilling control system over OPC UA: serve a session's samples from an
asyncua server, as ``tdmon publish X.mcap|X.csv --opcua opc.tcp://HOST:PORT`` does for tests
and demonstrations (docs/opcua.md, "Simulator").

The address space: an object ``Rig`` under Objects, in the namespace :data:`NAMESPACE`, with
one Double variable per channel, NodeId ``ns=<index>;s=Rig.<channel>`` and browse name
``<index>:<channel>`` (browse path ``<index>:Rig/<index>:<channel>``), each with its
``EngineeringUnits`` (:data:`SERVED_UNITS`: the units a rig's system shows, kN, kN m, r/min,
bar...). A variable holds ``BadWaitingForInitialData`` until its first value. Each time step
of the session (:func:`tdmon.ingest.wits0_server.session_steps`) is written to its channels'
variables with the step's time as source timestamp, so that a subscriber with the
status-value-timestamp trigger gets every step, also a value written again unchanged.

OPC UA has no flow control: a subscriber gets what its queue (per monitored item) holds
between two publishes, so the steps are paced (real time x N), never sent as fast as possible.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Iterable, Mapping
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import Any, Final
from urllib.parse import urlsplit

import orjson

from tdmon.channels import CHANNEL_UNITS, CHANNELS
from tdmon.errors import IngestError
from tdmon.ingest.opcua import UNECE_NAMESPACE, unit_id
from tdmon.ingest.opcua_source import application_uri, import_asyncua
from tdmon.ingest.wits0_server import Step
from tdmon.units import conversion

log = logging.getLogger(__name__)

#: the namespace of the simulator's nodes
NAMESPACE: Final = "urn:tdmon:rig-simulator"

#: channel -> (unit spelling for tdmon.units, UNECE common code, UNECE symbol): the units the
#: simulator's server sends each channel in, as its EngineeringUnits say
SERVED_UNITS: Final[Mapping[str, tuple[str, str, str]]] = {
    "hookload": ("kN", "B47", "kN"),
    "torque": ("kN*m", "B48", "kN·m"),
    "bit_depth": ("m", "MTR", "m"),
    "hole_depth": ("m", "MTR", "m"),
    "block_position": ("m", "MTR", "m"),
    "rpm": ("rpm", "RPM", "r/min"),
    "flow_in": ("L/min", "L2", "l/min"),
    "spp": ("bar", "BAR", "bar"),
    "wob": ("kN", "B47", "kN"),
    "downhole_wob": ("kN", "B47", "kN"),
    "downhole_torque": ("kN*m", "B48", "kN·m"),
    "mud_temp_in": ("degC", "CEL", "°C"),
    "mud_temp_out": ("degC", "CEL", "°C"),
    "mud_density": ("kg/m**3", "KMQ", "kg/m³"),
}

_USAGE = "expected opc.tcp://HOST:PORT, e.g. opc.tcp://127.0.0.1:4840"


def parse_opcua_url(text: str, flag: str = "--opcua") -> tuple[str, int]:
    """``opc.tcp://127.0.0.1:4840`` -> ``("127.0.0.1", 4840)``; anything else is the user's
    mistake."""
    parts = urlsplit(text)
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme != "opc.tcp" or not parts.hostname or port is None:
        raise IngestError(f"{flag} '{text}': {_USAGE}")
    return parts.hostname, port


def step_payload(step: Step) -> bytes:
    """A step as the payload :class:`OpcUaSender` takes (the sender interface carries bytes)."""
    return orjson.dumps({"t": step.t, "values": dict(step.values)})


class OpcUaRigServer:
    """An asyncua server on ``host:port`` holding one variable per channel.

    An async context manager; :meth:`write` sets a step's values, :meth:`write_status` a
    quality without a value (a sensor failure). Optional security for tests of the source:
    ``certificate`` and ``private_key`` (then only Basic256Sha256 SignAndEncrypt is offered)
    and ``users`` (user name -> password; then anonymous sessions are refused).
    """

    def __init__(self, host: str, port: int, *, channels: Iterable[str] = CHANNELS,
                 certificate: Path | None = None, private_key: Path | None = None,
                 users: Mapping[str, str] | None = None) -> None:
        self.host = host
        self.port = port
        self.channels = tuple(channels)
        self.certificate = certificate
        self.private_key = private_key
        self.users = dict(users or {})
        self.steps_written = 0
        self.subscriptions: set[int] = set()
        self._server: Any = None
        self._ua: Any = None  # asyncua.ua, once entered
        self._nodes: dict[str, Any] = {}
        self._factors = {channel: conversion(CHANNEL_UNITS[channel][0], SERVED_UNITS[channel][0])
                         for channel in self.channels}
        self._subscribed = asyncio.Condition()

    @property
    def bound_port(self) -> int:
        """The port listened on (the chosen one when ``port`` was 0)."""
        assert self._server is not None, "not entered"
        return int(self._server.bserver.port)

    @property
    def endpoint(self) -> str:
        return f"opc.tcp://{self.host}:{self.bound_port}/tdmon"

    def node_id(self, channel: str) -> str:
        """The NodeId text of ``channel``'s variable."""
        return self._nodes[channel].nodeid.to_string()

    async def __aenter__(self) -> OpcUaRigServer:
        asyncua = import_asyncua()
        ua = self._ua = asyncua.ua
        from asyncua.common.callback import CallbackType

        server = asyncua.Server(user_manager=_Users(self.users) if self.users else None)
        await server.init()
        server.set_endpoint(f"opc.tcp://{self.host}:{self.port}/tdmon")
        server.set_server_name("tdmon rig simulator")
        if self.certificate is not None and self.private_key is not None:
            uri = application_uri(self.certificate)
            if uri is not None:
                # clients check the server's application URI against its certificate's
                await server.set_application_uri(uri)
            await server.load_certificate(str(self.certificate))
            await server.load_private_key(str(self.private_key))
            server.set_security_policy([ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt])
        else:
            server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        if self.users:
            server.set_identity_tokens([ua.UserNameIdentityToken])
        index = await server.register_namespace(NAMESPACE)
        rig = await server.nodes.objects.add_object(ua.NodeId("Rig", index),
                                                    ua.QualifiedName("Rig", index))
        for channel in self.channels:
            unit, code, symbol = SERVED_UNITS[channel]
            variable = await rig.add_variable(
                ua.NodeId(f"Rig.{channel}", index), ua.QualifiedName(channel, index),
                ua.Variant(0.0, ua.VariantType.Double))
            eu = ua.EUInformation(NamespaceUri=UNECE_NAMESPACE, UnitId=unit_id(code),
                                  DisplayName=ua.LocalizedText(symbol),
                                  Description=ua.LocalizedText(unit))
            await variable.add_property(ua.NodeId(f"Rig.{channel}.EngineeringUnits", index),
                                        ua.QualifiedName("EngineeringUnits", 0), eu,
                                        datatype=ua.NodeId(ua.ObjectIds.EUInformation))
            await server.write_attribute_value(variable.nodeid, ua.DataValue(
                StatusCode=ua.StatusCode(ua.StatusCodes.BadWaitingForInitialData),
                SourceTimestamp=datetime.now(UTC)))
            self._nodes[channel] = variable
        server.subscribe_server_callback(CallbackType.ItemSubscriptionCreated, self._on_items)
        try:
            await server.start()
        except OSError as exc:
            raise IngestError(f"opcua: cannot listen on {self.host}:{self.port}: "
                              f"{exc.strerror or exc}") from exc
        self._server = server
        log.info("opcua: serving %s", self.endpoint)
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None,
                        exc: BaseException | None, tb: TracebackType | None) -> None:
        server, self._server = self._server, None
        if server is not None:
            with contextlib.suppress(Exception):
                await server.stop()

    async def _on_items(self, event: Any, dispatcher: Any) -> None:
        async with self._subscribed:
            self.subscriptions.add(event.request_params.SubscriptionId)
            self._subscribed.notify_all()

    async def wait_for_subscribers(self, count: int = 1) -> None:
        """Return once ``count`` subscriptions have monitored items of ours."""
        async with self._subscribed:
            await self._subscribed.wait_for(lambda: len(self.subscriptions) >= count)

    async def write(self, step: Step) -> None:
        """Write the step's values (SI, converted to :data:`SERVED_UNITS`) with the step's
        time as source timestamp; channels the server does not hold are left out."""
        ua = self._ua
        stamp = datetime.fromtimestamp(step.t, UTC)
        now = datetime.now(UTC)
        for channel, value in step.values.items():
            variable = self._nodes.get(channel)
            if variable is None:
                continue
            scale, offset = self._factors[channel]
            await self._server.write_attribute_value(variable.nodeid, ua.DataValue(
                ua.Variant(value * scale + offset, ua.VariantType.Double),
                SourceTimestamp=stamp, ServerTimestamp=now))
        self.steps_written += 1

    async def write_status(self, channel: str, t: float, status: str) -> None:
        """Set ``channel``'s quality to ``status`` (e.g. ``"BadSensorFailure"``) at ``t``
        [Unix s], without a value: a rig's sensor failing."""
        ua = self._ua
        await self._server.write_attribute_value(self._nodes[channel].nodeid, ua.DataValue(
            StatusCode=ua.StatusCode(getattr(ua.StatusCodes, status)),
            SourceTimestamp=datetime.fromtimestamp(t, UTC), ServerTimestamp=datetime.now(UTC)))


class _Users:
    """asyncua's user manager: the given user names with their passwords, nobody else."""

    def __init__(self, users: Mapping[str, str]) -> None:
        self.users = users

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> Any:
        from asyncua.crypto.permission_rules import User, UserRole

        if username is not None and self.users.get(username) == password:
            return User(role=UserRole.User, name=username)
        return None


class OpcUaSender:
    """The :class:`tdmon.ingest.publish.Sender` of steps (:func:`step_payload`) to an
    :class:`OpcUaRigServer`: the topic is ignored."""

    def __init__(self, server: OpcUaRigServer) -> None:
        self.server = server

    async def send(self, topic: str, payload: bytes) -> None:
        data = orjson.loads(payload)
        await self.server.write(Step(data["t"], data["values"]))

    async def flush(self) -> None:
        return None
