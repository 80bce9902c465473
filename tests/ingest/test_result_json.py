"""The published result's JSON: compact, valid JSON (NaN/inf as null), numpy values as numbers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tdmon.ingest.result_json import encode_result


def test_a_model_message_round_trips_through_the_json_module() -> None:
    message = {"t": 1.7e9 + 0.125, "bit_depth": 2450.25, "alarms": [], "state": "pick_up",
               "band": {"mu": [0.1, 0.2], "hookload": [1.1e6, 1.2e6]}, "residual": None,
               "count": 3, "ok": True}
    data = encode_result(message)
    assert json.loads(data) == message
    assert b" " not in data.replace(b"pick_up", b"")  # compact separators


def test_non_finite_numbers_become_null_so_the_payload_is_json() -> None:
    data = encode_result({"a": math.nan, "b": [1.0, math.inf], "c": {"d": -math.inf}})
    # the json module's strict parse refuses NaN/Infinity tokens
    assert json.loads(data, parse_constant=lambda name: pytest.fail(name)) == {
        "a": None, "b": [1.0, None], "c": {"d": None}}


def test_numpy_values_are_written_as_their_numbers() -> None:
    data = encode_result({"x": np.float64(1.5), "y": np.float32(0.25), "z": np.arange(3),
                          "n": np.int64(7)})
    assert json.loads(data) == {"x": 1.5, "y": 0.25, "z": [0, 1, 2], "n": 7}


def test_what_orjson_refuses_goes_through_the_json_module_with_the_same_rules() -> None:
    # an integer beyond 64 bits and a non-string key: orjson refuses both
    data = encode_result({"big": 2**70, 3: "three", "nan": math.nan})
    assert json.loads(data) == {"big": 2**70, "3": "three", "nan": None}


def test_something_that_is_not_json_raises_type_error() -> None:
    with pytest.raises(TypeError):
        encode_result({"x": object()})
