"""The WITS0 codec: frames cut out of any read pattern, rejected lines and frames with their
reasons, time from the date and time items, unit conversions checked by hand."""

from __future__ import annotations

import json
from datetime import UTC, datetime
from zoneinfo import ZoneInfo

import pytest

from tdmon.ingest.types import RawMessage
from tdmon.ingest.wits0 import (
    DEFAULT_ITEMS,
    FrameError,
    FrameParser,
    ItemOverride,
    WitsFrame,
    decode_frame,
    encode_frame,
    encode_sample_frame,
    item_map,
    si_to_items,
    time_items,
)
from tdmon.ingest.wits0_source import frame_messages

FRAME = (b"&&\r\n0105231004\r\n0106213015\r\n01081523.40\r\n01141436.5\r\n011825.75\r\n"
         b"0120120\r\n0101WELL-A\r\n!!\r\n")
T_FRAME = datetime(2023, 10, 4, 21, 30, 15, tzinfo=UTC).timestamp()


def _frames(out: list[WitsFrame | FrameError]) -> list[WitsFrame]:
    return [o for o in out if isinstance(o, WitsFrame)]


def test_default_items_are_record_01_and_0115_is_not_a_channel() -> None:
    # record 01, and record 09's MWD weight on bit and torque at the bit
    assert all(code.startswith("01") or code in ("0915", "0917") for code in DEFAULT_ITEMS)
    mapped = item_map()
    assert "0115" not in mapped and "0105" not in mapped and "0106" not in mapped
    assert {spec.channel for spec in mapped.values()} == {
        "bit_depth", "hole_depth", "block_position", "hookload", "wob", "torque", "rpm", "spp",
        "flow_in", "mud_density", "mud_temp_out", "mud_temp_in", "downhole_wob",
        "downhole_torque"}


def test_record_09_downhole_weight_and_torque_by_hand() -> None:
    # MWBA 1.8 KDN = 18 kN, MTQA 4.25 KNM = 4250 N m; field units 4.0 KLB, 3.1 KFLB
    frame_bytes = b"&&\r\n09151.8\r\n09174.25\r\n!!\r\n"
    [frame] = _frames(FrameParser().feed(frame_bytes))
    values = {item.channel: item.value for item in decode_frame(frame, item_map(), 1.0).items}
    assert values == {"downhole_wob": pytest.approx(18e3), "downhole_torque": pytest.approx(4250.0)}
    field_bytes = b"&&\r\n09154.0\r\n09173.1\r\n!!\r\n"
    [frame] = _frames(FrameParser().feed(field_bytes))
    values = {item.channel: item.value
              for item in decode_frame(frame, item_map("field"), 1.0).items}
    lbf, ft = 0.45359237 * 9.80665, 0.3048
    assert values["downhole_wob"] == pytest.approx(4000.0 * lbf, rel=1e-12)
    assert values["downhole_torque"] == pytest.approx(3100.0 * lbf * ft, rel=1e-12)


@pytest.mark.parametrize("sizes", [[len(FRAME)], [1] * len(FRAME), [3, 7, 11, 200], [50, 5]])
def test_a_frame_split_across_any_reads_is_the_same_frame(sizes: list[int]) -> None:
    parser = FrameParser()
    out: list[WitsFrame | FrameError] = []
    data = b"\r\n" + FRAME + FRAME  # a blank line between frames is no garbage
    pos = 0
    while pos < len(data):
        size = sizes[len(out) % len(sizes)] if pos < len(FRAME) else 13
        out += parser.feed(data[pos:pos + size])
        pos += size
    out += parser.close()
    assert len(out) == 2 and all(isinstance(o, WitsFrame) for o in out)
    frame = out[0]
    assert isinstance(frame, WitsFrame) and frame.raw == FRAME and frame.error is None
    assert [line.code for line in frame.lines] == ["0105", "0106", "0108", "0114", "0118",
                                                   "0120", "0101"]
    assert frame.lines[3].value == "1436.5"


def test_time_from_date_and_time_items_and_metric_conversions() -> None:
    [frame] = _frames(FrameParser().feed(FRAME))
    decoded = decode_frame(frame, item_map(), receive_time=1.0)
    assert decoded.time_from == "wits" and decoded.t == T_FRAME
    values = {item.channel: item.value for item in decoded.items}
    assert values["bit_depth"] == 1523.40
    assert values["hookload"] == pytest.approx(1436.5 * 10_000)  # KDN = 10 kN
    assert values["torque"] == pytest.approx(25.75e3)  # KNM
    assert values["rpm"] == pytest.approx(120 * 2 * 3.141592653589793 / 60)
    assert decoded.errors == ()  # 0101, the well name, is not mapped: no error


