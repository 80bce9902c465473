"""An OPC UA server of the rig's drilling control system as a daemon source (docs/opcua.md).

``async with OpcUaSource(...) as source: async for raw in source: ...``. Entering connects
(security policy and mode, the client's certificate, a user name), finds each configured
node (a NodeId, or a browse path from the Objects folder), reads its ``EngineeringUnits`` and
creates one subscription with a data-change monitored item per node: triggered on status,
value or source timestamp (so that a value written again at the rig's rate is sent again),
sampled at ``sampling_interval``, queued up to ``queue_size`` values per node between two
publishes every ``publishing_interval``. Every notification becomes one RawMessage in tdmon's
JSON payload (:func:`tdmon.ingest.opcua.value_message`) on its channel's topic; the decoder
rejects, and the recorder keeps, what is not Good.

Reconnecting is the supervisor's: the source raises :class:`~tdmon.errors.IngestError` when it
cannot connect, when the connection is lost (asyncua's watchdog reads the server's state every
``timeout / 2`` seconds; its own reconnection is off), and when the server ends the
subscription. asyncua is imported here, lazily by the daemon's source table: ``pip install
'tdmon[opcua]'``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

from tdmon.config.daemon import OpcUaConfig, OpcUaNodeConfig
from tdmon.errors import IngestError
from tdmon.ingest.opcua import eu_unit, node_error_message, value_message
from tdmon.ingest.types import RawMessage

if TYPE_CHECKING:
    from asyncua import Client, Node
    from asyncua.common.subscription import Subscription

log = logging.getLogger(__name__)

#: How long a session the server keeps for us after a lost connection [ms]: the daemon opens
#: a new one on reconnecting, so a short one frees the server's resources soon
SESSION_TIMEOUT_MS = 60_000


class _QuietOnLoss(logging.Filter):
    """asyncua logs a lost connection from several of its tasks (a traceback from the
    publish loop, warnings from closing the session): the source reports the loss itself,
    once, through the supervisor."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.exc_info and isinstance(record.exc_info[1], ConnectionError):
            return False
        return "connection is closed" not in str(record.msg)


def _quiet_asyncua() -> None:
    """asyncua's client logs every publish at INFO: the daemon's log keeps its warnings."""
    root = logging.getLogger("asyncua")
    if root.level == logging.NOTSET:
        root.setLevel(logging.WARNING)
    for name in ("asyncua.client.ua_session.UaSession", "asyncua.client.ua_client.UaClient"):
        logger = logging.getLogger(name)
        if not any(isinstance(f, _QuietOnLoss) for f in logger.filters):
            logger.addFilter(_QuietOnLoss())


def import_asyncua() -> Any:
    """The asyncua package, or an IngestError saying how to install it."""
    try:
        import asyncua
    except ImportError as exc:
        raise IngestError("OPC UA needs asyncua: pip install 'tdmon[opcua]'") from exc
    _quiet_asyncua()
    return asyncua


@dataclass(frozen=True, slots=True)
class _Item:
    """What a monitored item's notifications need: its channel's topic, node and unit."""

    channel: str
    topic: str
    node: str
    unit: str | None


