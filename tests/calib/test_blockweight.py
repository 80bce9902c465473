"""The running block weight: the incremental tracker gives the batch numbers exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tdmon.calib.blockweight import (
    BlockWeightState,
    BlockWeightTracker,
    block_weight_from_samples,
    update_block_weight,
)

# in-slips hook loads: mostly noise about one value, with repeats (coarse load cells), exact
# zeros (a dead sensor), hoisting peaks and non-finite readings
hookload = st.one_of(
    st.floats(min_value=640e3, max_value=670e3),
    st.sampled_from([655e3, 655e3 + 0.5, 0.0, 900e3, 1.2e6]),
    st.floats(min_value=-1e4, max_value=2e6, allow_subnormal=False),
    st.sampled_from([math.nan, math.inf, -math.inf]),
)


@settings(max_examples=300, deadline=None)
@given(values=st.lists(hookload, min_size=1, max_size=150),
       keep=st.sampled_from([1, 2, 3, 4, 7, 10, 400]))
def test_tracker_equals_the_batch_computation(values: list[float], keep: int) -> None:
    tracker = BlockWeightTracker(keep=keep)
    state = BlockWeightState()
    for value in values:
        estimate = tracker.add(value)
        state = update_block_weight(state, value, keep=keep)
        assert tracker.recent == state.recent
        if state.estimate is None:
            assert estimate is None
            continue
        assert estimate is not None
        # equal, not approximately: the same order statistics and the same arithmetic
        assert (estimate.value, estimate.std, estimate.n) == (
            state.estimate.value, state.estimate.std, state.estimate.n)
        batch = block_weight_from_samples(tracker.recent)
        assert (estimate.value, estimate.std) == (batch.value, batch.std)
    assert tracker.estimate == state.estimate


def test_tracker_by_hand() -> None:
    tracker = BlockWeightTracker(keep=4)
    assert tracker.add(math.nan) is None
    for value in (655e3, 652e3, 658e3):
        tracker.add(value)
    # median 655 kN; deviations 0, 3, 3 kN -> MAD 3 kN
    estimate = tracker.estimate
    assert estimate is not None and estimate.n == 3
    assert estimate.value == 655e3
    assert estimate.std == pytest.approx(1.2533 * 1.4826 * 3e3 / math.sqrt(3))
    tracker.add(900e3)  # a hoisting peak: median of four, (655 + 658) / 2
    assert tracker.estimate is not None and tracker.estimate.value == 656.5e3
    # deviations 1.5, 1.5, 4.5, 243.5 kN -> MAD 3 kN
    assert tracker.estimate.std == pytest.approx(1.2533 * 1.4826 * 3e3 / 2.0)
    tracker.add(654e3)  # the window keeps four: 655 kN drops out
    assert tracker.recent == (652e3, 658e3, 900e3, 654e3)
    assert tracker.estimate.value == 656e3
    assert tracker.add(math.inf) is tracker.estimate  # a non-finite value keeps the estimate


def test_tracker_long_run_against_numpy() -> None:
    rng = np.random.default_rng(3)
    values = np.round(655e3 + 2e3 * rng.standard_normal(2000), 0)  # 1 N resolution: ties
    tracker = BlockWeightTracker()
    for value in values:
        tracker.add(float(value))
    window = values[-400:]
    median = float(np.median(window))
    assert tracker.estimate is not None and tracker.estimate.value == median
    mad = float(np.median(np.abs(window - median)))
    assert tracker.estimate.std == 1.2533 * (1.4826 * mad) / math.sqrt(400)
    with pytest.raises(ValueError):
        BlockWeightTracker(keep=0)
