"""Live mu(T) calibration: the Glydril slope (0.0013 /K, Kaarstad et al. 2009) recovered within
25 % over a trip from TD on Example 7.1 with a geothermal profile (docs/back-calculation.md), the
identifiability statement, scale mode on a lab fit, and results that feed the model as is."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from tdmon.calib.mu_calibration import (
    MuTCalibrator,
    MuTState,
    family_parametrisation,
    identifiability,
    initial_state,
    scale_parametrisation,
    update,
)
from tdmon.calib.windows import Window
from tdmon.errors import ModelError
from tdmon.model.friction import (
    EVERY_COEFFICIENT,
    FAMILIES,
    KAARSTAD_2009,
    FrictionFamily,
    FrictionModel,
    power,
)
from tdmon.model.torque_drag import WellModel

GLYDRIL = KAARSTAD_2009["glydril"]  # mu = 0.23 + 0.0013 T


@pytest.fixture(scope="module")
def glydril_trip(model_open: WellModel, trip: Any, windows_of: Any,
                 temperatures: Any) -> tuple[np.ndarray, list[Window]]:
    temperature = temperatures(model_open)
    mu = GLYDRIL(temperature)
    session = trip(model_open, mu, start=4200.0, end=1700.0, seed=31)
    _, windows = windows_of(session)
    return temperature, [w for w in windows if w.state == "pick_up" and w.rejected is None]


def test_slope_recovered_within_25_percent(model_open: WellModel,
                                           glydril_trip: tuple[np.ndarray, list[Window]]
                                           ) -> None:
    temperature, windows = glydril_trip
    # a prior that knows nothing about temperature: constant 0.25, slope 0 +/- 0.005
    calibrator = MuTCalibrator(model_open, temperature, FrictionModel("linear",
                               {"a": 0.25, "b": 0.0}), prior_std=[0.1, 0.005])
    used = sum(calibrator.add_window(w) for w in windows)
    assert used >= 60
    params = calibrator.params
    assert params["b"] == pytest.approx(0.0013, rel=0.25)
    assert params["a"] == pytest.approx(0.23, abs=0.03)
    verdict = identifiability(calibrator.parametrisation, calibrator.state)
    assert verdict.identifiable, verdict.reason
    assert verdict.slope_interval[0] > 0.0
    low, high = verdict.temperature_range
    assert high - low > 10.0
    # what the fit returns is what the model takes
    model = FrictionModel("linear", params)
    assert float(model(60.0)) == pytest.approx(params["a"] + 60.0 * params["b"])
    fields = calibrator.message_fields()
    assert fields["identifiable"] is True
    assert all(math.isfinite(float(x)) for x in (fields["mu"], fields["mu_std"]))  # type: ignore[arg-type]


def test_few_windows_at_one_depth_are_not_identifiable(
        model_open: WellModel, glydril_trip: tuple[np.ndarray, list[Window]]) -> None:
    temperature, windows = glydril_trip
    calibrator = MuTCalibrator(model_open, temperature,
                               FrictionModel("linear", {"a": 0.25, "b": 0.0}),
                               prior_std=[0.1, 0.005])
    for window in windows[:3]:
        calibrator.add_window(window)
    verdict = identifiability(calibrator.parametrisation, calibrator.state)
    assert not verdict.identifiable
    assert "narrower" in verdict.reason or "includes zero" in verdict.reason
    assert verdict.temperature_range[1] - verdict.temperature_range[0] < 10.0


def test_scale_on_a_lab_fit(model_open: WellModel,
                            glydril_trip: tuple[np.ndarray, list[Window]]) -> None:
    temperature, windows = glydril_trip
    lab = FrictionModel("linear", {"a": 0.8 * 0.23, "b": 0.8 * 0.0013})  # lab reads 20 % low
    calibrator = MuTCalibrator(model_open, temperature, lab, mode="scale")
    for window in windows[::3]:
        calibrator.add_window(window)
    assert calibrator.params["a"] == pytest.approx(0.23, rel=0.03)
    assert calibrator.state.theta[0] == pytest.approx(1.25, rel=0.03)
    verdict = identifiability(calibrator.parametrisation, calibrator.state)
    assert not verdict.identifiable and "scale mode" in verdict.reason


def test_update_by_hand_and_missing_measurement() -> None:
    parametrisation, theta = family_parametrisation(FrictionModel("linear", {"a": 0.2, "b": 0.0}))
    assert parametrisation.names == ("a", "b")
    state = initial_state(theta, [0.1, 0.01])
    posterior = update(state, 1010.0, 1000.0, np.array([1000.0, 0.0]), 100.0, 40.0)
    # only a is seen: K_a = 0.01 * 1000 / (0.01 * 1e6 + 100)
    gain = 10.0 / 10100.0
    assert posterior.theta[0] == pytest.approx(0.2 + gain * 10.0)
    assert posterior.theta[1] == 0.0
    assert posterior.temperature_min == posterior.temperature_max == 40.0
    assert update(state, math.nan, 1000.0, np.array([1.0, 1.0]), 1.0) is state
    fresh = MuTState(theta, np.eye(2))
    assert not identifiability(parametrisation, fresh).identifiable
    scale, one = scale_parametrisation(GLYDRIL)
    assert scale.names == ("scale",) and one[0] == 1.0
    assert float(scale.mu([2.0], 10.0)) == pytest.approx(2 * (0.23 + 0.013))


@pytest.mark.parametrize("prior", [
    FrictionModel("linear", {"a": 0.23, "b": 0.0013}),
    FrictionModel("exponential", {"a": 0.2, "b": 0.004}),
    FrictionModel("power", {"a": 0.1, "b": 0.3}),
    FrictionModel("constant", {"mu": 0.25}),
    FrictionModel("polynomial", {"a0": 0.2, "a1": 1e-3}),
])
@pytest.mark.parametrize("mode", ["family", "scale"])
@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.parametrize("theta", [
    [1.3, 0.002], [1e308, 1e308], [math.nan, 0.001], [math.inf, -math.inf], [0.5], [0.5, 1, 2],
])
def test_mu_is_the_friction_model_called(prior: FrictionModel, mode: str,
                                         theta: list[float]) -> None:
    # mu evaluates the law without building its FrictionModel: the same bits and errors
    parametrisation = (family_parametrisation(prior) if mode == "family"
                       else scale_parametrisation(prior))[0]
    temperature = np.linspace(-10.0, 120.0, 27)

    def outcome(call: Any) -> object:
        try:
            return np.asarray(call()).tobytes()
        except Exception as exc:  # the errors themselves are compared
            return type(exc), str(exc)

    expected = outcome(lambda: parametrisation.friction_model(theta)(temperature))
    assert outcome(lambda: parametrisation.mu(theta, temperature)) == expected


def _measurement_case_by_case(model: WellModel, parametrisation: Any, theta: np.ndarray,
                              temperature: np.ndarray, operation: str, bit_depth: float,
                              mask: np.ndarray | None, base_mu: Any) -> tuple[Any, ...]:
    """`measurement` as it was written before its cases were built together: each case's
    friction on its own, then stacked (the reference its numbers must equal)."""
    n = model.n_elements
    where = np.ones(n, dtype=bool) if mask is None else mask
    base = np.broadcast_to(np.asarray(base_mu, dtype=np.float64), (n,))

    def friction(law: np.ndarray, extra: Any = 0.0) -> np.ndarray:
        return np.maximum(np.where(where, law + extra, base), 0.0)

    at_theta = parametrisation.mu(theta, temperature)
    cases = [friction(at_theta)]
    steps = np.empty(theta.size)
    for k in range(theta.size):
        steps[k] = max(abs(theta[k]) * 1e-3, 1e-6)
        bumped = theta.copy()
        bumped[k] += steps[k]
        cases.append(friction(parametrisation.mu(bumped, temperature)))
    scale = max(float(np.max(np.abs(temperature))), 1.0)
    cases.append(friction(at_theta, 1e-3))
    cases.append(friction(at_theta, 1e-3 * temperature / scale))
    values = model.evaluate_cases(operation, bit_depth, np.stack(cases))[0]
    predicted = float(values[0])
    jacobian = (values[1:theta.size + 1] - predicted) / steps
    uniform, weighted = float(values[-2]) - predicted, float(values[-1]) - predicted
    return predicted, jacobian.tobytes(), (weighted / uniform * scale if uniform != 0.0
                                           else math.nan)


@pytest.mark.parametrize("prior", [GLYDRIL, FrictionModel("polynomial", {"a0": 0.3, "a2": -1e-5}),
                                   FrictionModel("exponential", {"a": 0.2, "b": 0.004})])
@pytest.mark.parametrize("mode", ["family", "scale"])
@pytest.mark.parametrize("masked", [False, True])
def test_measurement_cases_are_those_built_one_by_one(model_open: WellModel,
                                                       prior: FrictionModel, mode: str,
                                                       masked: bool) -> None:
    from tdmon.calib.mu_calibration import measurement

    parametrisation, theta = (family_parametrisation(prior) if mode == "family"
                              else scale_parametrisation(prior))
    rng = np.random.default_rng(7)
    n = model_open.n_elements
    # temperatures where the law goes negative too (friction clipped at 0), -0.0 included
    temperature = np.linspace(-40.0, 150.0, n)
    mask = rng.random(n) < 0.6 if masked else None
    for base_mu in (0.0, -0.0, 0.21, rng.uniform(0.0, 0.4, n)):
        for scale in (1.0, -3.0, 1e-9):
            for depth in (1500.0, 4000.0):
                args = (model_open, parametrisation, theta * scale, temperature, "pick_up",
                        depth)
                predicted, jacobian, effective = measurement(*args, mask=mask,
                                                             base_mu=base_mu)
                expected = _measurement_case_by_case(*args, mask, base_mu)
                assert (predicted, jacobian.tobytes()) == expected[:2]
                assert effective == expected[2] or (math.isnan(effective)
                                                    and math.isnan(expected[2]))


#: a law of each family, T in degC
_LAWS = [("constant", {"mu": 0.3}), ("linear", {"a": 0.23, "b": 0.0013}),
         ("power", {"a": 0.17, "b": 0.14}), ("exponential", {"a": 0.25, "b": 0.003}),
         ("saturation-growth", {"a": 0.34, "b": 7.0}),
         ("polynomial", {"a0": 0.25, "a1": 0.001, "a2": -1e-6})]


def test_every_family_declares_what_scale_mode_scales() -> None:
    assert sorted(FAMILIES) == sorted(name for name, _ in _LAWS)
    temperature = np.array([5.0, 40.0, 95.0])
    for family, coefficients in _LAWS:
        scale, _ = scale_parametrisation(FrictionModel(family, coefficients))
        # s mu_lab(T): the declared coefficients multiplied, the others (an exponent, a
        # half-saturation temperature) as they are
        expected = 1.3 * FrictionModel(family, coefficients)(temperature)
        np.testing.assert_allclose(scale.mu([1.3], temperature), expected, rtol=1e-12)
        law = scale.friction_model([1.3])
        kept = {k for k, v in coefficients.items() if law.coefficients[k] == v}
        assert kept == {"power": {"b"}, "exponential": {"b"},
                        "saturation-growth": {"b"}}.get(family, set()), family


def test_a_family_without_its_scaled_coefficients_is_an_error() -> None:
    with pytest.raises(TypeError, match="scaled"):
        FrictionFamily(power)  # type: ignore[call-arg]
    with pytest.raises(ModelError, match="must be some of a, b"):
        FrictionFamily(power, scaled=("c",))
    with pytest.raises(ModelError, match="must be some of a, b"):
        FrictionFamily(power, scaled=())
    assert FrictionFamily(power, scaled=EVERY_COEFFICIENT).scale({"a": 0.2, "b": 0.1}, 2.0) == {
        "a": 0.4, "b": 0.2}
    assert FAMILIES["power"].scale({"a": 0.2, "b": 0.1}, 2.0) == {"a": 0.4, "b": 0.1}
    assert FAMILIES["power"](10.0, a=0.2, b=0.1) == power(10.0, 0.2, 0.1)  # callable as before
