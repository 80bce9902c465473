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

# the first rows of data/volve-f4/trip-in-2016-10-05.csv (Equinor Open Data
# Licence, "Equinor and the former Volve licence partners"), mapped columns only kept whole
VOLVE_HEAD = """time_utc,hole_depth_m,bit_depth_m,hookload_kN,surface_torque_kNm,surface_rpm,\
bit_rpm,flow_in_Lpm,flow_out_Lpm,spp_bar,wob_kN,rop_mph,rig_activity_code,block_pos_comp_m,\
block_pos_uncomp_m,rig_heave_m,bit_depth_5s_m
2016-10-05T00:30:00Z,3510,2051.0000,645.0371,0.0052,0.0000,0.0000,0.0000,36.4425,-0.4577,\
875.5380,0.0000,4,36.3941,36.3941,-0.0764,2051.0000
2016-10-05T00:30:15Z,3510,2051.0000,646.3192,0.0052,0.0000,0.0000,0.0000,35.7453,-0.4498,\
876.0511,0.0000,4,36.3941,36.3941,-0.0813,2051.0000
2016-10-05T00:30:30Z,3510,2051.0000,676.5752,0.0052,,0.0000,0.0000,35.9300,-0.4323,\
851.9299,0.0000,4,37.1792,40.3306,-0.0781,2051.0000
""".replace("\\\n", "")


@pytest.fixture
def volve(tmp_path: Path) -> Path:
    path = tmp_path / "trip-in-head.csv"
    path.write_text(VOLVE_HEAD)
    return path


def test_volve_csv_becomes_valid_payloads(volve: Path) -> None:
    messages = list(csv_messages(volve, "rig/F4"))
    rows = 3
    # one message per non-empty mapped cell; every one decodes to an SI sample
    assert len(messages) == rows * len(VOLVE_COLUMNS) - 1  # one empty cell is not sent
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


def test_column_mistakes(tmp_path: Path, volve: Path) -> None:
    with pytest.raises(IngestError, match="not channel=column:unit"):
        parse_columns("hookload")
    with pytest.raises(IngestError, match="no column HKLD"):
        list(csv_messages(volve, "p", parse_columns("hookload=HKLD:kN")))
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


def test_now_never_stamps_a_faster_than_real_time_session_ahead_of_the_clock() -> None:
    """--now at --speed 1 puts the first row at now; faster (or max) the last row, so that no
    sample of the session is ever ahead of the clock when it is sent."""
    import time

    from tdmon.cli.run import _now_shift

    times = [1000.0, 1015.0, 1030.0, 1045.0]
    before = time.time()
    live = _now_shift(True, 1.0, iter(times))
    fast = _now_shift(True, 60.0, iter(times))
    as_fast_as_possible = _now_shift(True, None, iter(times))
    after = time.time()
    assert before <= times[0] + live <= after
    assert before <= times[-1] + fast <= after
    assert before <= times[-1] + as_fast_as_possible <= after
    assert _now_shift(False, 60.0, iter(times)) == 0.0
    assert _now_shift(True, 60.0, iter([])) == 0.0
