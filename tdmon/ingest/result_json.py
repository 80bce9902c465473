"""The JSON bytes of a result message published to dashboards (MQTT and Zenoh sinks).

One message per frame leaves the daemon this way, so the encoder is on the hot path: orjson
encodes a ``model`` message about ten times faster than the json module. Its output is compact
JSON (no spaces) and it writes NaN and infinities as ``null``, as the recording does
(docs/recording.md); the json module wrote them as ``NaN``/``Infinity``, which is not JSON and
which a browser's ``JSON.parse`` refuses.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import orjson


def numpy_default(value: Any) -> Any:
    """The ``default`` of a JSON encoder: numpy scalars and arrays (float32, int64, ndarray)
    as their Python numbers and lists; ``TypeError`` for anything else."""
    tolist = getattr(value, "tolist", None)
    if tolist is None:
        raise TypeError(f"{type(value).__name__} is not JSON serialisable")
    return tolist()


def replace_nonfinite(value: Any) -> Any:
    """``value`` with every NaN and infinity replaced by None (numpy values as Python ones)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {key: replace_nonfinite(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [replace_nonfinite(item) for item in value]
    if hasattr(value, "tolist"):
        return replace_nonfinite(value.tolist())
    return value


def encode_result(message: Mapping[str, Any]) -> bytes:
    """``message`` as compact JSON bytes; NaN and infinities as ``null``.

    What orjson refuses (a key that is not a string, an integer beyond 64 bits) goes through
    the json module, with the same rule for non-finite numbers. Raises ``TypeError`` for a value
    that is not JSON at all.
    """
    try:
        return orjson.dumps(message, default=numpy_default)
    except TypeError:  # orjson.JSONEncodeError
        return json.dumps(replace_nonfinite(message), separators=(",", ":"),
                          allow_nan=False, default=numpy_default).encode()
