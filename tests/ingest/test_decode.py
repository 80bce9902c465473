"""The pure decoder: the payload contract, unit conversion, and a hypothesis fuzz."""

from __future__ import annotations

import json
import math

import orjson
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tdmon.ingest import decode
from tdmon.ingest.decode import (
    ChannelSpec,
    Decoder,
    SampleChecks,
    parse_payload,
    parse_payload_seq,
    parse_time,
)
from tdmon.ingest.types import RawMessage, Rejected, Sample, payload_text

DECODER = Decoder("rig/F4", [
    ChannelSpec("hookload", "HKLD", unit="kN", minimum=-1e5, maximum=1e7),
    ChannelSpec("torque", "torque", unit="kN*m"),
    ChannelSpec("bit_depth", "bit_depth"),  # no configured unit: the payload must say
    ChannelSpec("mud_temp_in", "mud_temp_in", unit="degF"),
])


def raw(topic: str, body: object | bytes) -> RawMessage:
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    return RawMessage("mqtt", topic, data, 1_700_000_000.0)


def test_configured_unit_is_converted_to_si() -> None:
    sample = DECODER.decode(raw("rig/F4/HKLD", {"t": 1475600400.0, "value": 1436.5}))
    assert isinstance(sample, Sample)
    assert sample.channel == "hookload"
    assert sample.value == pytest.approx(1436.5e3)
    assert sample.unit == "N"
    assert sample.t == 1475600400.0
    assert sample.topic == "rig/F4/HKLD"


def test_payload_unit_overrides_the_configured_one() -> None:
    sample = DECODER.decode(raw("rig/F4/HKLD", {"t": 0.5, "value": 100, "unit": "klbf"}))
    assert isinstance(sample, Sample)
    assert sample.value == pytest.approx(444822.16, rel=1e-6)
    feet = DECODER.decode(raw("rig/F4/bit_depth", {"t": 1, "value": 9950, "unit": "ft"}))
    assert isinstance(feet, Sample) and feet.value == pytest.approx(3032.76)


def test_temperature_offset() -> None:
    sample = DECODER.decode(raw("rig/F4/mud_temp_in", {"t": 1, "value": 212}))
    assert isinstance(sample, Sample) and sample.value == pytest.approx(100.0)


def test_iso_time() -> None:
    sample = DECODER.decode(raw("rig/F4/HKLD", {"t": "2016-10-04T17:00:00Z", "value": 1}))
    assert isinstance(sample, Sample) and sample.t == 1475600400.0
    naive = DECODER.decode(raw("rig/F4/HKLD", {"t": "2016-10-04T17:00:00", "value": 1}))
    assert isinstance(naive, Sample) and naive.t == 1475600400.0  # naive means UTC


