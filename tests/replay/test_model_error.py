"""Injected model errors of the simulator (a scenario's ``[model_error]``): the truth departs
from the well file by a fluid density factor, an unfilled pipe above a fill level, or a longer
string component; the weight factor each implies, checked against hand computations."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tdmon.errors import ConfigError
from tdmon.model.string import STEEL_DENSITY
from tdmon.model.torque_drag import WellModel
from tdmon.replay.loads import Loads, unfilled_string
from tdmon.replay.scenario import load_scenario_model
from tdmon.replay.session import simulate_session
from tdmon.replay.simulate import session_messages

from .conftest import REPO

WELL = REPO / "replays" / "scenarios" / "wells" / "example-7-1-weights.toml"
GLYDRIL = REPO / "replays" / "scenarios" / "wells" / "example-7-1-glydril.toml"


def _scenario(tmp_path: Path, model_error: str, *, well: Path = WELL,
              bit: float = 3300.0) -> Path:
    path = tmp_path / "scenario.toml"
    path.write_text(f"""
[scenario]
well = "{well}"
prefix = "sim/test"
bit_depth = "{bit:g} m"
hole_depth = "{bit + 10:g} m"
block_position = "2 m"

[model_error]
{model_error}

[sampling]
interval = "5 s"

[[phase]]
kind = "static"
duration = "20 s"

