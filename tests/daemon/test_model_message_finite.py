"""The model message vouches for its numbers (``FiniteMessage``) only when every one is finite,
and a recorder that then skips its search for a NaN counts and writes exactly what it did."""

from __future__ import annotations

import json
import math
import pickle
from pathlib import Path
from typing import Any

import orjson
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tdmon.daemon.pipeline import Frame
from tdmon.daemon.steps.monitor import ModelledLoads, model_message
from tdmon.record.mcap_recorder import McapRecorder, _has_nonfinite
from tdmon.record.reader import read_messages
from tdmon.record.sink import FiniteMessage
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


def _walked(message: dict[str, Any]) -> bool:
    """The recorder's own search, on a plain copy (what it did before the vouching)."""
    return _has_nonfinite(dict(message))


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
def test_vouched_only_when_every_number_is_finite(
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
    plain = dict(message)
    given_numbers = [t, depth, pick_up, slack_off, rotating, torque_rotating,
                     *band[0], *band[1], *band[2], *values.values()]
    assert message == plain and json.dumps(message) == json.dumps(plain)
    try:
        data = orjson.dumps(plain)
    except TypeError:  # an integer beyond 64 bits: the recorder takes the json module's way
        pass
    else:
        assert orjson.dumps(message) == data
    if type(message) is FiniteMessage:
        assert not _walked(plain)
    elif all(abs(x) < 1e300 for x in given_numbers):
        raise AssertionError(f"finite numbers not vouched for: {plain}")  # the usual case
    again = pickle.loads(pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL))
    assert type(again) is type(message) and json.dumps(again) == json.dumps(message)


@pytest.mark.parametrize("where", ["inline", "child"])
def test_the_recorder_counts_and_writes_what_it_did(tmp_path: Path, where: str) -> None:
    loads = ModelledLoads(1000.0, 8e5, 6e5, 7e5, 2e4, (0.1, 0.2), (7e5, 9e5), (5e5, 4e5))
    frames = [Frame(1.0, 0, {"hookload": 1e6}, {}, state="in_slips"),  # null residuals
              Frame(2.0, 0, {"hookload": math.nan}, {}, state="pick_up"),
              Frame(3.0, 0, {"hookload": 1e6, "torque": math.inf}, {}, state="drilling"),
              Frame(4.0, 0, {"hookload": 1e6}, {}, state="pick_up")]
    messages = [model_message(frame, loads) for frame in frames]
    assert [type(m) is FiniteMessage for m in messages] == [True, False, False, True]
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