@pytest.mark.parametrize(("topic", "body", "reason"), [
    ("rig/F4/HKLD", b"{not json", "malformed JSON"),
    ("rig/F4/HKLD", b"\xff\xfe", "not UTF-8"),
    ("rig/F4/HKLD", [1, 2], "not an object"),
    ("rig/F4/HKLD", {"value": 1}, "missing 't'"),
    ("rig/F4/HKLD", {"t": 1}, "missing 'value'"),
    ("rig/F4/HKLD", {"t": 1, "value": "12"}, "must be a number"),
    ("rig/F4/HKLD", {"t": 1, "value": True}, "must be a number"),
    ("rig/F4/HKLD", {"t": True, "value": 1}, "got bool"),
    ("rig/F4/HKLD", {"t": "yesterday", "value": 1}, "not ISO 8601"),
    ("rig/F4/HKLD", {"t": -5, "value": 1}, "out of range"),
    ("rig/F4/HKLD", {"t": 1.7e12, "value": 1}, "out of range"),  # milliseconds, not seconds
    ("rig/F4/HKLD", b'{"t": 1, "value": NaN}', "not finite"),
    ("rig/F4/HKLD", b'{"t": 1, "value": Infinity}', "not finite"),
    ("rig/F4/HKLD", b'{"t": 1, "value": 1e400}', "not finite"),
    ("rig/F4/HKLD", {"t": 1, "value": 10**400}, "too large"),
    ("rig/F4/HKLD", {"t": 1, "value": 1e9}, "above the hookload maximum"),
    ("rig/F4/HKLD", {"t": 1, "value": -1e9}, "below the hookload minimum"),
    ("rig/F4/HKLD", {"t": 1, "value": 1, "unit": "furlong"}, "not usable for hookload"),
    ("rig/F4/HKLD", {"t": 1, "value": 1, "unit": "m"}, "not usable for hookload"),
    ("rig/F4/HKLD", {"t": 1, "value": 1, "unit": 5}, "'unit' must be"),
    ("rig/F4/bit_depth", {"t": 1, "value": 1}, "no unit in payload"),
    ("rig/F4/weather", {"t": 1, "value": 1}, "unknown topic"),
    ("rig/F4/HKLD", b" " * 5000, "payload too large"),
])
def test_rejections_carry_their_reason(topic: str, body: object, reason: str) -> None:
    result = DECODER.decode(raw(topic, body))
    assert isinstance(result, Rejected), result
    assert reason in result.reason
    assert result.raw == (body if isinstance(body, bytes) else json.dumps(body).encode())
    assert result.topic == topic and result.source == "mqtt"


def test_bad_configured_unit_fails_at_construction() -> None:
    with pytest.raises(ValueError, match="furlong"):
        Decoder("p", [ChannelSpec("hookload", "h", unit="furlong")])
    with pytest.raises(ValueError, match="unknown channel"):
        Decoder("p", [ChannelSpec("weather", "w")])


def test_parse_time_and_payload_text() -> None:
    assert parse_time(1.5) == 1.5
    assert isinstance(parse_time(float("nan")), str)
    assert payload_text(b"abc") == ("abc", "utf-8")
    assert payload_text(b"\xff") == ("/w==", "base64")


# -- fuzz ---------------------------------------------------------------------------------

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True) | st.text(max_size=20),
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=10,
)
units = st.sampled_from(["kN", "N", "klbf", "lbf", "tonne_force", "kg", "m", "furlong", "", " ",
                         "kN*m", "1/0", "degC", "%", "kN kN", "((", "🙂"])
times = (st.floats(allow_nan=True, allow_infinity=True) | st.integers()
         | st.text(max_size=30) | st.sampled_from(["2016-10-04T17:00:00Z", "2016-13-45",
                                                   "9999-12-31T23:59:59+14:00"]))
values = (st.floats(allow_nan=True, allow_infinity=True) | st.integers()
          | st.integers(min_value=10**300, max_value=10**320) | json_values)
payloads = st.one_of(
    st.binary(max_size=200),
    st.builds(lambda t, v: {"t": t, "value": v}, times, values),
    st.builds(lambda t, v, u: {"t": t, "value": v, "unit": u}, times, values, units),
    json_values,
    st.builds(lambda n: {"t": 1.0, "value": 1.0, "pad": "x" * n}, st.integers(0, 10_000)),
)
topics = st.sampled_from(["rig/F4/HKLD", "rig/F4/torque", "rig/F4/bit_depth", "rig/F4/xyz",
                          "rig/F4/mud_temp_in", "", "rig/F4/tdmon/model", "#"])


def _encode(body: object) -> bytes:
    if isinstance(body, bytes):
        return body
    try:
        return json.dumps(body).encode()  # NaN/Infinity are written as JSON's non-standard words
    except (ValueError, TypeError):
        return repr(body).encode()