class OpcUaSource:
    """``async with OpcUaSource(config, topics) as source: async for raw in source: ...``.

    Parameters
    ----------
    config : the ``[sources.opcua]`` section
    topics : channel -> full topic of its samples (``<prefix>/<topic>``)
    max_pending : notifications held for the pipeline; as many more wait in the
        subscription's own queue, and a pipeline further behind than that counts as a lost
        connection (asyncua's DISCONNECT overflow policy): the source fails and is reopened
    """

    name = "opcua"

    def __init__(self, config: OpcUaConfig, topics: Mapping[str, str],
                 max_pending: int = 10_000) -> None:
        self.config = config
        self.topics = topics
        self.max_pending = max_pending
        self._client: Client | None = None
        self._subscription: Subscription | None = None
        # notifications for the pipeline; None only wakes the reader after a failure
        self._pending: asyncio.Queue[RawMessage | None] = asyncio.Queue()
        self._lost: IngestError | None = None
        self._pump: asyncio.Task[None] | None = None
        self._items: dict[int, _Item] = {}

    def describe(self) -> str:
        return f"opcua {self.config.endpoint}"

    async def __aenter__(self) -> OpcUaSource:
        asyncua = import_asyncua()
        ua = asyncua.ua
        config = self.config
        self._pending = asyncio.Queue(maxsize=self.max_pending)
        self._lost = None
        self._items = {}
        client = asyncua.Client(config.endpoint, timeout=config.timeout,
                                watchdog_intervall=config.timeout / 2)
        client.session_timeout = SESSION_TIMEOUT_MS
        client.name = client.description = "tdmon"
        client.connection_lost_callback = self._on_connection_lost
        self._client = client
        try:
            await self._secure(client, asyncua)
            await asyncio.wait_for(client.connect(), config.timeout * 2)
        except IngestError:
            await self._close()
            raise
        except TimeoutError as exc:
            await self._close()
            hint = ("" if config.server_certificate is None else
                    " (a server_certificate that is not the server's also shows as this)")
            raise IngestError(f"{self.describe()}: cannot connect: no answer within "
                              f"{config.timeout:g} s{hint}") from exc
        except (OSError, ConnectionError, ua.UaError) as exc:
            await self._close()
            raise IngestError(f"{self.describe()}: cannot connect: {_reason(exc)}") from exc
        try:
            await self._subscribe(client, asyncua)
        except (OSError, TimeoutError, ConnectionError, ua.UaError) as exc:
            await self._close()
            raise IngestError(f"{self.describe()}: cannot subscribe: {_reason(exc)}") from exc
        except BaseException:
            await self._close()
            raise
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None,
                        exc: BaseException | None, tb: TracebackType | None) -> None:
        await self._close()

    def __aiter__(self) -> OpcUaSource:
        return self

    async def __anext__(self) -> RawMessage:
        while True:
            # what arrived before a failure is handed out first, then the failure is raised
            if self._lost is not None and self._pending.empty():
                raise self._lost
            item = await self._pending.get()
            if item is not None:
                return item

    # -- connecting ---------------------------------------------------------------------------

    async def _secure(self, client: Client, asyncua: Any) -> None:
        config = self.config
        if config.username is not None:
            client.set_user(config.username)
            try:
                password = config.resolved_password()
            except OSError as exc:
                raise IngestError(f"{self.describe()}: password_file {config.password_file}: "
                                  f"{exc.strerror or exc}") from exc
            if password is not None:
                client.set_password(password)
        if config.security_policy == "None":
            return
        from asyncua.crypto import security_policies

        assert config.certificate is not None and config.private_key is not None
        policy = getattr(security_policies,
                         f"SecurityPolicy{config.security_policy.replace('_', '')}")
        mode = getattr(asyncua.ua.MessageSecurityMode, config.security_mode)
        uri = application_uri(config.certificate)
        if uri is not None:
            # servers check the client's application URI against its certificate's
            client.application_uri = uri
        try:
            await asyncio.wait_for(client.set_security(
                policy, str(config.certificate), str(config.private_key),
                server_certificate=(None if config.server_certificate is None
                                    else str(config.server_certificate)),
                mode=mode), config.timeout * 2)
        except (OSError, TimeoutError, ValueError, asyncua.ua.UaError) as exc:
            raise IngestError(f"{self.describe()}: security {config.security_policy} "
                              f"{config.security_mode}: {_reason(exc)}") from exc

    async def _subscribe(self, client: Client, asyncua: Any) -> None:
        ua = asyncua.ua
        config = self.config
        now = time.time()
        requests = []
        for handle, (channel, spec) in enumerate(config.nodes.items(), start=1):
            topic = self.topics[channel]
            label = spec.node or spec.path or "?"
            try:
                node = await self._find(client, spec, ua)
            except (ua.UaError, ValueError) as exc:
                reason = _reason(exc)
                log.warning("%s: %s (%s): %s", self.describe(), label, channel, reason)
                self._pending.put_nowait(node_error_message(topic, label, reason, now))
                continue
            unit = spec.unit or await self._unit(node, ua)
            log.info("%s: %s <- node %s [%s]", self.describe(), channel, label,
                     unit or "no unit")
            self._items[handle] = _Item(channel, topic, label, unit)
            parameters = ua.MonitoringParameters(
                ClientHandle=handle, SamplingInterval=config.sampling_interval * 1000,
                QueueSize=config.queue_size, DiscardOldest=True,
                Filter=ua.DataChangeFilter(Trigger=ua.DataChangeTrigger.StatusValueTimestamp))
            requests.append(ua.MonitoredItemCreateRequest(
                ItemToMonitor=ua.ReadValueId(NodeId=node.nodeid,
                                             AttributeId=ua.AttributeIds.Value),
                MonitoringMode=ua.MonitoringMode.Reporting, RequestedParameters=parameters))
        if not requests:
            raise IngestError(f"{self.describe()}: none of the configured nodes was found")
        # iterator mode: notifications wait in the subscription's queue for the pump; a
        # pipeline that falls that far behind forces a reconnect rather than a silent loss
        from asyncua.common.subscription import OverflowPolicy

        subscription = await client.create_subscription(
            config.publishing_interval * 1000, None, queue_maxsize=self.max_pending,
            overflow=OverflowPolicy.DISCONNECT)
        self._subscription = subscription
        results = await subscription.create_monitored_items(requests)
        for request, result in zip(requests, results, strict=True):
            if isinstance(result, ua.StatusCode):
                handle = request.RequestedParameters.ClientHandle
                item = self._items.pop(handle)
                reason = f"the server refused to monitor it: {result.name}"
                log.warning("%s: %s (%s): %s", self.describe(), item.node, item.channel, reason)
                self._pending.put_nowait(node_error_message(item.topic, item.node, reason, now))
        if not self._items:
            raise IngestError(f"{self.describe()}: the server monitors none of the nodes")
        self._pump = asyncio.create_task(self._forward(subscription, ua), name="opcua-pump")

    async def _find(self, client: Client, spec: OpcUaNodeConfig, ua: Any) -> Node:
        if spec.path is not None:
            return await client.nodes.objects.get_child(spec.path.split("/"))
        assert spec.node is not None
        node_id = ua.NodeId.from_string(spec.node)
        uri = getattr(node_id, "NamespaceUri", None)
        if uri:
            # nsu=...: the index of that namespace on this server now
            index = await client.get_namespace_index(uri)
            node_id = ua.NodeId(node_id.Identifier, index, node_id.NodeIdType)
        return client.get_node(node_id)

    async def _unit(self, node: Node, ua: Any) -> str | None:
        """The unit of the node's EngineeringUnits property, if it has one."""
        try:
            prop = await node.get_child("0:EngineeringUnits")
            eu = await prop.read_value()
        except (ua.UaError, ValueError):
            return None
        if not isinstance(eu, ua.EUInformation):
            return None
        return eu_unit(eu.NamespaceUri, eu.UnitId, eu.DisplayName.Text if eu.DisplayName else None)

    # -- receiving ----------------------------------------------------------------------------

    async def _forward(self, subscription: Subscription, ua: Any) -> None:
        """Turn the subscription's notifications into RawMessages, in the order they came."""
        from asyncua.common.subscription import DataChangeEvent, StatusChangeEvent

        async for event in subscription:
            receive_time = time.time()
            if isinstance(event, DataChangeEvent):
                notification = event.data.monitored_item
                item = self._items.get(notification.ClientHandle)
                if item is None:
                    continue
                data = notification.Value
                status = data.StatusCode
                code = 0 if status is None else int(status.value)
                name = ua.status_codes.get_name_and_doc(code)[0]
                value = data.Value.Value if data.Value is not None else None
                await self._pending.put(value_message(
                    item.topic, item.node, value, code, name, data.SourceTimestamp,
                    data.ServerTimestamp, receive_time, item.unit))
            elif isinstance(event, StatusChangeEvent):
                status = event.notification.Status
                if not status.is_good():
                    self._fail(IngestError(f"{self.describe()}: the server ended the "
                                           f"subscription ({status.name})"))
                    return
        self._fail(IngestError(f"{self.describe()}: the subscription ended"))

    async def _on_connection_lost(self, exc: Exception) -> None:
        # asyncua's supervisor found the connection gone (it does not reconnect: ours does)
        self._fail(IngestError(f"{self.describe()}: connection lost: {_reason(exc)}"))

    def _fail(self, error: IngestError) -> None:
        """Remember the first failure and wake the reader (a full queue wakes it anyway)."""
        if self._lost is None:
            self._lost = error
        with contextlib.suppress(asyncio.QueueFull):
            self._pending.put_nowait(None)

    async def _close(self) -> None:
        if self._pump is not None:
            self._pump.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._pump
            self._pump = None
        client, self._client = self._client, None
        self._subscription = None
        if client is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(client.disconnect(), self.config.timeout)


def application_uri(certificate: Path) -> str | None:
    """The URI in a certificate's subject alternative names (DER or PEM), if any."""
    from cryptography import x509

    try:
        data = certificate.read_bytes()
        cert = (x509.load_pem_x509_certificate(data) if data.startswith(b"-----")
                else x509.load_der_x509_certificate(data))
        names = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName)
    except (OSError, ValueError, x509.ExtensionNotFound):
        return None
    uris = names.value.get_values_for_type(x509.UniformResourceIdentifier)
    return uris[0] if uris else None


def _reason(exc: BaseException) -> str:
    """An exception as a short reason: asyncua's status errors by their code's name."""
    code = getattr(exc, "code", None)
    if code is not None:
        try:
            from asyncua.ua.status_codes import get_name_and_doc

            name, doc = get_name_and_doc(int(code))
            return f"{name} ({doc.rstrip('.')})"
        except (ImportError, TypeError, ValueError):
            pass
    return str(exc) or type(exc).__name__
