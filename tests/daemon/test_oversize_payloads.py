"""Oversized payloads through a real broker and daemon with the MCAP recorder: each is rejected
with its size in the reason and recorded as a bounded prefix with its size and SHA-256, so 40
payloads of 10 MB grow the recording by far less than 1 MB (they used to add 839 MB, recorded
whole twice). Normal payloads are recorded whole, exactly as received, and still replay."""

from __future__ import annotations

import base64
import hashlib
import os
import time
from pathlib import Path
from typing import Any

import aiomqtt
import jsonschema
from daemon_support import make_config, payload, running, wait_until

from tdmon.ingest.mcap_source import iter_raw
from tdmon.ingest.types import RECORDED_PAYLOAD_BYTES
from tdmon.record.reader import read_messages, schemas_of

BIG = 10 * 1024 * 1024
N_BIG = 40
N_SMALL = 20


def _big(i: int, block: bytes, heads: list[bytes]) -> bytes:
    """Even: JSON text padded to 10 MB (UTF-8); odd: binary (recorded as base64), with its own
    random first 8 KiB so that the recorded prefixes do not compress into each other."""
    if i % 2 == 0:
        head = b'{"t": %d, "value": 900.0, "pad": "' % (1_700_000_000 + i)
        return head + b"\xc3\xa9" * ((BIG - len(head)) // 2) + b'"}'
    return heads[i] + block[len(heads[i]):]


async def test_forty_10_mb_payloads_add_less_than_1_mb(mosquitto: Any, tmp_path: Path) -> None:
    folder = tmp_path / "rec"
    config = make_config({
        "sources": {"mqtt": {"port": mosquitto.port, "client_id": "tdmon-oversize"}},
        "recorder": {"enabled": True, "output": str(folder)},
    }, tmp_path)
    block = os.urandom(BIG)
    heads = [os.urandom(8192) for _ in range(N_BIG)]
    sent_big: list[tuple[int, str]] = []  # (size, sha256) in publishing order
    sent_small: list[bytes] = []
    t0 = time.time()
    async with running(config, connected=("mqtt",)) as (built, _sink):
        async with aiomqtt.Client("127.0.0.1", mosquitto.port, identifier="rig") as rig:
            for i in range(N_BIG):
                big = _big(i, block, heads)
                sent_big.append((len(big), hashlib.sha256(big).hexdigest()))
                await rig.publish("rig/T1/hookload", big, qos=1)
                if i % 2 == 0:
                    # stamped in the past: a stamp ahead of the receive time is a clock fault
                    small = payload(t0 - N_BIG + i, 900.0 + i, "kN")
                    sent_small.append(small)
                    await rig.publish("rig/T1/hookload", small, qos=1)
                del big
        await wait_until(lambda: built.stats.messages_in >= N_BIG + N_SMALL, 300,
                         "every payload handled")
    assert built.stats.rejected == N_BIG
    assert built.stats.samples_in == N_SMALL

    [recording] = sorted(folder.glob("*.mcap"))
    size = recording.stat().st_size
    print(f"{N_BIG} payloads of {BIG} bytes and {N_SMALL} normal ones: recording {size} bytes")
    assert size < 1_000_000

    stored = schemas_of(recording)
    raw = [m.message for m in read_messages(recording, "/tdmon/raw")]
    rejected = [m.message for m in read_messages(recording, "/tdmon/rejected")]
    assert len(raw) == N_BIG + N_SMALL and len(rejected) == N_BIG
    for message in raw + rejected:
        jsonschema.validate(message, stored["/tdmon/raw" if "reason" not in message
                                            else "/tdmon/rejected"])
    truncated = [m for m in raw if m.get("payload_truncated")]
    whole = [m for m in raw if not m.get("payload_truncated")]
    # normal payloads: exactly as before (no new fields), the text as sent
    assert [m["payload"].encode() for m in whole] == sent_small
    assert all(set(m) == {"source", "topic", "receive_time", "payload", "payload_encoding"}
               for m in whole)
    for recorded in (truncated, rejected):
        assert [(m["payload_bytes"], m["payload_sha256"]) for m in recorded] == sent_big
        for i, m in enumerate(recorded):
            assert m["payload_truncated"] is True
            if i % 2 == 0:
                assert m["payload_encoding"] == "utf-8"
                prefix = m["payload"].encode()
                # cut at a character boundary, never beyond the bound
                assert RECORDED_PAYLOAD_BYTES - 1 <= len(prefix) <= RECORDED_PAYLOAD_BYTES
            else:
                assert m["payload_encoding"] == "base64"
                prefix = base64.b64decode(m["payload"])
                assert len(prefix) == RECORDED_PAYLOAD_BYTES
            assert prefix == _big(i, block, heads)[:len(prefix)]
    for m, (size, _) in zip(rejected, sent_big, strict=True):
        assert size >= BIG
        assert m["reason"] == f"payload too large ({size} > 4096 bytes)"

    # a replay of the recording skips what it cannot reproduce and keeps the rest exactly
    with recording.open("rb") as stream:
        replayed = [raw_message.payload for _, raw_message in iter_raw(stream)]
    assert replayed == sent_small
