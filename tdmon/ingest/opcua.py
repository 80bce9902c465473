"""OPC UA values as tdmon input: the pure pieces of the OPC UA source and of the simulator's
server (docs/opcua.md). No asyncua here: the source and the server hand over plain values.

- :data:`UNECE_UNITS` and :func:`eu_unit`: a node's ``EngineeringUnits`` (an ``EUInformation``,
  OPC UA Part 8, 5.6.3: a UNECE common code packed into ``UnitId``, and a ``DisplayName``) to
  a unit spelling :mod:`tdmon.units` reads;
- :func:`value_message`: one data change (value, status code, source and server timestamps)
  as a :class:`~tdmon.ingest.types.RawMessage` in tdmon's own JSON payload, so that the
  pipeline records it raw, decodes it (converting the node's unit to SI) and replays it like
  any other input. A status that is not Good, or a value that is not a number, gives the same
  message with ``"error"``, which the decoder turns into a recorded rejection with that reason.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from datetime import UTC, datetime
from typing import Any, Final

from tdmon.ingest.types import RawMessage

#: the RawMessage source name of everything an OPC UA server gives
SOURCE: Final = "opcua"

#: ``EUInformation.NamespaceUri`` of units given by their UNECE common code (OPC UA Part 8)
UNECE_NAMESPACE: Final = "http://www.opcfoundation.org/UA/units/un/cefact"

#: UNECE Recommendation No. 20 common codes of the units a rig's control system uses for
#: tdmon's channels -> the spelling :mod:`tdmon.units` reads. Codes as OPC UA servers carry
#: them (the OPC Foundation's UNECE-to-OPC UA table): NEW newton, B47 kilonewton, C78
#: pound-force, NU newton metre, B48 kilonewton metre, 85 foot pound-force, MTR metre, FOT foot,
#: PAL pascal, KPA kilopascal, BAR bar, PS pound-force per square inch, RPM and M46
#: revolution per minute, 2A radian per second, MQS cubic metre per second, MQH cubic metre
#: per hour, L2 litre per minute, G2 US gallon per minute, KMQ kilogram per cubic metre, GE
#: pound per US gallon, CEL degree Celsius, FAH degree Fahrenheit, KEL kelvin.
UNECE_UNITS: Final[Mapping[str, str]] = {
    "NEW": "N", "B47": "kN", "C78": "lbf", "NU": "N*m", "B48": "kN*m", "85": "ft*lbf",
    "MTR": "m", "FOT": "ft", "PAL": "Pa", "KPA": "kPa", "BAR": "bar", "PS": "psi",
    "RPM": "rpm", "M46": "rpm", "2A": "rad/s",
    "MQS": "m**3/s", "MQH": "m**3/h", "L2": "L/min", "G2": "gpm",
    "KMQ": "kg/m**3", "GE": "lb/gallon", "CEL": "degC", "FAH": "degF", "KEL": "K",
}

# DisplayName spellings (UNECE symbols) that tdmon.units does not read as they are
_SYMBOLS: Final[Mapping[str, str]] = {
    "°C": "degC", "°F": "degF", "r/min": "rpm", "rpm": "rpm",
    "lbf/in²": "psi", "l/min": "L/min", "gal (US) /min": "gpm",
    "lb/gal (US)": "lb/gallon",
}


def unit_id(code: str) -> int:
    """``EUInformation.UnitId`` of a UNECE common code: its (up to three) characters packed
    into an integer, the first in the highest byte (OPC UA Part 8, 5.6.3): ``B47`` is
    0x423437 = 4338743."""
    value = 0
    for character in code:
        value = (value << 8) | ord(character)
    return value


def unece_code(identifier: int) -> str | None:
    """The UNECE common code packed into ``identifier`` (None: not printable ASCII)."""
    if identifier <= 0:
        return None
    characters = []
    while identifier:
        identifier, byte = divmod(identifier, 256)
        if not 0x20 < byte < 0x7F:
            return None
        characters.append(chr(byte))
    return "".join(reversed(characters))


def eu_unit(namespace_uri: str | None, identifier: int | None, display_name: str | None
            ) -> str | None:
    """The unit of a node's ``EngineeringUnits``, spelt for :mod:`tdmon.units`.

    The UNECE code first (when the namespace is UNECE's and the code is one of
    :data:`UNECE_UNITS`), else the display name (its UNECE symbol rewritten: ``·`` multiplies,
    ``²`` and ``³`` are powers, ``°C`` is ``degC``); None when neither says anything.
    """
    if namespace_uri == UNECE_NAMESPACE and identifier is not None:
        code = unece_code(identifier)
        if code is not None and code in UNECE_UNITS:
            return UNECE_UNITS[code]
    text = (display_name or "").strip()
    if not text:
        return None
    if text in _SYMBOLS:
        return _SYMBOLS[text]
    return text.replace("·", "*").replace("²", "**2").replace("³", "**3")


#: where the time of a value came from, in the order tried
TIME_SOURCES: Final = ("source", "server", "receive")

#: OPC UA's null DateTime (1601-01-01) and anything before 1970 mean "no timestamp"
_EPOCH: Final = datetime(1970, 1, 1, tzinfo=UTC)


def unix_time(stamp: datetime | None) -> float | None:
    """Unix seconds of an OPC UA timestamp (naive means UTC); None for a missing one (None,
    or OPC UA's null time 1601-01-01, or anything before 1970)."""
    if stamp is None:
        return None
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=UTC)
    if stamp <= _EPOCH:
        return None
    return stamp.timestamp()


