"""A batch's encoding finds every NaN and infinity of a model message (written as null), and
only those, and a recorder counts and writes exactly what it found."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import orjson
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tdmon.daemon.pipeline import Frame
from tdmon.daemon.steps.monitor import ModelledLoads, model_message
from tdmon.record.batch import Batch
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import read_messages
from tdmon.record.writer_process import RecorderProcess
from tdmon.vocabulary import RigState

# mostly ordinary numbers, with at most two odd ones put in anywhere: NaN, infinities, finite
# values whose sum overflows, integers (a 64-bit value from the decoder, one too large for a
# float)
ordinary = st.one_of(st.floats(-1e7, 1e7), st.integers(-(10**6), 10**6))
odd = st.one_of(st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 2**63 - 1,
                                 10**400]),
                st.floats(allow_nan=True, allow_infinity=True))
#: positions in the frame's numbers: t, bit depth, the four loads, 3 x 4 band values,
#: hook load, torque
_COUNT = 6 + 12 + 2


def _refused_by_json(message: dict[str, Any]) -> bool:
    """Whether the json module refuses the message for a NaN or an infinity (an independent
    check of the batch's search)."""
    try:
        json.dumps(message, allow_nan=False)
    except ValueError:
        return True
    return False


@settings(max_examples=800, deadline=None)
@given(base=st.lists(ordinary, min_size=_COUNT, max_size=_COUNT),
       changes=st.lists(st.tuples(st.integers(0, _COUNT - 1), odd), max_size=2),
       band_size=st.integers(0, 4), missing=st.sampled_from(["", "hookload", "torque", "both"]),
       state=st.sampled_from(list(RigState)))
# a NaN torque off rotation (measured, no residual); a residual that overflows between two
# finite numbers whose sum does not
@example(base=[1.0] * _COUNT, changes=[(19, math.nan)], band_size=2, missing="",
         state=RigState.STATIC)
@example(base=[1.0] * _COUNT, changes=[(18, 1e308), (2, -1e308)], band_size=2, missing="",
         state=RigState.PICK_UP)
@example(base=[1.0] * _COUNT, changes=[(19, 1e308), (5, -1e308)], band_size=2, missing="",
         state=RigState.DRILLING)
def test_the_encoding_finds_every_non_finite_number_and_only_those(
        base: list[float], changes: list[tuple[int, float]], band_size: int, missing: str,
        state: RigState) -> None:
    for index, value in changes:
        base[index] = value
    t, depth, pick_up, slack_off, rotating, torque_rotating = base[:6]
    band = [tuple(base[6 + 4 * i:6 + 4 * i + band_size]) for i in range(3)]
    hookload, torque = base[18:20]
    loads = ModelledLoads(depth, pick_up, slack_off, rotating, torque_rotating, *band)
    values = {name: value for name, value in (("hookload", hookload), ("torque", torque))
              if missing not in (name, "both")}
    try:
        message = model_message(Frame(t, 0, values, {}, state=state.value), loads)
    except OverflowError:  # a residual of an integer too large for a float: no message
        return
    # twice in one batch, beside a message with a null and no NaN: each found where it is
    plain = {"t": 1.0, "residual": {"hookload_N": None}}
    encoded = Batch("/tdmon/model", [0, 1, 2], [message, plain, message]).encoded()
    assert not encoded.refused and len(encoded.datas) == 3
    assert encoded.nonfinite == 2 * _refused_by_json(message)
    back = json.loads(encoded.datas[0])
    assert not _refused_by_json(back)  # NaN and infinities as null: strict JSON
    try:
        data = orjson.dumps(message)
    except TypeError:  # an integer beyond 64 bits: the json module's way, the same values
        assert back == json.loads(json.dumps(message).replace("NaN", "null").replace(
            "-Infinity", "null").replace("Infinity", "null"))
    else:
        assert encoded.datas[0] == data
    given_numbers = [t, depth, pick_up, slack_off, rotating, torque_rotating,
                     *band[0], *band[1], *band[2], *values.values()]
    if all(abs(x) < 1e300 for x in given_numbers):  # the usual case: nothing replaced
        assert encoded.nonfinite == 0


@pytest.mark.parametrize("where", ["inline", "child"])
def test_the_recorder_counts_and_writes_what_it_did(tmp_path: Path, where: str) -> None:
    loads = ModelledLoads(1000.0, 8e5, 6e5, 7e5, 2e4, (0.1, 0.2), (7e5, 9e5), (5e5, 4e5))
    frames = [Frame(1.0, 0, {"hookload": 1e6}, {}, state="in_slips"),  # null residuals
              Frame(2.0, 0, {"hookload": math.nan}, {}, state="pick_up"),
              Frame(3.0, 0, {"hookload": 1e6, "torque": math.inf}, {}, state="drilling"),
              Frame(4.0, 0, {"hookload": 1e6}, {}, state="pick_up")]
    messages = [model_message(frame, loads) for frame in frames]
    recorder = (McapRecorder(tmp_path) if where == "inline"
                else RecorderProcess(path=tmp_path / "child.mcap"))
    with recorder:
        for i, message in enumerate(messages):
            recorder.write("/tdmon/model", i, message)
    stats = recorder.stats
    assert stats.nonfinite_replaced == 2 and stats.written == 4
    back = {m.log_time_ns: m.message for m in read_messages(stats.files[0])}
    assert back[0]["residual"] == {"hookload_N": None, "torque_Nm": None}
    assert back[1]["measured"]["hookload_N"] is None
    assert back[2]["measured"]["torque_Nm"] is None
    assert back[3]["residual"]["hookload_N"] == 1e6 - 8e5
