"""The simulator's loads per rig state (tdmon.replay.loads) and the phase -> state timeline
(tdmon.replay.timeline), with the rig-state and operation words of tdmon.vocabulary."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tdmon.model.torque_drag import WellModel
from tdmon.replay.loads import MOVING_DOWN, MOVING_UP, Loads
from tdmon.replay.scenario import load_scenario_model
from tdmon.replay.spec import Phase, Scenario, TightSpot
from tdmon.replay.timeline import STATES, build_timeline
from tdmon.vocabulary import RigState

BIT = 4105.0  # [m], inside the tight spot below


@pytest.fixture
def scenario(write_scenario: Callable[..., Path]) -> Scenario:
    return load_scenario_model(write_scenario())


def test_moving_states_by_direction() -> None:
    assert set(MOVING_UP) == {"pick_up", "back_reaming"}
    assert set(MOVING_DOWN) == {"slack_off", "reaming"}
    assert len(STATES) == 9 and "unknown" not in STATES


def test_each_state_has_the_load_case_of_its_operation(scenario: Scenario) -> None:
    model = WellModel(scenario.well)
    mu = np.full(model.grid.element_mid_md.size, 0.25)
    loads = Loads(scenario, mu, model)
    # in slips the hook carries the block only
    assert loads.one(RigState.IN_SLIPS, BIT, 0.0, 0.0, 0.0) == (scenario.well.block_weight, 0.0)
    static = model.evaluate("static", BIT, mu, method=scenario.method)
    assert loads.one(RigState.STATIC, BIT, 0.0, 0.0, 0.0) == static
    assert loads.one(RigState.CIRCULATING, BIT, 0.0, 0.0, 0.0) == static
    for state, operation in ((RigState.PICK_UP, "pick_up"), (RigState.SLACK_OFF, "slack_off"),
                             (RigState.ROTATING_OFF_BOTTOM, "rotating")):
        assert loads.one(state, BIT, 0.3, 10.0, 0.0) == \
            model.evaluate(operation, BIT, mu, method=scenario.method), state
    # not rotating, reaming and back-reaming are pure slack-off and pick-up
    assert loads.one(RigState.BACK_REAMING, BIT, -0.3, 0.0, 0.0) == \
        loads.one(RigState.PICK_UP, BIT, -0.3, 0.0, 0.0)
    assert loads.one(RigState.REAMING, BIT, 0.3, 0.0, 0.0) == \
        loads.one(RigState.SLACK_OFF, BIT, 0.3, 0.0, 0.0)
    drilling = loads.one(RigState.DRILLING, BIT, 0.01, 10.0, 80e3)
    assert drilling == model.evaluate("on_bottom", BIT, mu, method=scenario.method, wob=80e3,
                                      bit_torque=80e3 * scenario.rig.bit_torque_factor)
    # weight on the bit takes hook load off: 80 kN less than rotating off bottom, friction aside
    assert 0.0 < loads.one(RigState.ROTATING_OFF_BOTTOM, BIT, 0.0, 10.0, 0.0)[0] \
        - drilling[0] <= 80e3 + 1.0


def test_tight_spot_pulls_up_and_sets_down(scenario: Scenario) -> None:
    model = WellModel(scenario.well)
    mu = np.full(model.grid.element_mid_md.size, 0.25)
    plain = Loads(scenario, mu, model)
    spotted = Loads(dataclasses.replace(scenario, tight_spots=(TightSpot(4100.0, 10.0, 50e3),)),
                    mu, model)
    for state, sign in ((RigState.PICK_UP, 1.0), (RigState.BACK_REAMING, 1.0),
                        (RigState.SLACK_OFF, -1.0), (RigState.REAMING, -1.0),
                        (RigState.STATIC, 0.0), (RigState.ROTATING_OFF_BOTTOM, 0.0)):
        extra = spotted.one(state, BIT, 0.2, 6.0, 0.0)[0] - plain.one(state, BIT, 0.2, 6.0,
                                                                    0.0)[0]
        assert extra == pytest.approx(sign * 50e3, abs=1e-6), state


def test_phases_become_rig_states(scenario: Scenario) -> None:
    phases = (Phase("static", duration=20.0), Phase("circulate", duration=10.0, flow=0.03),
              Phase("rotate", duration=5.0, rpm=10.0, flow=0.03),
              Phase("trip_out", to=4090.0, speed=0.5, slips_time=30.0),
              Phase("slips", duration=15.0))
    timeline = build_timeline(dataclasses.replace(scenario, bit_depth=4100.0,
                                                  block_position=12.0, phases=phases))
    assert timeline.state == (RigState.STATIC, RigState.CIRCULATING,
                              RigState.ROTATING_OFF_BOTTOM, RigState.PICK_UP, RigState.IN_SLIPS)
    # 10 m at 0.5 m/s with the block 10 m above its low end (travel 2-30 m): 20 s, no connection
    np.testing.assert_allclose(timeline.t1 - timeline.t0, [20.0, 10.0, 5.0, 20.0, 15.0])
    assert timeline.bit1[3] == 4090.0 and timeline.block1[3] == 22.0
    assert timeline.duration == 70.0
