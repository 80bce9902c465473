"""Reading a replay through its chunk index and record by record gives the same messages."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import IndexType, Writer

from tdmon.ingest import mcap_source
from tdmon.ingest.mcap_source import _all_in_indexed_chunks, iter_raw
from tdmon.ingest.types import RawMessage, raw_message

T0 = 1_700_000_000_000_000_000


def _write(path: Path, *, chunking: bool, chunk_size: int = 2000, index: bool = True) -> None:
    """Raw input (every third message from an earlier receive time: file order is not log
    time order) with a derived topic between, in small chunks so that there are several."""
    with path.open("wb") as stream:
        kwargs = {} if index else {"index_types": IndexType.CHUNK}
        writer = Writer(stream, use_chunking=chunking, chunk_size=chunk_size, **kwargs)
        writer.start()
        schema = writer.register_schema("any", "jsonschema", b"{}")
        derived = writer.register_channel("/truth/hookload", "json", schema)
        raw = writer.register_channel("/tdmon/raw", "json", schema)
        for i in range(300):
            t_ns = T0 + (i - 5 * (i % 3 == 0)) * 100_000_000
            writer.add_message(derived, t_ns, b'{"value": 1.0}', t_ns)
            payload = json.dumps({"t": t_ns / 1e9, "value": float(i)}).encode()
            body = raw_message(RawMessage("mqtt", f"rig/F4/ch{i % 4}", payload, t_ns / 1e9))
            writer.add_message(raw, t_ns, json.dumps(body).encode(), t_ns)
        writer.finish()


def _read(path: Path) -> list[tuple[int, RawMessage]]:
    with path.open("rb") as stream:
        return list(iter_raw(stream))


def test_indexed_chunks_read_like_the_stream(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                             ) -> None:
    chunked, flat = tmp_path / "chunked.mcap", tmp_path / "flat.mcap"
    _write(chunked, chunking=True)
    _write(flat, chunking=False)
    with chunked.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and len(summary.chunk_indexes) > 5
    assert _all_in_indexed_chunks(summary)

    read = _read(chunked)
    assert len(read) == 300
    # file order, not log-time order; each payload whole
    assert [json.loads(raw.payload)["value"] for _, raw in read] == [float(i) for i in
                                                                     range(300)]
    assert read[3][0] == T0 - 2 * 100_000_000  # message 3, received 0.5 s early
    assert read == _read(flat)

    # the same file read record by record, as a file without a summary is
    monkeypatch.setattr(mcap_source, "_summary", lambda stream: None)
    assert read == _read(chunked)


def test_messages_outside_the_index_are_read_record_by_record(tmp_path: Path) -> None:
    flat, unindexed = tmp_path / "flat.mcap", tmp_path / "unindexed.mcap"
    _write(flat, chunking=False)
    _write(unindexed, chunking=True, index=False)
    for path in (flat, unindexed):
        with path.open("rb") as stream:
            summary = make_reader(stream).get_summary()
        assert summary is not None and not _all_in_indexed_chunks(summary)
        assert len(_read(path)) == 300


def test_a_file_cut_short_is_read_up_to_the_cut(tmp_path: Path) -> None:
    path = tmp_path / "chunked.mcap"
    _write(path, chunking=True)
    data = path.read_bytes()
    with io.BytesIO(data[: len(data) // 2]) as stream:
        read = list(iter_raw(stream))
    assert 0 < len(read) < 300
    assert read == _read(path)[: len(read)]
