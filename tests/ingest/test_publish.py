"""The rig side of `tdmon publish`: reading CSV logs and recordings into messages."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.writer import Writer

from tdmon.errors import IngestError
from tdmon.ingest.decode import ChannelSpec, Decoder
from tdmon.ingest.publish import (
    VOLVE_COLUMNS,
    Column,
    csv_messages,
    parse_columns,
    recording_messages,
)
from tdmon.ingest.types import RawMessage, Sample, raw_message

VOLVE = Path("/work/shared/data/volve-f4/trip-in-2016-10-05.csv")


def test_volve_csv_becomes_valid_payloads() -> None:
    messages = list(csv_messages(VOLVE, "rig/F4"))
    rows = len(VOLVE.read_text().splitlines()) - 1
    # one message per non-empty mapped cell; every one decodes to an SI sample
    assert rows * 5 < len(messages) <= rows * len(VOLVE_COLUMNS)
    decoder = Decoder("rig/F4", [ChannelSpec(c.channel, c.channel) for c in VOLVE_COLUMNS])
    first = decoder.decode(RawMessage("test", messages[0][1], messages[0][2], 0.0))
    assert isinstance(first, Sample) and first.channel == "hookload"
    assert first.value == pytest.approx(645037.1)  # 645.0371 kN
    assert first.t == 1475627400.0  # 2016-10-05T00:30:00Z
    times = [t for t, _, _ in messages]
    assert times == sorted(times)


def test_time_shift_and_column_map(tmp_path: Path) -> None:
    log = tmp_path / "log.csv"
    log.write_text("TIME,HKLD,BITDEP\n10,200,\n20,210,3000\n")
    columns = parse_columns("hookload=HKLD:klbf, bit_depth=BITDEP:ft")
    assert columns == (Column("hookload", "HKLD", "klbf"), Column("bit_depth", "BITDEP", "ft"))
    messages = list(csv_messages(log, "rig/X", columns, "TIME", shift=100.0))
    assert [(t, topic) for t, topic, _ in messages] == [
        (110.0, "rig/X/hookload"), (120.0, "rig/X/hookload"), (120.0, "rig/X/bit_depth")]
    assert json.loads(messages[2][2]) == {"t": 120.0, "value": 3000.0, "unit": "ft"}


def test_column_mistakes(tmp_path: Path) -> None:
    with pytest.raises(IngestError, match="not channel=column:unit"):
        parse_columns("hookload")
    with pytest.raises(IngestError, match="no column HKLD"):
        list(csv_messages(VOLVE, "p", parse_columns("hookload=HKLD:kN")))
    bad = tmp_path / "bad.csv"
    bad.write_text("time_utc,hookload_kN\n2016-10-05T00:30:00Z,abc\n")
    with pytest.raises(IngestError, match=r"bad\.csv:2: hookload_kN is not a number"):
        list(csv_messages(bad, "p", [Column("hookload", "hookload_kN", "kN")]))


def test_recording_messages_replace_the_prefix(tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema("any", "jsonschema", b"{}")
        channel = writer.register_channel("/tdmon/raw", "json", schema)
        raw = RawMessage("mqtt", "rig/OLD/hookload", b'{"t": 1, "value": 2}', 5.0)
        writer.add_message(channel, 5_000_000_000, json.dumps(raw_message(raw)).encode(),
                           5_000_000_000)
        writer.finish()
    assert list(recording_messages(path, "rig/NEW")) == [
        (5.0, "rig/NEW/hookload", b'{"t": 1, "value": 2}')]
    assert next(iter(recording_messages(path)))[1] == "rig/OLD/hookload"
