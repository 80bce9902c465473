"""The daemon's TOML file as pydantic v2 models, and ``load_daemon_config(path)``.

Dimensional quantities are strings with a unit ("5 s", "9950 ft", "0.3 kN"): a plain number is
refused, since the unit it was meant in cannot be known. Every mistake is raised as
:class:`tdmon.errors.ConfigError` naming the file, the dotted key and the reason. Paths in the
file are relative to the file.
"""

from __future__ import annotations

import ipaddress
import logging
import math
import os
import re
import stat
from collections.abc import Callable
from datetime import UTC, date, datetime
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from tdmon.channels import CHANNEL_UNITS, ChannelSpec, check_channel, validate_prefix
from tdmon.config.common import (
    UNITS_REQUIRED,
    CrossFieldError,
    Duration,
    FrictionFactor,
    missing_unit,
    quantity,
    read_toml,
    validation_to_config_error,
)
from tdmon.config.limits import MAX_PAYLOAD_BYTES, MAX_QUEUE
from tdmon.config.rig_names import DEFAULT_NAME_PATTERN
from tdmon.config.thermal import FrictionModelConfig
from tdmon.errors import ConfigError
from tdmon.units import conversion, parse_quantity, parse_time

logger = logging.getLogger(__name__)


def _quantity(target: str) -> BeforeValidator:
    # config.common's reader: in a file a plain number for a dimensional key is an error
    return quantity(target)


Seconds = Duration
Meters = Annotated[float, _quantity("m")]
Newtons = Annotated[float, _quantity("N")]
NewtonMetres = Annotated[float, _quantity("N*m")]
MetersPerSecond = Annotated[float, _quantity("m/s")]
RadPerSecond = Annotated[float, _quantity("rad/s")]
CubicMetersPerSecond = Annotated[float, _quantity("m**3/s")]


class _Model(BaseModel):
    # defaults are SI floats written in Python, not a file's values: they are not validated
    # (a file's plain number needs a unit; a default does not)
    model_config = ConfigDict(extra="forbid", frozen=True)


def _resolved_password(password: str | None, env: str | None, file: Path | None
                       ) -> str | None:
    """The password given as ``password``, in the environment variable ``env`` or as the first
    line of ``file`` (read at each connection, so that a changed file is used); None when none
    is given or the variable is unset.

    Raises
    ------
    OSError
        ``file`` cannot be read.
    """
    if password is not None:
        return password
    if env is not None:
        return os.environ.get(env)
    if file is not None:
        text = file.read_text(encoding="utf-8")
        return text.splitlines()[0] if text else ""
    return None


class TlsConfig(_Model):
    """TLS towards the broker. Paths relative to the config file."""

    ca_file: Path | None = None
    cert_file: Path | None = None
    key_file: Path | None = None
    insecure: bool = Field(default=False, description="skip host name verification (test brokers)")


class MqttConfig(_Model):
    """An MQTT broker connection (aiomqtt)."""

    host: str = "127.0.0.1"
    port: int = Field(default=1883, ge=1, le=65535)
    client_id: str = Field(default="tdmon", min_length=1, max_length=200)
    username: str | None = None
    password: str | None = None
    password_env: str | None = None  # read the password from this environment variable
    # read the password from this file (its first line; relative to the daemon file)
    password_file: Path | None = None
    tls: TlsConfig | None = None
    qos: Literal[0, 1, 2] = 1
    keepalive: int = Field(default=30, ge=5, le=3600)
    # False keeps the session (subscription, queued QoS 1 messages) over reconnects
    clean_session: bool = False

    @model_validator(mode="after")
    def _one_password(self, info: ValidationInfo) -> MqttConfig:
        given = [key for key in ("password", "password_env", "password_file")
                 if getattr(self, key) is not None]
        if len(given) > 1:
            raise ValueError(f"give one of password, password_env and password_file, not "
                             f"{' and '.join(given)}")
        base = (info.context or {}).get("base_dir")
        if base is not None and self.password_file is not None \
                and not self.password_file.is_absolute():
            object.__setattr__(self, "password_file", Path(base) / self.password_file)
        return self

    def resolved_password(self) -> str | None:
        """The password (:func:`_resolved_password`)."""
        return _resolved_password(self.password, self.password_env, self.password_file)


class ZenohTlsConfig(_Model):
    """TLS of a Zenoh session's ``tls/`` endpoints (zenoh's ``transport/link/tls``;
    docs/configuration.md, "Zenoh TLS and access control"). Paths relative to the config file."""

    ca_file: Path | None = Field(default=None, description="root_ca_certificate: the CA that "
                                 "signed the other side's certificate")
    cert_file: Path | None = Field(default=None, description="this side's certificate "
                                   "(listen_certificate and connect_certificate)")
    key_file: Path | None = Field(default=None, description="its private key "
                                  "(listen_private_key and connect_private_key)")
    mutual: bool = Field(default=False, description="enable_mtls: each side shows a "
                         "certificate signed by ca_file, or the link is refused")
    verify_name: bool = Field(default=True, description="verify_name_on_connect: the "
                              "endpoint's host name must be in the listener's certificate")

    @model_validator(mode="after")
    def _pairs(self) -> ZenohTlsConfig:
        if (self.cert_file is None) != (self.key_file is None):
            raise CrossFieldError("key_file" if self.key_file is None else "cert_file",
                                  "missing key (give cert_file and key_file together)")
        if self.mutual and (self.ca_file is None or self.cert_file is None):
            raise CrossFieldError("ca_file" if self.ca_file is None else "cert_file",
                                  "missing key (mutual TLS needs ca_file, cert_file and "
                                  "key_file)")
        return self