[[phase]]
kind = "trip_out"
to = "{bit - 20:g} m"
speed = "0.5 m/s"
""")
    return path


def _loads(scenario_path: Path) -> tuple[Loads, WellModel]:
    scenario = load_scenario_model(scenario_path)
    model = WellModel(scenario.well)
    loads = Loads(scenario, np.full(model.n_elements, 0.26), model)
    assert scenario.model_well is not None
    return loads, WellModel(scenario.model_well)


def test_heavier_mud_scales_every_buoyed_weight(tmp_path: Path) -> None:
    loads, paper = _loads(_scenario(tmp_path, "density_factor = 1.05"))
    assert loads.scenario.well.fluid.density == pytest.approx(1470.0)
    assert paper.well.fluid.density == pytest.approx(1400.0)
    # eq 35 on weights in air: the ratio of buoyancy factors, at any depth
    expected = (1 - 1470.0 / STEEL_DENSITY) / (1 - 1400.0 / STEEL_DENSITY)
    for bit in (1000.0, 2500.0, 3300.0):
        assert loads.weight_factor(paper, bit) == pytest.approx(expected, rel=1e-9)


def test_unfilled_pipe_is_lighter_by_the_missing_fluid(tmp_path: Path) -> None:
    loads, paper = _loads(_scenario(tmp_path, 'fill_level = "300 m"'))
    pipe = paper.well.string.components[-1]
    # eq 36 with nothing inside, by hand: w_air (1 - rho_o A_o / (rho_s A_steel))
    outer, inner = pipe.outer_diameter ** 2, pipe.inner_diameter ** 2
    assert pipe.weight_in_air is not None
    empty = pipe.weight_in_air * (1 - 1400.0 * outer / (STEEL_DENSITY * (outer - inner)))
    full = pipe.weight_in_air * (1 - 1400.0 / STEEL_DENSITY)
    block = paper.well.block_weight
    for bit in (2000.0, 3300.0):
        true_static, _ = loads.model_at(bit).evaluate("static", bit, 0.0)
        modelled, _ = paper.evaluate("static", bit, 0.0)
        # the top 300 m hang vertically: static hook loads differ by 300 m of the difference
        assert modelled - true_static == pytest.approx(300.0 * (full - empty), rel=1e-9)
        assert loads.weight_factor(paper, bit) == pytest.approx(
            (true_static - block) / (modelled - block), rel=1e-12)
    # a bit above the fill level: the whole string in the hole is empty
    string = unfilled_string(paper.well, 200.0, 300.0)
    assert string.length == pytest.approx(paper.well.string.length)
    assert all(c.buoyed_weight is not None for c in string.components)


def test_fill_level_splits_the_component_it_falls_in(tmp_path: Path) -> None:
    _, paper = _loads(_scenario(tmp_path, 'fill_level = "300 m"'))
    # bit at 400 m: the level is 100 m above the bit, inside the 120 m of drill collars
    string = unfilled_string(paper.well, 400.0, 300.0)
    lengths = [c.length for c in string.components]
    assert lengths == pytest.approx([100.0, 20.0, 150.0, 3330.0])
    assert string.components[0].buoyed_weight is None  # full: buoyed with the well's fluid
    assert [c.buoyed_weight is not None for c in string.components[1:]] == [True] * 3


def test_longer_component_weighs_its_extra_length(tmp_path: Path) -> None:
    loads, paper = _loads(_scenario(
        tmp_path, 'string_extra_length = "30 m"\nstring_component = "HWDP"', bit=3630.0))
    assert loads.scenario.well.string.length == pytest.approx(3630.0)
    assert paper.well.string.length == pytest.approx(3600.0)
    hwdp, pipe = paper.well.string.components[1:]
    extra = 30.0 * (hwdp.buoyed_weight_in(1400.0) - pipe.buoyed_weight_in(1400.0))
    # at 3400 m the HWDP's extra 30 m (300-270 m above the bit) lie in the 60 deg tangent
    bit = 3400.0
    true_static, _ = loads.model_at(bit).evaluate("static", bit, 0.0)
    modelled, _ = paper.evaluate("static", bit, 0.0)
    assert true_static - modelled == pytest.approx(extra * math.cos(math.radians(60)), rel=1e-9)


def test_session_records_the_error_and_its_weight_factor(tmp_path: Path) -> None:
    scenario = load_scenario_model(_scenario(
        tmp_path, 'string_extra_length = "30 m"\nstring_component = "HWDP"', bit=3630.0))
    session = simulate_session(scenario)
    factors = session.truth["weight_factor"]
    moving = session.truth["state"] != "in_slips"
    assert np.isfinite(factors[moving]).all() and np.isnan(factors[~moving]).all()
    # the file's string (3600 m) taken to surface at 3630 m: the HWDP's 30 m are missing
    assert factors[moving].min() > 1.005 and factors[moving].max() < 1.007
    messages = session_messages(session)
    [error] = [m for _, topic, m in messages if topic == "/truth/model_error"]
    assert error["string_extra_component"] == "HWDP"
    assert error["true_string_length_m"] == pytest.approx(3630.0)
    assert error["model_string_length_m"] == pytest.approx(3600.0)
    weights = [m for _, topic, m in messages if topic == "/truth/weight"]
    assert len(weights) == int(moving.sum())


def test_without_an_error_nothing_changes(tmp_path: Path) -> None:
    scenario = load_scenario_model(_scenario(tmp_path, ""))
    assert scenario.model_well is None and not scenario.mismatch.any
    session = simulate_session(scenario)
    assert "weight_factor" not in session.truth
    topics = {topic for _, topic, _ in session_messages(session)}
    assert not {"/truth/model_error", "/truth/weight"} & topics


@pytest.mark.parametrize(("model_error", "key", "reason"), [
    ('string_extra_length = "30 m"\nstring_component = "casing"', "model_error.string_component",
     "no string component 'casing'"),
    ('string_component = "HWDP"', "model_error", "string_component needs string_extra_length"),
    ("density_factor = 3.0", "model_error.density_factor", "less than 2"),
])
def test_model_error_mistakes_name_the_key(tmp_path: Path, model_error: str, key: str,
                                           reason: str) -> None:
    with pytest.raises(ConfigError, match=key) as caught:
        load_scenario_model(_scenario(tmp_path, model_error))
    assert reason in str(caught.value)


def test_a_fluid_error_needs_weights_in_air(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="model_error: a fluid error needs the weight in air"):
        load_scenario_model(_scenario(tmp_path, "density_factor = 1.05", well=GLYDRIL,
                                      bit=4000.0))
