"""`evolve` makes what `dataclasses.replace` makes, or leaves the work to it."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tdmon.calib.estimator_state import SampleState
from tdmon.calib.frozen import evolve
from tdmon.calib.kalman import KalmanState
from tdmon.calib.mu_calibration import MuTState


@dataclass(frozen=True)
class _Plain:
    a: int = 0
    b: tuple[int, ...] = ()
    c: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class _Cached:
    a: int = 0

    @cached_property
    def twice(self) -> int:
        return 2 * self.a


@dataclass(frozen=True)
class _PostInit:
    a: int = 0
    b: int = field(init=False, default=0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "b", self.a + 1)


@given(st.integers(), st.integers(), st.booleans(), st.booleans())
def test_as_replace(a: int, b: int, change_a: bool, change_b: bool) -> None:
    obj = _Plain(1, (2,), [3])
    changes = {**({"a": a} if change_a else {}), **({"b": (b,)} if change_b else {})}
    new = evolve(obj, **changes)
    assert new == dataclasses.replace(obj, **changes)
    assert new is not obj and type(new) is _Plain
    assert vars(new) == vars(dataclasses.replace(obj, **changes))
    assert obj == _Plain(1, (2,), [3])  # the original is left as it was
    with pytest.raises(dataclasses.FrozenInstanceError):
        new.a = 5  # type: ignore[misc]


def test_kalman_states() -> None:
    state = MuTState(np.zeros(2), np.eye(2), temperature_min=3.0)
    new = evolve(state, updates=4, temperature_max=7.0)
    assert type(new) is MuTState
    assert vars(new).keys() == vars(state).keys()
    assert (new.updates, new.temperature_min, new.temperature_max) == (4, 3.0, 7.0)
    assert new.mean is state.mean
    base = evolve(KalmanState(np.ones(1), np.eye(1)), innovation=2.0)
    assert base == dataclasses.replace(KalmanState(base.mean, base.covariance), innovation=2.0)


def test_falls_back_to_replace() -> None:
    cached = _Cached(2)
    assert cached.twice == 4
    assert evolve(cached, a=5).twice == 10  # the cache is not copied
    assert evolve(_PostInit(1), a=5).b == 6  # __post_init__ runs
    assert evolve(SampleState(), block_alarmed=True).block_alarmed  # slots
    with pytest.raises(TypeError):
        evolve(_Plain(), d=1)


def test_per_frame_states_stay_frozen_values() -> None:
    # the hand-written __init__ of these (tests/test_hand_written_inits.py) keeps them values
    import copy
    import pickle

    from tdmon.calib.estimator_state import EstimatorState
    from tdmon.calib.windows import WindowAccumulator
    from tdmon.vocabulary import RigState

    acc = WindowAccumulator(RigState.PICK_UP, (), (1.0,))
    state = SampleState(acc, block_alarmed=True)
    for value in (acc, state, EstimatorState(state, None)):  # type: ignore[arg-type]
        assert pickle.loads(pickle.dumps(value)) == value == copy.copy(value)
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(value, dataclasses.fields(value)[0].name, None)
    assert SampleState() == SampleState(WindowAccumulator())
    assert dataclasses.replace(state, block_alarmed=False).accumulator is acc
