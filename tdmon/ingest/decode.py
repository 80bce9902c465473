"""Pure payload decoding: ``bytes -> Sample | Rejected`` for the per-channel JSON contract.

A message on ``<prefix>/<topic>`` carries ``{"t": <Unix s or ISO 8601>, "value": <number>,
"unit": <optional>}``. The channel map (from the daemon config) says which canonical channel a
topic feeds and in which unit the rig sends it when the payload does not say. Conversion
factors to SI are computed once per (channel, unit) and reused, because pint is far too slow to
call per message.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import orjson

# CHANNEL_UNITS and ChannelSpec live in tdmon.channels (the config builds channel specs
# without importing the decoder); they are named here too for the decoder's users.
from tdmon.channels import CHANNEL_UNITS, ChannelSpec, check_channel
from tdmon.ingest.types import RawMessage, Rejected, Sample
from tdmon.units import T_MAX, T_MIN, conversion, parse_time
from tdmon.units import clip as _clip

__all__ = ["ABS_VALUE_MAX", "CHANNEL_UNITS", "T_MAX", "T_MIN", "ChannelSpec", "Decoder",
           "SampleChecks", "parse_payload", "parse_time", "topic_for"]

#: Timestamps outside [1970, 2200) are typos or unit mix-ups (ms instead of s), not data.

#: Anything larger in magnitude is not a measurement, whatever the channel.
ABS_VALUE_MAX = 1e15

#: How many distinct payload units one channel may introduce before we stop caching them; a
#: misbehaving publisher must not grow memory without bound.
_MAX_CACHED_UNITS = 32

#: JSON numbers (a tuple: ``int | float`` would build a union type on every call).
_NUMBER = (int, float)

#: Payload numbers whose type could differ between orjson and json (integers beyond 64 bits):
#: ``t``, ``value`` and ``seq`` (see _beyond_int64).
_INT64 = 2.0**63

#: What :meth:`Decoder.decode` needs of a topic's channel: its name, SI unit, the configured
#: unit's factor (None: none configured), the cache of payload units' factors, its bounds
#: [SI] (None: none), the well's limit with its reason (depth channels; else None), and the
#: range [SI] a value passes every check in (all bounds and ``ABS_VALUE_MAX`` together).
_Route = tuple[str, str, "tuple[float, float] | None", dict[str, tuple[float, float]],
               "float | None", "float | None", "tuple[float, str] | None", float, float]


@dataclass(frozen=True, slots=True)
class SampleChecks:
    """Checks of a decoded sample beyond its channel's bounds (docs/daemon.md, "Clock faults").

    Attributes
    ----------
    earliest_t : a stamp before this [Unix s] is a rig clock that was never set (t = 0 is
        1970-01-01), not data; None: no check
    well_depth : total depth of the configured well [m]; None: no well file, no check
    depth_margins : per depth channel (bit and hole depth), how far beyond ``well_depth`` a
        value may lie [m]
        (the well file may lag a few hundred metres of drilling behind the hole)
    """

    earliest_t: float | None = None
    well_depth: float | None = None
    depth_margins: Mapping[str, float] = field(default_factory=dict)


class Decoder:
    """Decode raw messages of one rig (prefix) into Samples, or Rejected with a reason.

    Pure apart from its conversion-factor cache: the same input always gives the same output.
    """

    def __init__(
        self,
        prefix: str,
        channels: Mapping[str, ChannelSpec] | list[ChannelSpec],
        max_payload_bytes: int = 4096,
        checks: SampleChecks | None = None,
    ) -> None:
        specs = list(channels.values()) if isinstance(channels, Mapping) else list(channels)
        self.prefix = prefix.strip("/")
        self.max_payload_bytes = max_payload_bytes
        self.checks = checks or SampleChecks()
        self._earliest = self.checks.earliest_t
        earliest = self._earliest
        self._earliest_text = ("" if earliest is None else datetime.fromtimestamp(
            earliest, UTC).strftime("%Y-%m-%d %H:%M:%SZ").replace(" 00:00:00Z", ""))
        # per channel: (largest value, why) from the well's total depth
        self._beyond_well: dict[str, tuple[float, str]] = {}
        well_depth = self.checks.well_depth
        if well_depth is not None:
            for channel, margin in self.checks.depth_margins.items():
                check_channel(channel)
                self._beyond_well[channel] = (
                    well_depth + margin, f"{well_depth + margin:g} m (the well's total depth "
                                         f"{well_depth:g} m + {margin:g} m)")
        self._by_topic: dict[str, ChannelSpec] = {}
        self._factors: dict[str, dict[str, tuple[float, float]]] = {}
        self._default_factor: dict[str, tuple[float, float] | None] = {}
        for spec in specs:
            check_channel(spec.channel)
            topic = topic_for(self.prefix, spec.topic)
            self._by_topic[topic] = spec
            target = CHANNEL_UNITS[spec.channel][0]
            self._factors[spec.channel] = {}
            if spec.unit is None:
                self._default_factor[spec.channel] = None
            else:
                # a bad configured unit is a configuration error, raised now and not per message
                self._default_factor[spec.channel] = conversion(spec.unit, target)
        # per topic, what decode needs of its channel in one lookup (once per message)
        self._routes: dict[str, _Route] = {
            topic: (spec.channel, CHANNEL_UNITS[spec.channel][1],
                    self._default_factor[spec.channel], self._factors[spec.channel],
                    spec.minimum, spec.maximum, self._beyond_well.get(spec.channel),
                    *_accepted_range(spec, self._beyond_well.get(spec.channel)))
            for topic, spec in self._by_topic.items()}

    @property
    def topics(self) -> list[str]:
        """Full topics this decoder accepts."""
        return list(self._by_topic)

    def decode(self, raw: RawMessage) -> Sample | Rejected:  # noqa: C901  (complex today; simplify when next touched)
        """Decode one message (see :func:`parse_payload` for the rules)."""
        route = self._routes.get(raw.topic)
        if route is None:
            return _reject(raw, _source_error(raw) or f"unknown topic '{_clip(raw.topic)}'")
        payload = raw.payload
        if len(payload) > self.max_payload_bytes:
            return _reject(
                raw, f"payload too large ({len(payload)} > {self.max_payload_bytes} bytes)"
            )
        parsed = parse_payload_seq(payload)
        if isinstance(parsed, str):
            return _reject(raw, parsed)
        t, value, unit, seq = parsed
        earliest = self._earliest
        if earliest is not None and t < earliest:
            return _reject(raw, f"t before the earliest accepted time ({_utc(t)} < "
                                f"{self._earliest_text}: a rig clock that was never set)")
        channel, si_unit, default, factors, minimum, maximum, beyond, low, high = route
        # the usual case, a unit seen before or the configured one, without a method call
        factor = default if unit is None else factors.get(unit)
        if factor is None:
            looked_up = self._factor(channel, unit)
            if isinstance(looked_up, str):
                return _reject(raw, looked_up)
            factor = looked_up
        si_value = value * factor[0] + factor[1]
        if low <= si_value <= high:
            # the usual value, inside every check below at once (NaN is not)
            return Sample(channel, t, si_value, raw.source, raw.topic, si_unit,
                          raw.receive_time, seq)
        if not math.isfinite(si_value) or abs(si_value) > ABS_VALUE_MAX:
            return _reject(raw, f"value {value!r} out of range after unit conversion")
        if minimum is not None and si_value < minimum:
            return _reject(raw, f"value {si_value:g} below the {channel} minimum "
                                f"{minimum:g} {si_unit}")
        if maximum is not None and si_value > maximum:
            return _reject(raw, f"value {si_value:g} above the {channel} maximum "
                                f"{maximum:g} {si_unit}")
        if beyond is not None and si_value > beyond[0]:
            return _reject(raw, f"beyond the well: {channel} {si_value:g} m > {beyond[1]}")
        # positional: channel, t, value, source, topic, unit, receive_time
        return Sample(channel, t, si_value, raw.source, raw.topic, si_unit, raw.receive_time,
                      seq)

    def _factor(self, channel: str, unit: str | None) -> tuple[float, float] | str:
        if unit is None:
            default = self._default_factor[channel]
            if default is None:
                return f"no unit in payload and none configured for channel '{channel}'"
            return default
        cache = self._factors[channel]
        cached = cache.get(unit)
        if cached is not None:
            return cached
        try:
            # tdmon's own unit names only: no payload makes the daemon import pint
            factor = conversion(unit, CHANNEL_UNITS[channel][0], pint_names=False)
        except ValueError as exc:
            # units.conversion is itself LRU-cached, so repeated garbage stays cheap
            return f"unit '{_clip(unit)}' not usable for {channel}: {_clip(str(exc), 120)}"
        if len(cache) < _MAX_CACHED_UNITS:
            cache[unit] = factor
        return factor


def _accepted_range(spec: ChannelSpec, beyond: tuple[float, str] | None
                    ) -> tuple[float, float]:
    """The values [SI] of ``spec``'s channel that no check of :meth:`Decoder.decode` rejects:
    within ``ABS_VALUE_MAX``, its minimum and maximum, and the well's limit ``beyond``."""
    low = -ABS_VALUE_MAX if spec.minimum is None else max(-ABS_VALUE_MAX, spec.minimum)
    highs = [ABS_VALUE_MAX, *(b for b in (spec.maximum, beyond and beyond[0]) if b is not None)]
    return low, min(highs)