class ZenohConfig(_Model):
    """A Zenoh session. Peer mode on explicit endpoints needs no router."""

    mode: Literal["peer", "client", "router"] = "peer"
    listen: list[str] = Field(default_factory=list)
    connect: list[str] = Field(default_factory=list)
    scouting: bool = False  # multicast and gossip scouting; off: explicit endpoints only
    tls: ZenohTlsConfig | None = None
    #: zenoh's own ``access_control`` table, passed as it is (``enabled``,
    #: ``default_permission``, ``rules``, ``subjects``, ``policies``); zenoh checks it
    access_control: dict[str, Any] | None = None

    @model_validator(mode="after")
    def _resolve_tls_files(self, info: ValidationInfo) -> ZenohConfig:
        base = (info.context or {}).get("base_dir")
        if base is not None and self.tls is not None:
            for name in ("ca_file", "cert_file", "key_file"):
                path = getattr(self.tls, name)
                if path is not None and not path.is_absolute():
                    object.__setattr__(self.tls, name, Path(base) / path)
        return self

    @field_validator("listen", "connect")
    @classmethod
    def _endpoints(cls, value: list[str]) -> list[str]:
        for endpoint in value:
            if "/" not in endpoint:
                raise ValueError(f"'{endpoint}' is not a Zenoh endpoint such as tcp/127.0.0.1:7447")
        return value


class McapSourceConfig(_Model):
    """Replay of a recording as a source."""

    path: Path
    speed: float | Literal["max"] = Field(
        default="max", description="real time x N, or 'max' for as fast as possible"
    )

    @field_validator("speed")
    @classmethod
    def _positive(cls, value: float | str) -> float | str:
        if not isinstance(value, str) and value <= 0:
            raise ValueError("speed must be positive or 'max'")
        return value


class Wits0ItemConfig(_Model):
    """A feed's change to one WITS item (docs/wits0.md): the channel it feeds (``false``:
    none) and its WITS unit name (e.g. "KDN", "KLB")."""

    channel: str | Literal[False] | None = None
    unit: str | None = Field(default=None, min_length=1)

    @field_validator("channel")
    @classmethod
    def _channel(cls, value: str | bool | None) -> str | bool | None:
        if isinstance(value, str):
            check_channel(value)
        return value


class Wits0Config(_Model):
    """A WITS Level 0 feed (docs/wits0.md): as TCP client of the rig's WITS server, as TCP
    server the rig pushes to, or on a serial line."""

    mode: Literal["tcp-client", "tcp-server", "serial"] = "tcp-client"
    host: str | None = None  # tcp-client: the rig's WITS server
    listen: str = "127.0.0.1"  # tcp-server: the address to listen on
    port: int | None = Field(default=None, ge=1, le=65535)
    device: str | None = None  # serial: e.g. /dev/ttyUSB0
    baud_rate: int = Field(default=9600, gt=0)
    # the default unit set of the items: the WITS specification's metric or field units
    units: Literal["metric", "field"] = "metric"
    # item code ("0114") -> channel and/or unit, over the default record 01 map
    items: dict[str, Wits0ItemConfig] = Field(default_factory=dict)
    # the zone of the date and time items (0105, 0106): an IANA name
    timezone: str = "UTC"
    # a feed silent for this long counts as lost: the daemon reconnects
    timeout: Seconds = Field(default=30.0, gt=0)

    @field_validator("timezone")
    @classmethod
    def _zone(cls, value: str) -> str:
        from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

        try:
            ZoneInfo(value)
        except (ZoneInfoNotFoundError, ValueError):
            raise ValueError(f"unknown time zone '{value}' (an IANA name such as 'UTC' or "
                             "'Europe/Oslo')") from None
        return value

    @model_validator(mode="after")
    def _endpoint(self) -> Wits0Config:
        if self.mode == "tcp-client" and (self.host is None or self.port is None):
            raise ValueError("mode 'tcp-client' needs host and port (the rig's WITS server)")
        if self.mode == "tcp-server" and self.port is None:
            raise ValueError("mode 'tcp-server' needs port (where the rig connects)")
        if self.mode == "serial" and not self.device:
            raise ValueError("mode 'serial' needs device (e.g. '/dev/ttyUSB0')")
        return self


# A NodeId as text (OPC UA Part 6, 5.3.1.10): "ns=2;s=Rig.HookLoad", "i=2258",
# "nsu=urn:rig;s=HKLD", "ns=3;g=<guid>", "ns=4;b=<base64>"
_NODE_ID = re.compile(r"(?:(?:ns=\d+|nsu=[^;]+);)?"
                      r"(?:i=\d+|s=.+|g=[0-9A-Fa-f-]{36}|b=[A-Za-z0-9+/=]+)")
# One browse name of a browse path: "2:HookLoad" (namespace index and name) or "Objects" (0)
_BROWSE_NAME = re.compile(r"(?:\d+:)?[^/:]+")


class OpcUaNodeConfig(_Model):
    """The node feeding one channel: its NodeId (``node``) or its browse path from the
    Objects folder (``path``), and optionally its unit over the node's EngineeringUnits."""

    node: str | None = None
    path: str | None = None
    unit: str | None = Field(default=None, min_length=1)

    @field_validator("node")
    @classmethod
    def _node_id(cls, value: str | None) -> str | None:
        if value is not None and not _NODE_ID.fullmatch(value.strip()):
            raise ValueError(f"'{value}' is not a NodeId such as 'ns=2;s=Rig.HookLoad', "
                             "'nsu=urn:rig;s=HKLD' or 'ns=2;i=1001'")
        return None if value is None else value.strip()

    @field_validator("path")
    @classmethod
    def _browse_path(cls, value: str | None) -> str | None:
        if value is None:
            return None
        names = value.strip().strip("/").split("/")
        if not all(_BROWSE_NAME.fullmatch(name.strip()) for name in names):
            raise ValueError(f"'{value}' is not a browse path such as '2:Rig/2:HookLoad' "
                             "(browse names from the Objects folder, each 'index:name')")
        return "/".join(name.strip() for name in names)

    @model_validator(mode="after")
    def _node_or_path(self) -> OpcUaNodeConfig:
        if (self.node is None) == (self.path is None):
            raise ValueError("give one of node (a NodeId) and path (a browse path)")
        return self