@settings(max_examples=2500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(topic=topics, body=payloads)
def test_fuzz_decoder_never_raises_and_only_passes_clean_samples(topic: str, body: object
                                                                  ) -> None:
    data = _encode(body)
    result = DECODER.decode(RawMessage("zenoh", topic, data, 0.0))
    if isinstance(result, Rejected):
        assert result.reason and result.raw == data
        json.dumps({"reason": result.reason, "payload": payload_text(data)[0]})
        return
    # a Sample is finite, in range, on a known channel, and came from a well-formed object
    assert math.isfinite(result.value) and math.isfinite(result.t)
    assert 0 <= result.t < 7_258_118_400.0
    assert result.channel in {"hookload", "torque", "bit_depth", "mud_temp_in"}
    obj = json.loads(data)
    assert isinstance(obj, dict) and not isinstance(obj["value"], bool)
    parsed = parse_payload(data)
    assert not isinstance(parsed, str) and parsed[0] == result.t


# -- the plain-object fast path ---------------------------------------------------------

def _loads_outcome(text: str) -> tuple[str, object]:
    """What json.loads makes of ``text``, an error as the decoder words it."""
    try:
        return "value", json.loads(text)
    except ValueError as exc:
        message = str(exc)
        return "error", "malformed JSON: " + (message if len(message) <= 80
                                              else message[:77] + "...")


@settings(max_examples=500, deadline=None)
@given(body=json_values | st.builds(lambda t, v: {"t": t, "value": v}, times, values),
       before=st.sampled_from(["", " ", "\n", "\ufeff", "x", "{"]),
       after=st.sampled_from(["", " ", "\r\n", "}", "{}", "x", "]"]))
def test_payload_parsing_is_json_loads_whatever_surrounds_the_object(
        body: object, before: str, after: str) -> None:
    text = before + _encode(body).decode() + after
    kind, expected = _loads_outcome(text)
    parsed = parse_payload(text.encode())
    if kind == "error":
        assert parsed == expected  # json's own message
        return
    if not isinstance(expected, dict) or "t" not in expected or "value" not in expected:
        assert isinstance(parsed, str)
        return
    if not isinstance(parsed, str):  # the rules on t, value and unit are tested above
        assert parsed == (parse_time(expected["t"]), float(expected["value"]),
                          expected.get("unit"))


counters = (st.none() | st.integers() | st.integers(min_value=2**63 - 2, max_value=2**65)
            | st.floats(allow_nan=False) | st.booleans() | st.text(max_size=3))
usual = st.builds(
    lambda t, v, u, q, extra: {"t": t, "value": v, **({"unit": u} if u else {}),
                               **({"seq": q} if q is not None else {}), **extra},
    st.floats(-10.0, 8e9) | st.integers(-10, 8 * 10**9) | times,
    st.floats(allow_nan=False) | st.integers(-2**64, 2**64) | values,
    st.none() | units | st.integers(), counters,
    st.dictionaries(st.sampled_from(["error", "x", "t0"]), st.none() | st.text(max_size=3),
                    max_size=1))


def _refuse(data: bytes) -> object:
    raise orjson.JSONDecodeError("refused", "", 0)


def _by_json(payload: bytes) -> object:
    """``parse_payload_seq`` with the json module as the only parser (the oracle): orjson
    refuses every payload."""
    with pytest.MonkeyPatch.context() as patched:
        patched.setattr(decode.orjson, "loads", _refuse)
        return parse_payload_seq(payload)


@settings(max_examples=1500, deadline=None)
@given(body=usual)
def test_the_usual_payload_s_answer_is_the_json_module_s(body: dict[str, object]) -> None:
    payload = _encode(body)
    assert parse_payload_seq(payload) == _by_json(payload)


@settings(max_examples=1000, deadline=None)
@given(body=payloads)
def test_any_payload_s_answer_is_the_json_module_s(body: object) -> None:
    payload = _encode(body)
    assert parse_payload_seq(payload) == _by_json(payload)


@pytest.mark.parametrize("payload", [
    b'{"t":1714521600.0,"value":1472812.0,"unit":"N"}',
    b'{"t":1714521600,"value":-0.0,"unit":"kN","seq":7}',
    b'{"t":1714521600,"value":1,"t":5}',  # a repeated key: the last one, as json
    b'{"t":1714521600.0,"value":9007199254740993}',  # an integer float() rounds
    b'{"t":1714521600.0,"value":1,"unit":"\\ud800"}',  # a lone surrogate
    b'{"t":1714521600.0,"value":1,"unit":"\xff"}',  # not UTF-8
    b'{"t":1714521600.0,"value":1,"seq":1.0}', b'{"t":1714521600.0,"value":1,"seq":-3}',
    b'{"t":1714521600.0,"value":1,"seq":99999999999999999999999}',
    b'{"t":1714521600.0,"value":1,"seq":-9223372036854775809}',
    b'{"t":1714521600.0,"value":1,"seq":18446744073709551615}',
    b'{"t":99999999999999999999999,"value":1}',
    b'{"t":1714521600.0,"value":-99999999999999999999}',
    b'{"t":1714521600.0,"value":1' + b"0" * 400 + b"}",  # an integer beyond a double
    b'{"t":1714521600.0,"value":1,"x":NaN}',  # a non-standard word outside the fields
    b'{"t":1714521600.0,"value":true}', b' {"t":1714521600.0,"value":1e400} ',
    b'{"t":1714521600.0,"value":1,"unit":" "}', b'{"t":1714521600.0,"value":1,"unit":null}',
    b'{"t":-1.0,"value":1}', b'{"t":"2024-05-01T00:00:00Z","value":1}',
    b'{"t":1714521600.0,"value":1,"error":"bad line"}', b'{"t":1714521600.0}',
    b'\xef\xbb\xbf{"t":1714521600.0,"value":1}', b'[1, 2]', b'{"t":1714521600.0,"value":1',
    b'99999999999999999999999', b'"text"', b"[" * 2000 + b"]" * 2000,
])
def test_the_answer_is_the_json_module_s_at_the_edges(payload: bytes) -> None:
    assert parse_payload_seq(payload) == _by_json(payload)


def test_orjson_reads_the_usual_payload() -> None:
    # orjson's path is taken (the tests above would also pass without it)
    with pytest.MonkeyPatch.context() as patched:
        patched.setattr(decode.json, "loads", _refuse)
        assert parse_payload_seq(b'{"t":1714521600.0,"value":1.5,"unit":"N","seq":3}') == (
            1714521600.0, 1.5, "N", 3)


@pytest.mark.parametrize(("text", "expected"), [
    (' {"t": 1, "value": 2}', (1.0, 2.0, None)),  # whitespace around: json.loads accepts it
    ('{"t": 1, "value": 2}\n', (1.0, 2.0, None)),
    ('{"t": 0.0, "value": 2}', (0.0, 2.0, None)),  # the first second of 1970 is in range
    ('{"t": 7258118399.5, "value": -0.0, "unit": "N"}', (7258118399.5, -0.0, "N")),
    ('{"t": 7258118400.0, "value": 2}', "'t' out of range (7.25812e+09 s)"),
    ('{"t": NaN, "value": 2}', "'t' is not finite (nan)"),
    ('{"t": -Infinity, "value": 2}', "'t' is not finite (-inf)"),
    ('{"t": 1, "value": 2}{}', "malformed JSON: Extra data: line 1 column 21 (char 20)"),
    ("\ufeff{}", "malformed JSON: Unexpected UTF-8 BOM (decode using utf-8-sig): line 1 "
                 "column 1 (char 0)"),
    ('{"t": 1, "value": 2', "malformed JSON: Expecting ',' delimiter: line 1 column 20 "
                            "(char 19)"),
])
def test_payload_edge_cases(text: str, expected: object) -> None:
    assert parse_payload(text.encode()) == expected


# -- sample checks (issue 13, item 8): a clock never set, negative depths, depths beyond the well

CHECKED = Decoder("rig", [ChannelSpec("bit_depth", "bit_depth", "m", minimum=-2.0),
                          ChannelSpec("hole_depth", "hole_depth", "ft", minimum=-2.0),
                          ChannelSpec("hookload", "hookload", "kN")],
                  checks=SampleChecks(earliest_t=946_684_800.0, well_depth=3000.0,
                                      depth_margins={"bit_depth": 500.0, "hole_depth": 100.0}))


@pytest.mark.parametrize(("topic", "body", "reason"), [
    ("rig/hookload", {"t": 0, "value": 900},
     "t before the earliest accepted time (1970-01-01T00:00:00Z < 2000-01-01: a rig clock "
     "that was never set)"),
    ("rig/hookload", {"t": "1999-12-31T23:59:59Z", "value": 900},
     "t before the earliest accepted time (1999-12-31T23:59:59Z < 2000-01-01: a rig clock "
     "that was never set)"),
    ("rig/bit_depth", {"t": 1.7e9, "value": -2.5}, "value -2.5 below the bit_depth minimum -2 m"),
    ("rig/bit_depth", {"t": 1.7e9, "value": 3500.5},
     "beyond the well: bit_depth 3500.5 m > 3500 m (the well's total depth 3000 m + 500 m)"),
    # 11 500 ft = 3505.2 m: in feet, beyond a 3000 m well with a 100 m margin
    ("rig/hole_depth", {"t": 1.7e9, "value": 11_500},
     "beyond the well: hole_depth 3505.2 m > 3100 m (the well's total depth 3000 m + 100 m)"),
])
def test_each_misleading_sample_is_rejected_with_its_reason(
        topic: str, body: dict[str, object], reason: str) -> None:
    rejected = CHECKED.decode(raw(topic, body))
    assert isinstance(rejected, Rejected)
    assert rejected.reason == reason


@pytest.mark.parametrize(("topic", "value"), [
    ("rig/bit_depth", -2.0), ("rig/bit_depth", 0.0), ("rig/bit_depth", 3500.0),
    ("rig/hole_depth", 3100.0 / 0.3048), ("rig/hookload", 1e6),  # no depth limit on hook load
])
def test_values_at_the_limits_are_samples(topic: str, value: float) -> None:
    sample = CHECKED.decode(raw(topic, {"t": "2000-01-01", "value": value}))
    assert isinstance(sample, Sample)
    assert sample.t == 946_684_800.0


def test_without_checks_the_decoder_takes_any_time_and_depth() -> None:
    sample = DECODER.decode(raw("rig/F4/bit_depth", {"t": 0, "value": -1e4, "unit": "m"}))
    assert isinstance(sample, Sample) and sample.value == -1e4


def _every_check(decoder: Decoder) -> Decoder:
    """``decoder`` with no value taken in its accepted range at once: each through every
    check of its own."""
    slow = Decoder.__new__(Decoder)
    slow.__dict__.update(decoder.__dict__)
    slow._routes = {topic: (*route[:-2], math.inf, -math.inf)
                    for topic, route in decoder._routes.items()}
    return slow


@settings(max_examples=600, deadline=None)
@given(topic=st.sampled_from(["rig/bit_depth", "rig/hole_depth", "rig/hookload"]),
       value=st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(
           [-2.0, -2.0000001, 3500.0, 3500.0001, 3100.0 / 0.3048, 1e12, 1e15 / 1000.0]),
       unit=st.sampled_from([None, "m", "ft", "kN", "N", "lbf"]))
def test_the_accepted_range_decides_as_every_check_does(
        topic: str, value: float, unit: str | None) -> None:
    body: dict[str, object] = {"t": 1.7e9, "value": value}
    if unit is not None:
        body["unit"] = unit
    message = raw(topic, body)
    assert CHECKED.decode(message) == _every_check(CHECKED).decode(message)