def test_field_units_klb_and_kflb_by_hand() -> None:
    lbf = 0.45359237 * 9.80665  # [N]
    ft = 0.3048  # [m]
    [frame] = _frames(FrameParser().feed(FRAME))
    decoded = decode_frame(frame, item_map("field"), 1.0)
    values = {item.channel: item.value for item in decoded.items}
    assert values["hookload"] == pytest.approx(1436.5 * 1000 * lbf, rel=1e-12)
    assert values["torque"] == pytest.approx(25.75 * 1000 * lbf * ft, rel=1e-12)
    assert values["bit_depth"] == pytest.approx(1523.40 * ft, rel=1e-12)


def test_item_overrides_and_their_mistakes() -> None:
    items = item_map("metric", {"0114": ItemOverride(False),
                                "0115": ItemOverride("hookload", "klb"),
                                "0121": ItemOverride(unit="BAR"),
                                "0850": ItemOverride("mud_temp_in", "DEGF"),
                                "0134": ItemOverride(False)})
    assert "0114" not in items and items["0115"].channel == "hookload"
    assert items["0121"].scale == pytest.approx(1e5)
    assert items["0850"].to_si(212.0) == pytest.approx(100.0)
    with pytest.raises(ValueError, match="items 0114 and 0115 both feed 'hookload'"):
        item_map("metric", {"0115": ItemOverride("hookload")})
    with pytest.raises(ValueError, match="item 0114: unknown WITS unit 'KGF'"):
        item_map("metric", {"0114": ItemOverride(unit="KGF")})
    with pytest.raises(ValueError, match=r"item 0118: WITS unit 'KDN'.*cannot be converted"):
        item_map("metric", {"0118": ItemOverride(unit="KDN")})
    with pytest.raises(ValueError, match="item 0999: give its unit"):
        item_map("metric", {"0999": ItemOverride("spp")})


def test_time_in_a_configured_zone_and_senders_that_drop_leading_zeros() -> None:
    frame = b"&&\n010551004\n010691520.0\n01141000\n!!\n"  # 2005-10-04 09:15:20, LF only
    [parsed] = _frames(FrameParser().feed(frame))
    oslo = ZoneInfo("Europe/Oslo")  # summer time in October: UTC+2
    decoded = decode_frame(parsed, item_map(), 1.0, oslo)
    assert decoded.t == datetime(2005, 10, 4, 7, 15, 20, tzinfo=UTC).timestamp()
    assert time_items(decoded.t, oslo) == {"0105": "051004", "0106": "091520"}


def test_receive_time_without_both_date_and_time_and_with_a_bad_date() -> None:
    [no_time] = _frames(FrameParser().feed(b"&&\r\n0106213015\r\n01141000\r\n!!\r\n"))
    decoded = decode_frame(no_time, item_map(), 1_700_000_000.5)
    assert decoded.time_from == "receive" and decoded.t == 1_700_000_000.5
    [bad] = _frames(FrameParser().feed(b"&&\r\n0105231304\r\n0106213015\r\n01141000\r\n!!\r\n"))
    decoded = decode_frame(bad, item_map(), 1_700_000_000.5)
    assert decoded.time_from == "receive" and len(decoded.items) == 1
    [error] = decoded.errors
    assert "not a valid time" in error.reason and "month must be in 1..12" in error.reason


def test_bad_lines_are_rejected_with_reasons_and_good_lines_kept() -> None:
    data = (b"&&\r\n01141436.5\r\n0118abc\r\n01\r\nAB141.0\r\n0120\r\n0116 12.5\r\n"
            b"\xff\xfe99\r\n!!\r\n")
    [frame] = _frames(FrameParser().feed(data))
    decoded = decode_frame(frame, item_map(), 1.0)
    assert {item.channel: item.value for item in decoded.items} == {
        "hookload": pytest.approx(14_365_000.0), "wob": pytest.approx(125_000.0)}
    reasons = sorted(error.reason for error in decoded.errors)
    assert reasons == sorted([
        "item 0118 (torque): value 'abc' is not a number",
        "line '01' is too short for a four-digit code and a value",
        "line 'AB141.0' does not start with a four-digit item code",
        "line '0120' is too short for a four-digit code and a value",
        "line is not ASCII text",
    ])