class OpcUaConfig(_Model):
    """An OPC UA server of the rig's drilling control system (docs/opcua.md): one
    subscription, a data-change monitored item per configured channel."""

    endpoint: str  # opc.tcp://HOST:PORT[/PATH]
    # the security policies of OPC UA Part 7 that asyncua implements, without the deprecated
    # Basic128Rsa15 and Basic256
    security_policy: Literal["None", "Basic256Sha256", "Aes128_Sha256_RsaOaep",
                             "Aes256_Sha256_RsaPss"] = "None"
    security_mode: Literal["None", "Sign", "SignAndEncrypt"] = "None"
    # the client's application instance certificate and its key (DER or PEM), needed by a
    # security policy other than None; relative to the daemon file
    certificate: Path | None = None
    private_key: Path | None = None
    # the server's certificate: when given, only a server holding it is accepted; otherwise
    # the one the server's endpoint shows is taken
    server_certificate: Path | None = None
    username: str | None = Field(default=None, min_length=1)
    password: str | None = None
    password_env: str | None = None
    password_file: Path | None = None
    # how often the server sends what changed (the rig's rate), how often it samples each
    # node (0: every value the server gets), and how many values it queues per node in between
    publishing_interval: Seconds = Field(default=1.0, gt=0)
    sampling_interval: Seconds = Field(default=0.0, ge=0)
    queue_size: int = Field(default=100, ge=1, le=100_000)
    # a request unanswered for this long, or a server whose state cannot be read for this long
    # (checked every timeout / 2), counts as lost: the daemon reconnects
    timeout: Seconds = Field(default=10.0, gt=0)
    # channel -> its node: a NodeId as text, or a table with node or path (and unit)
    nodes: dict[str, OpcUaNodeConfig] = Field(min_length=1)

    @field_validator("endpoint")
    @classmethod
    def _endpoint(cls, value: str) -> str:
        from urllib.parse import urlsplit

        parts = urlsplit(value)
        try:
            port = parts.port
        except ValueError:
            port = None
        if parts.scheme != "opc.tcp" or not parts.hostname or port is None:
            raise ValueError(f"'{value}' is not an OPC UA endpoint such as "
                             "'opc.tcp://10.0.0.5:4840'")
        return value

    @field_validator("nodes", mode="before")
    @classmethod
    def _short_form(cls, value: Any) -> Any:
        # hookload = "ns=2;s=HKLD" is short for [sources.opcua.nodes.hookload] node = "..."
        if isinstance(value, dict):
            return {channel: {"node": node} if isinstance(node, str) else node
                    for channel, node in value.items()}
        return value

    @field_validator("nodes")
    @classmethod
    def _channels(cls, value: dict[str, OpcUaNodeConfig]) -> dict[str, OpcUaNodeConfig]:
        for channel in value:
            check_channel(channel)
        return value

    @model_validator(mode="after")
    def _security(self, info: ValidationInfo) -> OpcUaConfig:
        if (self.security_policy == "None") != (self.security_mode == "None"):
            raise CrossFieldError("security_mode", f"policy '{self.security_policy}' with mode "
                                  f"'{self.security_mode}': give both as None, or a policy "
                                  "with Sign or SignAndEncrypt")
        if self.security_policy != "None":
            for key in ("certificate", "private_key"):
                if getattr(self, key) is None:
                    raise CrossFieldError(key, f"security policy '{self.security_policy}' "
                                          "needs the client's certificate and private_key")
        self._check_password()
        self._resolve_files((info.context or {}).get("base_dir"))
        return self

    def _check_password(self) -> None:
        """One way to give the password, with a user name; its variable set."""
        given = [key for key in ("password", "password_env", "password_file")
                 if getattr(self, key) is not None]
        if len(given) > 1:
            raise CrossFieldError(given[1], f"give one of password, password_env and "
                                  f"password_file, not {' and '.join(given)}")
        if given and self.username is None:
            raise CrossFieldError("username", f"{given[0]} needs a username")
        if self.password_env is not None and self.password_env not in os.environ:
            raise CrossFieldError("password_env",
                                  f"environment variable {self.password_env} is not set")

    def _resolve_files(self, base: str | Path | None) -> None:
        """Certificate, key and password files relative to the daemon file, and there."""
        if base is None:
            return
        for key in ("certificate", "private_key", "server_certificate", "password_file"):
            path = getattr(self, key)
            if path is None:
                continue
            if not path.is_absolute():
                path = Path(base) / path
                object.__setattr__(self, key, path)
            if not path.is_file():
                raise CrossFieldError(key, f"no such file: {path}")
            if key == "password_file":
                warn_if_readable_by_others(path, "sources.opcua.password_file")

    def resolved_password(self) -> str | None:
        """The password (:func:`_resolved_password`)."""
        return _resolved_password(self.password, self.password_env, self.password_file)


class SourcesConfig(_Model):
    mqtt: MqttConfig | None = None
    zenoh: ZenohConfig | None = None
    mcap: McapSourceConfig | None = None
    wits0: Wits0Config | None = None
    opcua: OpcUaConfig | None = None

    @model_validator(mode="after")
    def _at_least_one(self) -> SourcesConfig:
        if (self.mqtt is None and self.zenoh is None and self.mcap is None
                and self.wits0 is None and self.opcua is None):
            raise ValueError("configure at least one source: [sources.mqtt], [sources.zenoh], "
                             "[sources.mcap], [sources.wits0] or [sources.opcua]")
        return self


#: Lowest value a depth channel takes when ``min`` is not configured [m]. Measured depths and
#: the block position start at the drill floor; a depth tracker zeroed a little off reads a
#: little below 0, a sign or datum mistake reads far below: 2 m separates the two.
DEFAULT_MINIMUM: dict[str, float] = {"bit_depth": -2.0, "hole_depth": -2.0,
                                     "block_position": -2.0}

#: How far beyond the well file's total depth a bit or hole depth may lie when ``beyond_well``
#: is not configured [m]: a well file kept a day or two behind the drilling (a few hundred
#: metres) is not refused, a depth in feet taken as metres (x 3.28) is.
DEFAULT_BEYOND_WELL = 500.0

#: Channels that are measured depths in the hole (``beyond_well`` applies to them).
DEPTH_CHANNELS = ("bit_depth", "hole_depth")


