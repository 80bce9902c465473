"""Adjoint gradient of the torque-and-drag march with respect to per-element friction: by hand
on a straight hole, against central differences of `WellModel.evaluate` on Example 7.1 and a
3D well for every operation and quantity of both methods, one-sided at mu = 0, determinism."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from tdmon.errors import ModelError
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.survey import minimum_curvature
from tdmon.model.torque_drag import Operation, WellModel
from tdmon.model.well import Fluid, HoleSection, Well

# (operation, quantity index, keyword arguments): every operation with both quantities, and
# combined motion (pick-up and slack-off while rotating), where both quantities carry friction
CASES: list[tuple[str, int, dict[str, float]]] = [
    *((op.value, q, {"wob": 60e3, "bit_torque": 4e3} if op is Operation.ON_BOTTOM else {})
      for op in Operation for q in (0, 1)),
    *(("pick_up", q, {"psi": 0.6}) for q in (0, 1)),
    *(("slack_off", q, {"psi": 0.6}) for q in (0, 1)),
]
CASE_IDS = [f"{op}-{'torque' if q else 'hookload'}{'-psi' if 'psi' in kw else ''}"
            for op, q, kw in CASES]

# Central differences of step 1e-5 on values of ~1e6 N: truncation ~ h^2 |q'''| is ~1e-10 of
# the gradient, rounding ~ eps |q| / h ~ 1e-5 N against gradients of 1e3-1e4 N; the adjoint
# agrees to ~1e-8 of the largest element gradient, 1e-6 leaves room for the rounding.
STEP = 1e-5
RELATIVE_TOLERANCE = 1e-6


def _central_differences(model: WellModel, operation: str, depth: float, mu: np.ndarray,
                         quantity: int, method: str, **kwargs: Any) -> np.ndarray:
    """d value / d mu_e by central differences, for every element the string reaches."""
    gradient = np.zeros(model.n_elements)
    for e in np.flatnonzero(model.node_md[:-1] < depth):
        up, down = mu.copy(), mu.copy()
        up[e] += STEP
        down[e] -= STEP
        high = model.evaluate(operation, depth, up, method=method, **kwargs)[quantity]
        low = model.evaluate(operation, depth, down, method=method, **kwargs)[quantity]
        gradient[e] = (high - low) / (2.0 * STEP)
    return gradient


def _random_friction(model: WellModel, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0.1, 0.4, model.n_elements)


@pytest.fixture(scope="module")
def model_71(example_71: Well) -> WellModel:
    return WellModel(example_71)


@pytest.fixture(scope="module")
def model_3d(three_d: Well) -> WellModel:
    return WellModel(three_d)


# --- by hand ------------------------------------------------------------------------------


def test_straight_inclined_hole_by_hand() -> None:
    # A straight hole at 40 deg: no bend, so N = w dL sin a on every piece and the hook load is
    # sum(w dL (cos a +/- mu sin a)): d/dmu_e = +/- w dL_e sin a, torque d/dmu_e = w dL_e r sin a,
    # whatever the friction elsewhere.
    inclination = math.radians(40.0)
    weight, depth = 300.0, 1234.5
    well = Well(
        survey=minimum_curvature([0.0, 2000.0], [40.0, 40.0], [0.0, 0.0]),
        string=DrillString((StringComponent("pipe", 2000.0, outer_diameter=0.127,
                                            inner_diameter=0.108, buoyed_weight=weight),)),
        sections=(HoleSection(0.0, 2000.0, 0.2159, "open", friction=0.2),),
        fluid=Fluid(density=1200.0),
        element_length=10.0,
    )
    model = WellModel(well)
    radius = well.string.components[0].torque_radius
    mu = _random_friction(model, 3)
    reached = np.clip(np.minimum(model.node_md[1:], depth) - model.node_md[:-1], 0.0, None)
    per_length = weight * math.sin(inclination)
    _, pick_up = model.evaluate_gradient("pick_up", depth, mu)
    _, slack_off = model.evaluate_gradient("slack_off", depth, mu)
    _, torque = model.evaluate_gradient("rotating", depth, mu, quantity_index=1)
    assert pick_up == pytest.approx(per_length * reached, rel=1e-12, abs=1e-9)
    assert slack_off == pytest.approx(-per_length * reached, rel=1e-12, abs=1e-9)
    assert torque == pytest.approx(per_length * radius * reached, rel=1e-12, abs=1e-9)


# --- against central differences ----------------------------------------------------------


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
@pytest.mark.parametrize(("operation", "quantity", "kwargs"), CASES, ids=CASE_IDS)
@pytest.mark.parametrize("well", ["example 7.1", "3D"])
def test_gradient_matches_central_differences(
    model_71: WellModel, model_3d: WellModel, well: str, method: str, operation: str,
    quantity: int, kwargs: dict[str, float],
) -> None:
    # Example 7.1: bit 3.3 m above TD, so the bit and the BHA top split elements; the 3D well
    # (build, hold, turn across north, drop, cased/open): bit in the drop section
    model, depth = (model_71, model_71.node_md[-1] - 3.3) if well == "example 7.1" else (
        model_3d, 3456.7)
    mu = _random_friction(model, 11)
    value, gradient = model.evaluate_gradient(operation, depth, mu, quantity_index=quantity,
                                              method=method, **kwargs)
    assert value == model.evaluate(operation, depth, mu, method=method, **kwargs)[quantity]
    expected = _central_differences(model, operation, depth, mu, quantity, method, **kwargs)
    scale = float(np.abs(expected).max())
    if scale == 0.0:  # no friction in this quantity (static, rotating hook load, ...)
        assert np.all(gradient == 0.0)
    else:
        assert np.abs(gradient - expected).max() <= RELATIVE_TOLERANCE * scale
    assert np.all(gradient[model.node_md[:-1] >= depth] == 0.0)  # below the bit


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
@pytest.mark.parametrize("depth", [1300.0, 1750.0, 2600.0])
def test_gradient_at_shallower_bits(model_3d: WellModel, method: str, depth: float) -> None:
    # vertical, in the turn, in the drop: the bit and the BHA top at other places; on bottom
    # the BHA is in compression
    mu = _random_friction(model_3d, 5)
    on_bottom = {"wob": 120e3, "bit_torque": 4e3}
    for operation, quantity, kwargs in (("pick_up", 0, {}), ("slack_off", 0, {}),
                                        ("rotating", 1, {}), ("on_bottom", 1, on_bottom)):
        _, gradient = model_3d.evaluate_gradient(operation, depth, mu, quantity_index=quantity,
                                                 method=method, **kwargs)
        expected = _central_differences(model_3d, operation, depth, mu, quantity, method,
                                        **kwargs)
        scale = float(np.abs(expected).max())
        assert np.abs(gradient - expected).max() <= RELATIVE_TOLERANCE * scale


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
@pytest.mark.parametrize(("operation", "quantity"),
                         [("pick_up", 0), ("slack_off", 0), ("rotating", 1)])
def test_gradient_at_zero_friction_is_the_one_sided_derivative(
    model_71: WellModel, method: str, operation: str, quantity: int,
) -> None:
    # friction cannot go below 0: the derivative there is the one friction moves into (for
    # Aadnoy's build, that of the pick-up or slack-off formula, which meet at mu = 0)
    depth = model_71.node_md[-1]
    mu = np.zeros(model_71.n_elements)
    value, gradient = model_71.evaluate_gradient(operation, depth, mu, quantity_index=quantity,
                                                 method=method)
    step = 1e-6
    reached = np.flatnonzero(model_71.node_md[:-1] < depth)
    forward = np.zeros(model_71.n_elements)
    for e in reached:
        bumped = mu.copy()
        bumped[e] = step
        forward[e] = (model_71.evaluate(operation, depth, bumped, method=method)[quantity]
                      - value) / step
    # forward differences: error ~ step |q''| / 2, ~1e-6 of the gradient here
    assert np.abs(gradient - forward).max() <= 1e-5 * np.abs(forward).max()


def test_gradient_in_compression() -> None:
    # Reaming down (slack-off while rotating) a 700 m tangent at 85 deg puts the string above it
    # in compression in a turn: the soft string's contact force changes sides and Aadnoy's 2010
    # torque takes |F1|, with F1 depending on the friction below
    well = Well(
        survey=minimum_curvature([0.0, 500.0, 1500.0, 1800.0, 2500.0],
                                 [0.0, 0.0, 85.0, 85.0, 85.0], [0.0, 0.0, 0.0, 40.0, 40.0]),
        string=DrillString((StringComponent("pipe", 2500.0, outer_diameter=0.127,
                                            inner_diameter=0.108, buoyed_weight=250.0),)),
        sections=(HoleSection(0.0, 2500.0, 0.2159, "open", friction=0.3),),
        fluid=Fluid(density=1200.0),
        element_length=10.0,
    )
    model = WellModel(well)
    mu = _random_friction(model, 8)
    depth, kwargs = 2495.0, {"psi": 1.2}
    for method in ("soft-string", "aadnoy"):
        md, force, _, _ = model.profiles(["slack_off"], depth, mu, method=method, **kwargs)
        in_turn = (md > 1500.0) & (md < 1800.0)
        assert force[0][in_turn].min() < -10e3, method
        for quantity in (0, 1):
            _, gradient = model.evaluate_gradient("slack_off", depth, mu, method=method,
                                                  quantity_index=quantity, **kwargs)
            expected = _central_differences(model, "slack_off", depth, mu, quantity, method,
                                            **kwargs)
            scale = float(np.abs(expected).max())
            assert np.abs(gradient - expected).max() <= RELATIVE_TOLERANCE * scale


# --- properties ---------------------------------------------------------------------------


def test_gradient_is_deterministic_and_sums_to_the_uniform_derivative(
    model_3d: WellModel,
) -> None:
    first = model_3d.evaluate_gradient("pick_up", 3456.7, 0.25)
    second = model_3d.evaluate_gradient("pick_up", 3456.7, 0.25)
    assert first[0] == second[0]
    assert np.array_equal(first[1], second[1])
    h = 1e-5
    uniform = (model_3d.evaluate("pick_up", 3456.7, 0.25 + h)[0]
               - model_3d.evaluate("pick_up", 3456.7, 0.25 - h)[0]) / (2 * h)
    assert first[1].sum() == pytest.approx(uniform, rel=1e-7)


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
def test_value_is_evaluate_s_at_every_depth(model_3d: WellModel, method: str) -> None:
    # the gradient kernel repeats the march's loop: same pieces, same runs, same numbers, with
    # the bit between nodes, on nodes and on survey stations
    mu = _random_friction(model_3d, 13)
    depths = np.concatenate([np.linspace(15.0, 3600.0, 61), model_3d.node_md[1::37], [2100.0]])
    for depth in depths:
        for operation, quantity, kwargs in CASES:
            value, _ = model_3d.evaluate_gradient(operation, depth, mu, quantity_index=quantity,
                                                  method=method, **kwargs)
            assert value == model_3d.evaluate(operation, depth, mu, method=method,
                                              **kwargs)[quantity]


def test_gradient_takes_friction_like_evaluate(model_3d: WellModel) -> None:
    # None (the sections', 0.2 cased and 0.3 open) and the equivalent array agree
    sections = model_3d.friction(None)
    from_sections = model_3d.evaluate_gradient("slack_off", 3000.0)
    from_array = model_3d.evaluate_gradient("slack_off", 3000.0, sections.copy())
    assert from_sections[0] == from_array[0]
    assert np.array_equal(from_sections[1], from_array[1])
    assert from_sections[1].shape == (model_3d.n_elements,)


def test_gradient_bad_inputs_are_errors(model_71: WellModel) -> None:
    with pytest.raises(ModelError, match="quantity index"):
        model_71.evaluate_gradient("pick_up", 3000.0, 0.2, quantity_index=2)
    with pytest.raises(ModelError, match="unknown torque-and-drag method"):
        model_71.evaluate_gradient("pick_up", 3000.0, 0.2, method="stiff")
    with pytest.raises(ModelError, match="deeper than the drill string"):
        model_71.evaluate_gradient("pick_up", 9000.0, 0.2)
    with pytest.raises(ModelError, match=">= 0"):
        model_71.evaluate_gradient("pick_up", 3000.0, -0.1)
