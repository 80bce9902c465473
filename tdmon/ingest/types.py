"""Value types that cross the ingest boundary: what a source yields and what a decoder returns."""

from __future__ import annotations

import base64
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True, slots=True)
class RawMessage:
    """One message as a transport delivered it.

    ``receive_time`` is Unix seconds taken when the message reached tdmon (for a replay, the
    time recorded when it originally arrived), so latency and pacing can be measured from it.

    Delivery (docs/daemon.md, "At-least-once delivery"): ``ack``, when set, tells the transport
    that the message is safe with tdmon; the daemon calls it once the message has been
    processed and the recorder has flushed it to its file. ``redelivered`` is the transport's
    mark of a second delivery (MQTT's DUP flag); ``duplicate`` says the source recognised it
    as one this run already handed out, so it is counted and acknowledged, not processed again.
    """

    source: str
    topic: str
    payload: bytes
    receive_time: float
    ack: Callable[[], None] | None = field(default=None, compare=False, repr=False)
    redelivered: bool = False
    duplicate: bool = False


@dataclass(frozen=True, slots=True)
class Sample:
    """A decoded, unit-converted measurement on a canonical channel (value in SI)."""

    channel: str
    t: float
    value: float
    source: str
    topic: str
    unit: str
    receive_time: float
    seq: int | None = None
    """The payload's optional message counter (per topic), for loss detection."""


@dataclass(frozen=True, slots=True)
class Rejected:
    """A message that could not become a Sample, with the reason and the bytes as received."""

    reason: str
    raw: bytes
    source: str
    topic: str
    receive_time: float


def payload_text(payload: bytes) -> tuple[str, str]:
    """Return ``(text, encoding)`` for storing a payload in JSON: UTF-8 when it is, else base64."""
    try:
        return payload.decode("utf-8"), "utf-8"
    except UnicodeDecodeError:
        return base64.b64encode(payload).decode("ascii"), "base64"


def raw_message(raw: RawMessage) -> dict[str, Any]:
    """The ``raw`` daemon message (docs/architecture.md)."""
    text, encoding = payload_text(raw.payload)
    return {
        "source": raw.source,
        "topic": raw.topic,
        "receive_time": raw.receive_time,
        "payload": text,
        "payload_encoding": encoding,
    }


def sample_message(sample: Sample) -> dict[str, Any]:
    """The ``sample`` daemon message."""
    return {
        "channel": sample.channel,
        "t": sample.t,
        "value": sample.value,
        "unit": sample.unit,
        "source": sample.source,
        "topic": sample.topic,
    }


def rejected_message(rejected: Rejected) -> dict[str, Any]:
    """The ``rejected`` daemon message."""
    text, encoding = payload_text(rejected.raw)
    return {
        "reason": rejected.reason,
        "source": rejected.source,
        "topic": rejected.topic,
        "receive_time": rejected.receive_time,
        "payload": text,
        "payload_encoding": encoding,
    }