class ChannelConfig(_Model):
    """How a rig topic feeds a canonical channel; bounds are in the channel's SI unit."""

    topic: str | None = None  # topic after the prefix (default: the channel name)
    unit: str | None = None  # unit when the payload has none, e.g. "kN"
    min: float | str | None = None  # default: DEFAULT_MINIMUM for depths, else none
    max: float | str | None = None
    # bit and hole depth only: how far beyond the well file's total depth a value may lie
    # (default DEFAULT_BEYOND_WELL; needs `well`)
    beyond_well: Meters | None = Field(default=None, ge=0)


class PublishConfig(_Model):
    """Publishing results on ``<prefix>/tdmon/<name>``."""

    mqtt: bool | MqttConfig = False
    zenoh: bool | ZenohConfig = False
    names: list[str] = Field(default_factory=lambda: ["state", "model", "estimate", "alarm",
                                                      "status", "well", "profile"])
    qos: Literal[0, 1, 2] = 1
    status_interval: Seconds = Field(default=1.0, gt=0)


class RecorderConfig(_Model):
    enabled: bool = False
    output: Path = Path("recordings")
    rotation: Seconds = Field(default=3600.0, gt=0)
    flush_interval: Seconds = Field(default=2.0, gt=0)
    process: Literal["auto", "child", "inline"] = Field(
        default="auto",
        description="where the recorder encodes and writes: 'child' in a process of its own "
                    "(on another core), 'inline' in the daemon's; 'auto' is 'child' when the "
                    "daemon may use two cores or more (docs/daemon.md)")


class RerunConfig(_Model):
    mode: Literal["off", "file", "live"] = "off"
    path: Path | None = None
    port: int = Field(default=9876, ge=1, le=65535)

    @model_validator(mode="after")
    def _file_mode_needs_path(self) -> RerunConfig:
        if self.path is None and self.mode == "file":
            raise CrossFieldError("path", "mode 'file' needs a path for the .rrd file")
        return self


def _at_most(limit: int, why: str) -> Callable[[Any], Any]:
    """A check before pydantic's own that a number is at most ``limit``, with the reason:
    pydantic's own words for 1e30 are about parsing a string."""

    def check(value: Any) -> Any:
        if isinstance(value, (int, float)) and not isinstance(value, bool) and value > limit:
            raise ValueError(f"{value:g} is more than {limit} {why}")
        return value

    return check


#: a queue's length: each waiting message holds up to ``max_payload_bytes``
QueueSize = Annotated[int, BeforeValidator(_at_most(
    MAX_QUEUE, "messages, the most a queue may hold (each holds its payload in memory)")),
    Field(ge=1)]


class QueuesConfig(_Model):
    ingest: QueueSize = Field(default=10_000, description="raw messages waiting for the pipeline")
    publish: QueueSize = Field(default=10_000, description="results waiting for a publisher")
    max_payload_bytes: Annotated[int, BeforeValidator(_at_most(
        MAX_PAYLOAD_BYTES, "bytes, more than any rig message needs"))] = Field(default=4096, ge=16)


def _unix_time(value: Any, name: str, example: str) -> Any:
    """A rig time from a TOML datetime, date, ISO string or Unix seconds [s since 1970, UTC];
    anything else is left to the field's own check. ``name`` and ``example`` word the error."""
    if isinstance(value, datetime):
        return (value if value.tzinfo else value.replace(tzinfo=UTC)).timestamp()
    if isinstance(value, date):
        return datetime(value.year, value.month, value.day, tzinfo=UTC).timestamp()
    if isinstance(value, str | int | float) and not isinstance(value, bool):
        seconds = parse_time(value)
        if isinstance(seconds, str):
            raise ValueError(seconds.replace("'t'", name) + f" (give e.g. \"{example}\")")
        return seconds
    return value


class AlignConfig(_Model):
    stale_timeout: Seconds = Field(default=5.0, gt=0, description="older channels are left out")
    max_wait: Seconds = Field(
        default=0.25, ge=0, description="how long a hook-load frame waits for the other channels"
    )
    # channels a frame waits for while they keep pace with the hook load (default: all)
    wait_for: list[str] | None = None
    # the rig clock (docs/daemon.md, "Clock faults"): a sample stamped more than this ahead
    # of its receive time (plus the rig clock's known offset) is rejected; 10 s is well above
    # NTP skew and the jitter of the bundled replays (2.8 s), and bounds what one such
    # sample that slips through can hold frames back
    future_tolerance: Seconds = Field(default=10.0, gt=0)
    # this many samples in a row, consistently off by more than the tolerance (offsets within
    # clock_jump_spread of each other), are a clock jump: one alarm, the aligner re-anchors
    clock_jump_samples: int = Field(default=5, ge=2, le=1000)
    clock_jump_spread: Seconds = Field(default=5.0, gt=0)
    # a stamp before this is a rig clock never set (t = 0 is 1970): rejected; ISO 8601 date
    # or time (UTC unless it says), or Unix seconds
    earliest_time: float = Field(default=946_684_800.0)  # 2000-01-01T00:00:00Z

    @field_validator("earliest_time", mode="before")
    @classmethod
    def _earliest(cls, value: Any) -> Any:
        return _unix_time(value, "the time", "2000-01-01")