def is_good(status: int) -> bool:
    """Whether a StatusCode's severity (its two highest bits) is Good (OPC UA Part 4, 7.39);
    Uncertain (01) and Bad (10) are not."""
    return status >> 30 == 0


def value_message(topic: str, node: str, value: Any, status: int, status_name: str,
                  source_time: datetime | None, server_time: datetime | None,
                  receive_time: float, unit: str | None) -> RawMessage:
    """The RawMessage of one data change of ``node`` on its channel's ``topic``.

    The payload is ``{"t", "value", "unit", "node", "status", "time_from", "source_time",
    "server_time"}``: ``t`` is the source timestamp, else the server's, else
    ``receive_time`` (``time_from`` says which: "source", "server" or "receive"); ``value``
    the number as the server sent it, in ``unit`` (the node's; None leaves the unit to the
    daemon file's ``[channels.<name>] unit``). A status that is not Good, or a value that is
    not a finite number, adds ``"error"`` naming it, so that the decoder rejects the value.
    """
    times = (unix_time(source_time), unix_time(server_time), receive_time)
    index = next(k for k, t in enumerate(times) if t is not None)
    body: dict[str, Any] = {
        "t": times[index], "value": None, "unit": unit, "node": node, "status": status_name,
        "time_from": TIME_SOURCES[index], "source_time": _iso(source_time),
        "server_time": _iso(server_time)}
    number = _number(value)
    if isinstance(number, float) and math.isfinite(number):
        body["value"] = number
    elif value is not None:
        body["value"] = value if isinstance(value, (str, int, float, bool)) else repr(value)
    if not is_good(status):
        body["error"] = f"OPC UA status {status_name} (0x{status:08X}) from node {node}"
    elif not isinstance(number, float):
        body["error"] = f"node {node}: value {_describe(value)} is not a number"
    elif not math.isfinite(number):
        body["error"] = f"node {node}: value {number} is not finite"
    return RawMessage(SOURCE, topic, json.dumps(body).encode(), receive_time)


def node_error_message(topic: str, node: str, reason: str, receive_time: float) -> RawMessage:
    """The RawMessage saying that ``node`` cannot be read (unknown node, no such browse path,
    a monitored item the server refused), on its channel's topic: recorded as a rejection."""
    body = {"t": receive_time, "node": node, "error": f"node {node}: {reason}"}
    return RawMessage(SOURCE, topic, json.dumps(body).encode(), receive_time)


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        return float(value)
    except OverflowError:
        return None


def _describe(value: Any) -> str:
    if value is None:
        return "null"
    text = repr(value)
    return f"{text[:40]}{'...' if len(text) > 40 else ''} ({type(value).__name__})"


def _iso(stamp: datetime | None) -> str | None:
    t = unix_time(stamp)
    if t is None:
        return None
    return datetime.fromtimestamp(t, UTC).isoformat().replace("+00:00", "Z")
