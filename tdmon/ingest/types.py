"""Value types that cross the ingest boundary: what a source yields and what a decoder returns,
and the daemon messages made of them (``raw``, ``sample``, ``rejected``)."""

from __future__ import annotations

import base64
import hashlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from operator import attrgetter
from typing import Any, Final

from tdmon.record.batch import Items

#: Longest payload kept whole in the ``raw`` and ``rejected`` messages [bytes]. A longer one (an
#: oversized payload the decoder rejects) is recorded as its first bytes, its size and its
#: SHA-256, so that a flood of 10 MB payloads cannot fill the recording's disk
#: (docs/recording.md). The daemon raises it to its ``max_payload_bytes`` when that is larger,
#: so that every payload the decoder may accept is recorded, and replays, whole.
RECORDED_PAYLOAD_BYTES: Final = 4096


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

    ``recorded``: the ``raw`` message's JSON bytes as a recording held them, when they say
    exactly what :func:`raw_message` would (a replay of tdmon's own recording, see
    :func:`tdmon.ingest.mcap_source.raw_from_record`); a recorder may write them again as they
    are instead of encoding the message anew (docs/recording.md). None for live input. A copy
    that changes what the message says (``dataclasses.replace``) must be given
    ``recorded=None``.
    """

    source: str
    topic: str
    payload: bytes
    receive_time: float
    ack: Callable[[], None] | None = field(default=None, compare=False, repr=False)
    redelivered: bool = False
    duplicate: bool = False
    recorded: bytes | None = field(default=None, compare=False, repr=False)


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


def bounded_payload(payload: bytes, max_bytes: int = RECORDED_PAYLOAD_BYTES) -> dict[str, Any]:
    """The payload fields of a ``raw``/``rejected`` message, at most ``max_bytes`` of payload.

    A payload of at most ``max_bytes`` [bytes] gives ``payload`` and ``payload_encoding`` as
    :func:`payload_text` does. A longer one gives its first ``max_bytes`` (fewer when the cut
    would split a UTF-8 character of a text payload) and ``payload_bytes`` (its whole size
    [bytes]), ``payload_sha256`` (hex digest of the whole payload) and ``payload_truncated``
    (``True``).
    """
    if len(payload) <= max_bytes:
        text, encoding = payload_text(payload)
        return {"payload": text, "payload_encoding": encoding}
    prefix = payload[:max_bytes]
    # A cut inside a multi-byte character would turn a text payload into base64: step back
    # over at most three continuation bytes to keep it readable.
    for cut in range(len(prefix), max(len(prefix) - 4, 0), -1):
        try:
            text, encoding = prefix[:cut].decode("utf-8"), "utf-8"
            break
        except UnicodeDecodeError:
            continue
    else:
        text, encoding = base64.b64encode(prefix).decode("ascii"), "base64"
    return {
        "payload": text,
        "payload_encoding": encoding,
        "payload_bytes": len(payload),
        "payload_sha256": hashlib.sha256(payload).hexdigest(),
        "payload_truncated": True,
    }


def bounded_topic(topic: str, max_bytes: int = RECORDED_PAYLOAD_BYTES) -> dict[str, Any]:
    """The topic fields of a ``raw``/``rejected`` message: ``topic`` whole when its UTF-8 is
    at most ``max_bytes`` [bytes] (the payloads' bound), else its first ``max_bytes`` (whole
    characters) with ``topic_bytes`` (its whole size [bytes]) and ``topic_truncated``
    (``True``). MQTT allows topics of 64 KiB; a rig's are tens of bytes."""
    if len(topic) * 4 <= max_bytes:  # UTF-8 takes at most 4 bytes a character
        return {"topic": topic}
    data = topic.encode("utf-8", "surrogatepass")
    if len(data) <= max_bytes:
        return {"topic": topic}
    return {"topic": data[:max_bytes].decode("utf-8", "ignore"), "topic_bytes": len(data),
            "topic_truncated": True}


#: a topic this long [characters] or shorter is recorded whole whatever the bound (>= 4 KiB)
_SHORT_TOPIC: Final = RECORDED_PAYLOAD_BYTES // 4