class RigStateConfig(_Model):
    in_slips_hookload: Newtons = Field(
        default=400e3, description="below this hook load the string is in slips"
    )
    moving_speed: MetersPerSecond = Field(default=0.05, gt=0)
    rotating_rpm: RadPerSecond = Field(default=5 * math.pi / 30, ge=0)
    circulating_flow: CubicMetersPerSecond = Field(default=100 / 60_000, ge=0)
    on_bottom: Meters = Field(default=0.5, ge=0)
    steady_frames: int = Field(default=3, ge=1)
    # drilling ahead: the bit within on_bottom of a hole depth that deepened within this long
    # is on bottom whatever the weight on bit reads (docs/drilling.md)
    drilling_ahead_time: Seconds = Field(default=120.0, gt=0)
    # rotation needs the surface torque above its still-string zero offset by at least this
    # (and 4 standard deviations of its level), whenever a torque channel is there
    rotating_torque: NewtonMetres = Field(default=100.0, ge=0)
    # the torque level is the mean of its samples over this long
    torque_average: Seconds = Field(default=5.0, gt=0)
    # a channel unchanged (within its resolution) while its neighbours say it must move, for
    # this long in all and over this many of its own samples, is frozen
    frozen_time: Seconds = Field(default=30.0, gt=0)
    frozen_samples: int = Field(default=4, ge=2)
    # per channel, the change below which a reading counts as unchanged ("0.5 kN" for a hook
    # load sent in whole kN); the channels of tdmon.calib.frozen, each with its unit
    frozen_resolution: dict[str, float] = Field(default_factory=dict)

    @field_validator("frozen_resolution", mode="before")
    @classmethod
    def _resolutions(cls, value: Any) -> Any:
        from tdmon.calib.frozen import FROZEN_CHANNELS

        if not isinstance(value, dict):
            raise ValueError("a table of channel = \"resolution with its unit\"")
        out: dict[str, float] = {}
        for channel, text in value.items():
            check_channel(channel, FROZEN_CHANNELS)
            if not isinstance(text, str):
                raise ValueError(f"{channel}: give the resolution with its unit "
                                 f"(e.g. \"1 {CHANNEL_UNITS[channel][0]}\")")
            try:
                resolution = parse_quantity(text, CHANNEL_UNITS[channel][0])
            except ValueError as exc:
                raise ValueError(f"{channel}: {exc}") from exc
            if not (math.isfinite(resolution) and resolution >= 0.0):
                raise ValueError(f"{channel}: the resolution must be a finite amount >= 0")
            out[channel] = resolution
        return out


class MonitorConfig(_Model):
    mu: FrictionFactor = 0.25  # friction factor of the modelled curves
    band_mu: list[FrictionFactor] = Field(default_factory=lambda: [0.1, 0.2, 0.3, 0.4])
    method: Literal["aadnoy", "soft-string"] = "aadnoy"
    grid_step: Meters = Field(default=10.0, gt=0)
    # drilling (docs/drilling.md): the bit torque drilling without a downhole torque, before
    # the first tag's torque step is known: mu_b W D_b / 3 (Pessier and Fear 1992) with the
    # bit's diameter and its specific coefficient of sliding friction (both, or neither)
    bit_diameter: Meters | None = Field(default=None, gt=0)
    bit_friction: float | None = Field(default=None, gt=0, lt=2)
    # the bit torque of a tag is the mean torque step of its first this many seconds on bottom
    tag_settle: Seconds = Field(default=30.0, gt=0)

    @model_validator(mode="after")
    def _bit_model(self) -> MonitorConfig:
        if (self.bit_diameter is None) != (self.bit_friction is None):
            raise ValueError("the bit torque model needs both bit_diameter and bit_friction")
        return self

    @field_validator("band_mu")
    @classmethod
    def _band(cls, value: list[float]) -> list[float]:
        return sorted(value)  # each a FrictionFactor (config.common's one rule)


class CalibrationConfig(_Model):
    """Live back-calculation (tdmon.calib) in the daemon; needs a well file."""

    enabled: bool = False
    # hook load up to the block weight plus this margin means in slips (replaces
    # [rig_state] in_slips_hookload when calibration is on)
    in_slips_margin: Newtons = Field(default=150e3, ge=0)
    # ... but for a light string: this share of its modelled buoyed weight at the bit depth,
    # at least in_slips_min_margin (in_slips_margin is then the largest margin)
    in_slips_fraction: float = Field(default=0.5, gt=0, le=1)
    in_slips_min_margin: Newtons = Field(default=20e3, ge=0)
    # live mu(T) calibration (needs the well file's [temperature] table): "family" calibrates
    # the coefficients of a section's law, "scale" one factor on `lab_fit`, "off" neither
    mu_t: Literal["off", "family", "scale"] = "family"
    # the hole section whose law is calibrated (name or index); default the deepest one,
    # where the bit is and where the temperature range is widest
    mu_t_section: str | int | None = None
    # the laboratory law scaled in "scale" mode: a number, a published fit's name or a table
    lab_fit: FrictionModelConfig | None = None
    # prior standard deviation of each parameter, in the order of the law's coefficients
    # (default: max(|coefficient|, 0.01))
    mu_t_prior_std: list[float] | None = None
    # /tdmon/profile is sent again when the friction profile changed, at most this often
    # (rig time, so that replays give the same messages at any speed)
    profile_interval: Seconds = Field(default=30.0, gt=0)
    # joint friction and weight-factor estimate (docs/back-calculation.md, "Friction and weight
    # together"): the prior of the factor on the modelled buoyed string weight, and the
    # relative weight difference the weight-mismatch alarm reports
    weight_factor: float = Field(default=1.0, gt=0.5, lt=1.5)
    weight_factor_std: float = Field(default=0.05, gt=0, le=0.5)
    weight_mismatch_tolerance: float = Field(default=0.01, gt=0, lt=0.5)
    # the hook-load measurement in the joint estimate (docs/hookload.md; the sensor's place
    # and rigging are the well file's [hookload_sensor]): how well the block weight of the well
    # file is known, the sensor's zero offset (prior spread and drift per hour), the sheave
    # efficiency's prior spread (deadline sensors; its centre is the well file's efficiency),
    # the unmodelled hoisting/lowering hysteresis relative to the load, and the torque
    # sensor's zero and scale uncertainty
    block_weight_std: Newtons = Field(default=20e3, gt=0, le=1e6)
    hookload_offset_std: Newtons = Field(default=20e3, gt=0, le=1e6)
    hookload_offset_drift: Newtons = Field(default=20e3, ge=0, le=1e6)
    sheave_efficiency_std: float = Field(default=0.02, gt=0, le=0.1)
    hookload_hysteresis: float = Field(default=0.01, ge=0, le=0.2)
    torque_uncertainty: NewtonMetres = Field(default=300.0, ge=0, le=1e5)

    @model_validator(mode="after")
    def _scale_needs_lab_fit(self) -> CalibrationConfig:
        if self.mu_t == "scale" and self.lab_fit is None:
            raise ValueError("mu_t = 'scale' needs lab_fit (the laboratory law to scale)")
        if self.mu_t_prior_std is not None and not all(
                math.isfinite(s) and s > 0 for s in self.mu_t_prior_std):
            raise ValueError("mu_t_prior_std must be positive numbers")
        return self