def topic_for(prefix: str, topic: str) -> str:
    """Full topic of a channel: ``<prefix>/<topic>``, or ``topic`` itself if it starts with '/'."""
    if topic.startswith("/"):
        return topic.lstrip("/")
    return f"{prefix.strip('/')}/{topic}" if prefix.strip("/") else topic


def parse_payload(payload: bytes) -> tuple[float, float, str | None] | str:
    """Parse one JSON payload into ``(t, value, unit)``, or return the rejection reason
    (the rules of :func:`parse_payload_seq`, without the counter)."""
    parsed = parse_payload_seq(payload)
    return parsed if isinstance(parsed, str) else parsed[:3]


def parse_payload_seq(payload: bytes) -> tuple[float, float, str | None, int | None] | str:  # noqa: C901  (complex today; simplify when next touched)
    """Parse one JSON payload into ``(t, value, unit, seq)``, or return the rejection reason.

    Rules: a JSON object; ``t`` a finite number of Unix seconds or an ISO 8601 string (naive
    means UTC) between 1970 and 2200; ``value`` a finite JSON number (not a boolean, not a
    string); ``unit`` absent, null or a non-empty string. ``seq``, the publisher's optional
    message counter per topic, is a non-negative integer or None (anything else is ignored, never
    a rejection: the sample is good without it).
    """
    try:
        obj = _json_value(payload)
    except _NotJson as exc:
        return str(exc)
    if not isinstance(obj, dict):
        return f"payload is a JSON {type(obj).__name__}, not an object"
    error = obj.get("error")
    if isinstance(error, str) and error:
        # a source that translates another protocol (WITS0) passes on why a line was bad
        return _clip(error, 200)
    if "t" not in obj:
        return "missing 't'"
    if "value" not in obj:
        return "missing 'value'"
    t = obj["t"]
    if not (type(t) is float and T_MIN <= t < T_MAX):  # else a finite float in range already
        t = parse_time(t)
        if isinstance(t, str):
            return t
    value = obj["value"]
    if type(value) is not float:
        if isinstance(value, bool) or not isinstance(value, _NUMBER):
            return f"'value' must be a number, got {type(value).__name__}"
        try:
            value = float(value)
        except OverflowError:
            return "'value' is too large"
    if not math.isfinite(value):
        return f"'value' is not finite ({value})"
    unit = obj.get("unit")
    if unit is not None and (not isinstance(unit, str) or not unit.strip()):
        return "'unit' must be a non-empty string"
    seq = obj.get("seq")
    if type(seq) is not int or seq < 0:
        seq = None
    return t, value, unit, seq