def test_garbage_overlong_and_unclosed_frames() -> None:
    parser = FrameParser(max_frame_bytes=64)
    out = parser.feed(b"hello rig\r\n" + FRAME[:41])  # garbage, then a frame begins...
    out += parser.feed(b"&&\r\n01141000\r\n!!\r\n")  # ...and is cut by the next one
    out += parser.feed(b"&&\r\n" + b"01141000\r\n" * 10 + b"01161\r\n!!\r\n")  # too long
    out += parser.feed(b"&&\r\n01142000\r\n!!\r\n")  # back in step
    out += parser.feed(b"x" * 100)  # a line without end longer than a frame
    out += parser.close()
    kinds = [(type(o).__name__, o.reason if isinstance(o, FrameError) else o.error)
             for o in out]
    assert kinds == [
        ("FrameError", "bytes outside a frame (no '&&' before them)"),
        ("WitsFrame", "frame not closed by '!!' before the next '&&'"),
        ("WitsFrame", None),
        ("FrameError", "frame longer than 64 bytes without '!!', dropped"),
        ("WitsFrame", None),
        ("FrameError", "bytes outside a frame (no '&&' before them)"),
    ]
    unclosed = out[1]
    assert isinstance(unclosed, WitsFrame)
    assert [line.code for line in unclosed.lines] == ["0105", "0106", "0108"]
    assert isinstance(out[4], WitsFrame) and out[4].lines[0].value == "2000"
    assert all(len(o.raw) <= 64 for o in out if isinstance(o, FrameError))


def test_encode_then_parse_round_trip_through_si() -> None:
    items = item_map("field")
    values = {"hookload": 1.234567e6, "torque": 31_234.5, "bit_depth": 2500.25,
              "mud_temp_in": 45.5, "flow_in": 0.05}
    t = 1_700_000_123.9
    data = encode_sample_frame(t, values, items)
    [frame] = _frames(FrameParser().feed(data))
    decoded = decode_frame(frame, items, 0.0)
    assert decoded.t == 1_700_000_123.0  # whole seconds
    got = {item.channel: item.value for item in decoded.items}
    assert got == {k: pytest.approx(v, rel=1e-12) for k, v in values.items()}
    # 1 klbf = 1000 lb x 0.45359237 kg/lb x 9.80665 m/s^2
    assert si_to_items({"hookload": 4448.2216152605, "spp": 1e5}, items) == {
        "0114": pytest.approx(1.0, rel=1e-12), "0121": pytest.approx(14.503773773, rel=1e-9)}
    assert encode_frame({"0114": 1e-7, "0101": "A"}) == b"&&\r\n01140.0000001\r\n0101A\r\n!!\r\n"
    with pytest.raises(ValueError, match="not four digits"):
        encode_frame({"114": 1.0})
    with pytest.raises(ValueError, match="cannot be sent"):
        encode_frame({"0101": "a\r\nb"})


def _decode_all(messages: list[RawMessage]) -> list[tuple[str, dict[str, object]]]:
    return [(m.topic, json.loads(m.payload)) for m in messages]


def test_frame_messages_in_tdmon_payload_form() -> None:
    topics = {"hookload": "rig/A/hookload", "torque": "rig/A/tq", "rpm": "rig/A/rpm",
              "bit_depth": "rig/A/bit_depth"}
    items = {code: spec for code, spec in item_map().items() if spec.channel in topics}
    [frame] = _frames(FrameParser().feed(FRAME.replace(b"011825.75", b"0118x")))
    messages = frame_messages(frame, items, topics, "rig/A/wits0", 5.0)
    assert all(m.source == "wits0" and m.receive_time == 5.0 for m in messages)
    decoded = _decode_all(messages)
    assert [topic for topic, _ in decoded] == ["rig/A/bit_depth", "rig/A/hookload",
                                               "rig/A/rpm", "rig/A/tq"]
    first = decoded[0][1]
    assert first["frame"] == FRAME.replace(b"011825.75", b"0118x").decode()
    assert first["time_from"] == "wits" and first["t"] == T_FRAME
    assert decoded[1][1] == {"t": T_FRAME, "value": pytest.approx(14_365_000.0), "unit": "N",
                             "wits": "01141436.5"}
    assert decoded[3][1] == {"t": T_FRAME, "value": "x", "unit": "N*m", "wits": "0118x",
                             "error": "item 0118 (torque): value 'x' is not a number"}
    [nothing] = _decode_all(frame_messages(
        _frames(FrameParser().feed(b"&&\r\n0101WELL\r\n!!\r\n"))[0], items, topics,
        "rig/A/wits0", 5.0))
    assert nothing == ("rig/A/wits0", {"t": 5.0, "frame": "&&\r\n0101WELL\r\n!!\r\n",
                                       "error": "no item of the frame is mapped to a channel"})