class DisplayConfig(_Model):
    """``[display]``: the units Rerun views show (``units = "field"``: klbf, kft lbf, ft, ppg,
    degF); recordings and published messages stay SI. ``--units`` and ``TDMON_UNITS`` win."""

    units: Literal["si", "field"] = "si"


class RunConfig(_Model):
    """``[[runs]]``: from rig time ``start`` on, the string is the one of well file ``well``
    (a trip that changes the string; docs/configuration.md). The top-level ``well`` is the
    run before the first start."""

    start: float
    well: Path

    @field_validator("start", mode="before")
    @classmethod
    def _start(cls, value: Any) -> Any:
        return _unix_time(value, "start", "2024-03-05T12:10:00Z")


#: The sections a rig of a fleet daemon may set for itself (``[[rigs]]``); the keys it sets
#: replace the file's, the others are the file's (docs/daemon.md, "Many rigs").
RIG_SECTIONS = ("channels", "align", "rig_state", "monitor", "calibration")


class RigConfig(_Model):
    """``[[rigs]]``: one rig of a fleet daemon, its prefix, well file and own settings."""

    prefix: str = Field(min_length=1)
    well: Path | None = None  # default: the file's `well`
    channels: dict[str, ChannelConfig] | None = None
    align: AlignConfig | None = None
    rig_state: RigStateConfig | None = None
    monitor: MonitorConfig | None = None
    calibration: CalibrationConfig | None = None

    @field_validator("prefix")
    @classmethod
    def _prefix(cls, value: str) -> str:
        return validate_prefix(value)


class FleetConfig(_Model):
    """``[fleet]``: rigs found by their topics. Every ``<prefix>/<name>/...`` is rig
    ``<prefix>/<name>`` from its first message on; its well file is ``<wells>/<name>.toml``
    (else the file's ``well``)."""

    discover: bool = True
    wells: Path | None = None  # folder of well files named after the rigs
    # a bound on the rigs found (a stray publisher must not grow the daemon without limit)
    max_rigs: int = Field(default=200, ge=1, le=100_000)
    # what a found rig's name must match besides the fixed rule (tdmon/config/rig_names.py):
    # it narrows the rule, never widens it
    name_pattern: str = DEFAULT_NAME_PATTERN
    # a found rig silent this long is retired: its recording finished, its slot freed
    idle_rig_timeout: Seconds = Field(default=3600.0, gt=0)

    @field_validator("name_pattern")
    @classmethod
    def _name_pattern(cls, value: str) -> str:
        try:
            re.compile(value)
        except re.error as exc:
            raise ValueError(f"not a regular expression: {exc}") from None
        return value


class DaemonConfig(_Model):
    """The whole daemon file."""

    prefix: str = Field(min_length=1)
    well: Path | None = None
    sources: SourcesConfig
    channels: dict[str, ChannelConfig] = Field(default_factory=dict)
    publish: PublishConfig = Field(default_factory=PublishConfig)
    recorder: RecorderConfig = Field(default_factory=RecorderConfig)
    rerun: RerunConfig = Field(default_factory=RerunConfig)
    queues: QueuesConfig = Field(default_factory=QueuesConfig)
    align: AlignConfig = Field(default_factory=AlignConfig)
    rig_state: RigStateConfig = Field(default_factory=RigStateConfig)
    monitor: MonitorConfig = Field(default_factory=MonitorConfig)
    calibration: CalibrationConfig = Field(default_factory=CalibrationConfig)
    display: DisplayConfig = Field(default_factory=DisplayConfig)
    runs: list[RunConfig] = Field(default_factory=list)
    # many rigs in one daemon (docs/daemon.md, "Many rigs"): listed, and/or found by topic
    rigs: list[RigConfig] = Field(default_factory=list)
    fleet: FleetConfig | None = None
    #: the file this was read from (set by load_daemon_config; paths are relative to it)
    source_file: Path | None = Field(default=None, exclude=True)

    @field_validator("prefix")
    @classmethod
    def _prefix(cls, value: str) -> str:
        return validate_prefix(value)

    @model_validator(mode="after")
    def _publishing_shares_a_source_connection(self) -> DaemonConfig:
        """``publish.zenoh = true`` and ``publish.mqtt = true`` publish over the source's
        session or broker, so that source must be configured."""
        if self.publish.zenoh is True and self.sources.zenoh is None:
            raise CrossFieldError("publish.zenoh",
                                  "true needs [sources.zenoh]; give a table with endpoints")
        if self.publish.mqtt is True and self.sources.mqtt is None:
            raise CrossFieldError("publish.mqtt",
                                  "true needs [sources.mqtt]; give a table with the broker")
        return self

    @field_validator("channels")
    @classmethod
    def _channels(cls, value: dict[str, ChannelConfig]) -> dict[str, ChannelConfig]:
        for name in value:
            check_channel(name)
        return value

    def channel_specs(self) -> list[ChannelSpec]:
        """Channel map for the decoder; every canonical channel is accepted on its own name.
        Depth channels without a configured ``min`` get :data:`DEFAULT_MINIMUM`."""
        specs = []
        for name, (target, _) in CHANNEL_UNITS.items():
            cfg = self.channels.get(name, ChannelConfig())
            specs.append(ChannelSpec(
                channel=name,
                topic=cfg.topic or name,
                unit=cfg.unit,
                minimum=(DEFAULT_MINIMUM.get(name) if cfg.min is None
                         else parse_quantity(cfg.min, target)),
                maximum=None if cfg.max is None else parse_quantity(cfg.max, target),
            ))
        return specs

    def depth_margins(self) -> dict[str, float]:
        """How far beyond the well's total depth each depth channel may lie [m]."""
        margins = {}
        for name in DEPTH_CHANNELS:
            cfg = self.channels.get(name)
            margin = None if cfg is None else cfg.beyond_well
            margins[name] = DEFAULT_BEYOND_WELL if margin is None else margin
        return margins

    @property
    def is_fleet(self) -> bool:
        """True when the file serves many rigs (``[[rigs]]`` or ``[fleet]``), each under
        ``prefix``; False for the single rig ``prefix``."""
        return bool(self.rigs) or (self.fleet is not None and self.fleet.discover)

    def for_rig(self, prefix: str, rig: RigConfig | None = None,
                well: Path | None = None) -> DaemonConfig:
        """The single-rig configuration of rig ``prefix``: the file's sections with the keys
        ``rig`` sets replaced, its well file (``well``, else the rig's, else the file's)."""
        update: dict[str, Any] = {"prefix": prefix, "rigs": [], "fleet": None}
        if rig is not None:
            for name in RIG_SECTIONS:
                own = getattr(rig, name)
                if own is None:
                    continue
                if name == "channels":
                    update[name] = {**self.channels, **own}
                    continue
                base = getattr(self, name)
                merged = base.model_copy(update={key: getattr(own, key)
                                                 for key in own.model_fields_set})
                # the section's own checks across its keys, on the merged values
                update[name] = type(base).model_validate(merged.model_dump())
            if rig.well is not None:
                update["well"] = rig.well
        if well is not None:
            update["well"] = well
        return self.model_copy(update=update)

    def resolve(self, path: Path) -> Path:
        """A path from the file, made absolute relative to the file's folder."""
        if path.is_absolute() or self.source_file is None:
            return path
        return self.source_file.parent / path