def raw_message(raw: RawMessage, max_bytes: int = RECORDED_PAYLOAD_BYTES) -> dict[str, Any]:
    """The ``raw`` daemon message (docs/architecture.md); payload and topic bounded as in
    :func:`bounded_payload` and :func:`bounded_topic`."""
    if len(raw.payload) > max_bytes or len(raw.topic) > _SHORT_TOPIC:
        return {"source": raw.source, **bounded_topic(raw.topic, max_bytes),
                "receive_time": raw.receive_time, **bounded_payload(raw.payload, max_bytes)}
    # the usual case, once per input message: no intermediate dict
    text, encoding = payload_text(raw.payload)
    return {
        "source": raw.source,
        "topic": raw.topic,
        "receive_time": raw.receive_time,
        "payload": text,
        "payload_encoding": encoding,
    }


def sample_message(sample: Sample) -> dict[str, Any]:
    """The ``sample`` daemon message (its keys: :data:`SAMPLE_FIELDS`, written out here because
    this runs once per input message)."""
    return {
        "channel": sample.channel,
        "t": sample.t,
        "value": sample.value,
        "unit": sample.unit,
        "source": sample.source,
        "topic": sample.topic,
    }


#: The fields a ``sample`` message holds, in its order.
SAMPLE_FIELDS: Final = ("channel", "t", "value", "unit", "source", "topic")

#: A RawMessage's fields its ``raw`` message is made of, as one tuple (its *row*), and a
#: Sample's for its ``sample`` message: the plain values a batch of them pickles as
#: (:class:`tdmon.record.batch.Items`), taken in C without building a dict per message.
_RAW_ROW: Final = attrgetter("source", "topic", "payload", "receive_time")
_SAMPLE_ROW: Final = attrgetter(*SAMPLE_FIELDS)
_RECORDED: Final = attrgetter("recorded")


def raw_row_message(row: tuple[str, str, bytes, float],
                    max_bytes: int = RECORDED_PAYLOAD_BYTES) -> dict[str, Any]:
    """:func:`raw_message` of a RawMessage's row."""
    return raw_message(RawMessage(*row), max_bytes)


def sample_row_message(row: tuple[str, float, float, str, str, str]) -> dict[str, Any]:
    """:func:`sample_message` of a Sample's row."""
    return dict(zip(SAMPLE_FIELDS, row, strict=True))


def recorded_raw(raws: Sequence[RawMessage], max_bytes: int) -> list[bytes] | None:
    """The ``raw`` messages of ``raws`` as a recording of tdmon held them
    (``RawMessage.recorded``: a replay of tdmon's own recording), when every one is there and
    short enough for its payload to be kept whole (``max_bytes`` [bytes]; a recorded message
    is longer than its payload); else None."""
    kept = list(map(_RECORDED, raws))  # bytes (never empty) or None each
    return kept if all(kept) and max(map(len, kept)) <= max_bytes else None


def raw_items(max_bytes: int = RECORDED_PAYLOAD_BYTES) -> Items:
    """RawMessages as the items of a batch of ``raw`` messages (payloads bounded to
    ``max_bytes`` [bytes] as in :func:`bounded_payload`)."""
    return Items(message=partial(raw_message, max_bytes=max_bytes), row=_RAW_ROW,
                 from_row=partial(raw_row_message, max_bytes=max_bytes),
                 encoded=partial(recorded_raw, max_bytes=max_bytes))


#: Samples as the items of a batch of ``sample`` messages.
SAMPLE_ITEMS: Final = Items(message=sample_message, row=_SAMPLE_ROW,
                            from_row=sample_row_message)


def rejected_message(rejected: Rejected,
                     max_bytes: int = RECORDED_PAYLOAD_BYTES) -> dict[str, Any]:
    """The ``rejected`` daemon message; payload and topic bounded as in
    :func:`bounded_payload` and :func:`bounded_topic`."""
    return {
        "reason": rejected.reason,
        "source": rejected.source,
        **bounded_topic(rejected.topic, max_bytes),
        "receive_time": rejected.receive_time,
        **bounded_payload(rejected.raw, max_bytes),
    }