class _NotJson(ValueError):
    """A payload that is not JSON, with the rejection reason."""


def _json_value(payload: bytes) -> Any:
    """What ``json.loads`` makes of ``payload`` (decoded as UTF-8), read by orjson where the
    two agree; raises :class:`_NotJson` with the reason for anything else.

    orjson reads strict JSON only, so what it refuses (invalid UTF-8, a byte-order mark, NaN
    and Infinity, lone surrogates, numbers beyond a double, damage) goes to ``json``, which
    reads JSON's non-standard words and words the error for the rest; so does anything but an
    object, and an object where orjson may have read a number that matters otherwise
    (:func:`_beyond_int64`). The rules after it see json's values either way.
    """
    try:
        obj = orjson.loads(payload)
    except orjson.JSONDecodeError:
        pass
    else:
        if type(obj) is dict and not _beyond_int64(obj):
            return obj
    try:
        # decoded explicitly: json.loads on bytes would also guess UTF-16/32 from the first
        # bytes
        text = payload.decode("utf-8")
    except UnicodeDecodeError:
        raise _NotJson("payload is not UTF-8") from None
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise _NotJson(f"malformed JSON: {_clip(str(exc), 80)}") from None


def _beyond_int64(obj: dict[str, Any]) -> bool:
    """Whether orjson may have read one of the numbers that matter (``t``, ``value``, ``seq``)
    otherwise than ``json``: a float beyond 2**63 in magnitude, which orjson makes of an
    integer too large for 64 bits (``json`` keeps it an integer)."""
    return any(type(number) is float and not -_INT64 < number < _INT64
               for number in (obj.get("t"), obj.get("value"), obj.get("seq")))


def _reject(raw: RawMessage, reason: str) -> Rejected:
    return Rejected(reason=reason, raw=raw.payload, source=raw.source, topic=raw.topic,
                    receive_time=raw.receive_time)


def _utc(t: float) -> str:
    """``t`` [Unix s] as a UTC time for a message."""
    return datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _source_error(raw: RawMessage) -> str | None:
    """The reason a translating source (WITS0) gave for a message it could not map, if any:
    such messages come on a topic of their own, which no channel owns."""
    if raw.source != "wits0" or b'"error"' not in raw.payload:
        return None
    try:
        obj = _json_value(raw.payload)
    except _NotJson:
        return None
    error = obj.get("error") if isinstance(obj, dict) else None
    return _clip(error, 200) if isinstance(error, str) and error else None