def load_daemon_config(path: str | os.PathLike[str]) -> DaemonConfig:
    """Read and validate a daemon TOML file.

    Raises
    ------
    ConfigError
        The file is missing, not TOML, or invalid; the message names the key and reason.
    """
    file = Path(path)
    data = read_toml(file)
    return parse_daemon_config(data, file)


def parse_daemon_config(data: dict[str, Any], file: Path) -> DaemonConfig:  # noqa: C901  (complex today; simplify when next touched)
    """Validate already-parsed TOML data (see :func:`load_daemon_config`)."""
    try:
        config = DaemonConfig.model_validate(
            {**data, "source_file": None},
            context={UNITS_REQUIRED: True, "base_dir": file.parent})
    except ValidationError as exc:
        raise validation_to_config_error(file, exc, DaemonConfig) from exc
    except ValueError as exc:  # a validator outside pydantic's wrapping
        raise ConfigError(str(file), "", str(exc)) from exc
    config = config.model_copy(update={"source_file": file.resolve()})
    for name, channel_cfg in config.channels.items():
        # configured units and bounds are checked now, not when the first message arrives
        target = CHANNEL_UNITS[name][0]
        for key in ("min", "max"):
            bound = getattr(channel_cfg, key)
            if bound is not None:
                reason = missing_unit(bound, target, key)
                if reason is not None:
                    raise ConfigError(str(file), f"channels.{name}.{key}", reason)
                try:
                    parse_quantity(bound, target)
                except ValueError as exc:
                    raise ConfigError(str(file), f"channels.{name}.{key}", str(exc)) from exc
        if channel_cfg.unit is not None:
            try:
                conversion(channel_cfg.unit, target)
            except ValueError as exc:
                raise ConfigError(str(file), f"channels.{name}.unit", str(exc)) from exc
    _check_brokers(config, file)
    _check_zenoh_files(config, file)
    for name in config.publish.names:
        if not name or "/" in name:
            raise ConfigError(str(file), "publish.names", f"'{name}' is not a message name")
    for name, channel_cfg in config.channels.items():
        if channel_cfg.beyond_well is not None and name not in DEPTH_CHANNELS:
            raise ConfigError(str(file), f"channels.{name}.beyond_well",
                              f"only depths ({', '.join(DEPTH_CHANNELS)}) can lie beyond the "
                              "well; remove the key")
    for channel in config.align.wait_for or ():
        try:
            check_channel(channel)
        except ValueError as exc:
            raise ConfigError(str(file), "align.wait_for", str(exc)) from None
    if config.calibration.enabled and config.well is None:
        raise ConfigError(str(file), "calibration.enabled", "calibration needs a well file")
    if config.well is not None and not config.resolve(config.well).exists():
        raise ConfigError(str(file), "well", f"file not found: {config.resolve(config.well)}")
    _check_runs(config, file)
    _check_rigs(config, file)
    return config


def _check_runs(config: DaemonConfig, file: Path) -> None:
    """``[[runs]]`` need the top-level well (the first run), start times in order and their
    well files present."""
    previous = -math.inf
    for index, run in enumerate(config.runs):
        if config.well is None:
            raise ConfigError(str(file), "runs", "runs need the top-level 'well' (the well "
                              "file before the first run's start)")
        if not run.start > previous:
            raise ConfigError(str(file), f"runs[{index}].start",
                              "each run must start after the one before it")
        previous = run.start
        if not config.resolve(run.well).exists():
            raise ConfigError(str(file), f"runs[{index}].well",
                              f"file not found: {config.resolve(run.well)}")


def _check_rigs(config: DaemonConfig, file: Path) -> None:  # noqa: C901  (complex today; simplify when next touched)
    """The ``[[rigs]]`` and ``[fleet]`` keys: each rig under ``prefix`` and listed once, its
    well file there, its settings valid once merged with the file's."""
    if not config.is_fleet:
        return
    if config.rerun.mode != "off":
        raise ConfigError(str(file), "rerun.mode", "a daemon of many rigs has no Rerun views; "
                          "set mode = 'off' and watch the fleet with 'tdmon fleet --rerun'")
    if config.sources.wits0 is not None:
        raise ConfigError(str(file), "sources.wits0", "a WITS0 feed is one rig's: give it a "
                          "daemon file of its own (without [[rigs]] and [fleet])")
    if config.sources.opcua is not None:
        raise ConfigError(str(file), "sources.opcua", "an OPC UA server is one rig's: give it "
                          "a daemon file of its own (without [[rigs]] and [fleet])")
    if config.fleet is not None and config.fleet.wells is not None \
            and not config.resolve(config.fleet.wells).is_dir():
        raise ConfigError(str(file), "fleet.wells",
                          f"no such folder: {config.resolve(config.fleet.wells)}")
    seen: set[str] = set()
    for index, rig in enumerate(config.rigs):
        key = f"rigs[{index}]"
        if not rig.prefix.startswith(config.prefix + "/"):
            raise ConfigError(str(file), f"{key}.prefix", f"'{rig.prefix}' is not under the "
                              f"file's prefix '{config.prefix}/': give e.g. "
                              f"'{config.prefix}/{rig.prefix.rsplit('/', 1)[-1]}'")
        if rig.prefix in seen:
            raise ConfigError(str(file), f"{key}.prefix", f"rig '{rig.prefix}' is listed twice")
        if any(rig.prefix.startswith(other + "/") or other.startswith(rig.prefix + "/")
               for other in seen):
            raise ConfigError(str(file), f"{key}.prefix",
                              f"'{rig.prefix}' nests with another rig's prefix")
        seen.add(rig.prefix)
        if "/tdmon/" in rig.prefix + "/":
            raise ConfigError(str(file), f"{key}.prefix", "'tdmon' is where results go")
        try:
            rig_config = config.for_rig(rig.prefix, rig)
        except ValidationError as exc:
            error = validation_to_config_error(file, exc)
            raise ConfigError(str(file), f"{key}.{error.key}".rstrip("."), error.reason) from exc
        if rig.well is not None and not rig_config.resolve(rig.well).exists():
            raise ConfigError(str(file), f"{key}.well",
                              f"file not found: {rig_config.resolve(rig.well)}")
        if rig_config.calibration.enabled and rig_config.well is None:
            raise ConfigError(str(file), f"{key}.well", "calibration needs a well file")


def broker_sections(config: DaemonConfig) -> list[tuple[str, MqttConfig]]:
    """Every MQTT connection of the file with its dotted key (``[publish.mqtt] = true``
    shares the source's connection and is checked there)."""
    brokers = []
    if config.sources.mqtt is not None:
        brokers.append(("sources.mqtt", config.sources.mqtt))
    if isinstance(config.publish.mqtt, MqttConfig):
        brokers.append(("publish.mqtt", config.publish.mqtt))
    return brokers


def _check_brokers(config: DaemonConfig, file: Path) -> None:
    """What a broker connection needs at start, so that a mistake stops the daemon with one
    line instead of a connection retried for ever: the password's variable or file, the TLS
    files. A clear-text password readable by group or others is a warning."""
    clear_text_in_toml = False
    for key, mqtt in broker_sections(config):
        if mqtt.password_env is not None and mqtt.password_env not in os.environ:
            raise ConfigError(str(file), f"{key}.password_env",
                              f"environment variable {mqtt.password_env} is not set")
        if mqtt.password_file is not None:
            try:
                secret = mqtt.resolved_password()
            except (OSError, UnicodeDecodeError) as exc:
                reason = "no such file" if isinstance(exc, FileNotFoundError) else str(exc)
                raise ConfigError(str(file), f"{key}.password_file",
                                  f"{mqtt.password_file}: {reason}") from exc
            if not secret:
                raise ConfigError(str(file), f"{key}.password_file",
                                  f"{mqtt.password_file}: the first line is empty")
            warn_if_readable_by_others(mqtt.password_file, f"{key}.password_file")
        clear_text_in_toml |= mqtt.password is not None
        if mqtt.tls is not None:
            for name in ("ca_file", "cert_file", "key_file"):
                path = getattr(mqtt.tls, name)
                if path is not None and not config.resolve(path).is_file():
                    raise ConfigError(str(file), f"{key}.tls.{name}",
                                      f"no such file: {config.resolve(path)}")
        warn_if_credentials_in_clear(key, mqtt)
    if clear_text_in_toml:
        warn_if_readable_by_others(file, "password")


def _check_zenoh_files(config: DaemonConfig, file: Path) -> None:
    """The Zenoh TLS files exist (zenoh's own message names none of our keys)."""
    for key, zenoh in (("sources.zenoh", config.sources.zenoh),
                       ("publish.zenoh", config.publish.zenoh)):
        if isinstance(zenoh, ZenohConfig) and zenoh.tls is not None:
            for name in ("ca_file", "cert_file", "key_file"):
                path = getattr(zenoh.tls, name)
                if path is not None and not path.is_file():
                    raise ConfigError(str(file), f"{key}.tls.{name}", f"no such file: {path}")


def _loopback(host: str) -> bool:
    if host.strip().lower() in ("localhost", "localhost.localdomain", "ip6-localhost"):
        return True
    try:
        return ipaddress.ip_address(host.strip().strip("[]")).is_loopback
    except ValueError:
        return False


def warn_if_credentials_in_clear(key: str, mqtt: MqttConfig) -> bool:
    """Log one warning when a user name or password goes to a broker off this machine without
    TLS (anyone on the path reads them); True when it warned."""
    credentials = mqtt.username is not None or any(
        getattr(mqtt, name) is not None for name in ("password", "password_env", "password_file"))
    if not credentials or mqtt.tls is not None or _loopback(mqtt.host):
        return False
    logger.warning("%s: the user name and password go to %s:%d in clear text (no [%s.tls]); "
                   "anyone on the network path can read them", key, mqtt.host, mqtt.port, key)
    return True


def warn_if_readable_by_others(path: Path, key: str) -> bool:
    """Log one warning when ``path``, which holds a clear-text password (``key``), can be read
    by the file's group or by others; True when it warned."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return False
    if not mode & (stat.S_IRWXG | stat.S_IRWXO):
        return False
    logger.warning("%s holds a clear-text password (%s) and is readable by others "
                   "(mode %03o): chmod 600 %s", path, key, stat.S_IMODE(mode), path)
    return True
