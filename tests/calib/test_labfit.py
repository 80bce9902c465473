"""Tests of tdmon.calib.labfit on the thesis's Glydril tribometer data (Tables 14-16)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from tdmon.calib.labfit import (
    confidence_band,
    fit_friction,
    fit_friction_models,
    temperature_averages,
    tribometer_from_table,
)
from tdmon.errors import FitError
from tdmon.model.friction import FrictionModel

TEMPERATURES = np.array([30.0, 40.0, 50.0, 60.0, 70.0])
# the "Average" row of Table 14 as printed (0.283 is printed "0,.283")
PRINTED_AVERAGES = np.array([0.279, 0.287, 0.283, 0.3185, 0.306])

# Table 14 typed in independently of the CSV (None = the failed run, test 1 at 60 degC)
TABLE_14: dict[int, list[float | None]] = {
    30: [0.372, 0.256, 0.132, 0.18, 0.409, 0.314, 0.301],
    40: [0.225, 0.314, 0.291, 0.337, 0.254, 0.327, 0.272],
    50: [0.285, 0.283, 0.245, 0.304, 0.277, 0.271, 0.316],
    60: [None, 0.183, 0.214, 0.409, 0.359, 0.401, 0.345],
    70: [0.3, 0.215, 0.272, 0.287, 0.389, 0.366, 0.313],
}


def table_14_rows() -> list[tuple[int, float, float | None]]:
    """Table 14 as (test, temperature, friction) rows in the order of data/lab's CSV file."""
    return [(test, float(t), mu) for t, runs in TABLE_14.items()
            for test, mu in enumerate(runs, start=1)]


@pytest.fixture(scope="module")
def lab() -> tuple[np.ndarray, np.ndarray]:
    data = tribometer_from_table(table_14_rows(),
                                 ["test", "temperature_C", "friction_coefficient"])
    return data.temperature, data.friction


# --------------------------------------------------------------------------- rows

def test_table_14_rows_drop_and_count_the_failed_run() -> None:
    data = tribometer_from_table(table_14_rows(),
                                 ["test", "temperature_C", "friction_coefficient"])
    assert data.failed_runs == 1
    assert data.friction.size == 34
    assert data.friction[:3].tolist() == [0.372, 0.256, 0.132]
    assert set(data.test) == set(range(1, 8))


def test_true_means_differ_from_printed_averages(lab: tuple[np.ndarray, np.ndarray]) -> None:
    levels, means, counts = temperature_averages(*lab)
    assert levels == pytest.approx(TEMPERATURES)
    assert counts.tolist() == [7, 7, 7, 6, 7]
    # docs/lab-fit.md (Table 14 errata): the means at 30 and 40 degC are 0.2806 and 0.2886,
    # printed 0.279 and 0.287; 50, 60, 70 agree with the print
    assert means == pytest.approx([0.2806, 0.2886, 0.283, 0.3185, 0.306], abs=5e-5)


def test_table_rows_without_the_csv() -> None:
    data = tribometer_from_table([(1, "30", "0.3"), (2, 30, None), (3, 40.0, 0.25)],
                                 ["test", "temperature_C", "friction_coefficient"])
    assert data.failed_runs == 1
    assert data.friction.tolist() == [0.3, 0.25]
    with pytest.raises(FitError, match="data row 1: 'temperature_C' is not finite"):
        tribometer_from_table([(1, "nan", "0.3")], ["test", "temperature_C",
                                                    "friction_coefficient"])
    with pytest.raises(FitError, match="data row 1: 'temperature_C' is empty"):
        tribometer_from_table([(1, "", "0.3")], ["test", "temperature_C",
                                                 "friction_coefficient"])


# --------------------------------------------------------------------------- the thesis's numbers

def test_linear_fit_on_printed_averages() -> None:
    fit = fit_friction(TEMPERATURES, PRINTED_AVERAGES, "linear", data="averages")
    # docs/lab-fit.md: 0.25195 + 0.000855 T, R^2 0.643, adjusted 0.524, SE 0.0116
    # (by hand: slope = sum(dT dmu)/sum(dT^2) = 0.855/1000; intercept = 0.29470 - 50 b)
    assert fit.coefficients["a"] == pytest.approx(0.25195, abs=1e-6)
    assert fit.coefficients["b"] == pytest.approx(0.000855, abs=1e-9)
    assert fit.r2 == pytest.approx(0.643, abs=5e-4)
    assert fit.adj_r2 == pytest.approx(0.524, abs=5e-4)
    assert fit.stderr == pytest.approx(0.0116, abs=5e-5)
    # Table 16 (linear): R 0.79947, R^2 0.63915, adj 0.51886, SE 0.01164 -- not reproducible
    # from either set of averages; the standard error agrees to 1e-5
    assert fit.stderr == pytest.approx(0.01164, abs=2e-5)
    assert fit.data == "averages"
    # even on five averages the slope is not significant at 95 % (p = 0.10)
    assert fit.temperature_significant is False
    assert fit.p_values["b"] == pytest.approx(0.103, abs=1e-3)


def test_linear_fit_on_true_means(lab: tuple[np.ndarray, np.ndarray]) -> None:
    levels, means, _ = temperature_averages(*lab)
    fit = fit_friction(levels, means, "linear", data="averages")
    # docs/lab-fit.md: 0.25494 + 0.000808 T, R^2 0.612
    assert fit.coefficients["a"] == pytest.approx(0.25494, abs=1e-5)
    assert fit.coefficients["b"] == pytest.approx(0.000808, abs=1e-6)
    assert fit.r2 == pytest.approx(0.612, abs=5e-4)


def test_linear_fit_on_raw_values_says_not_significant(
        lab: tuple[np.ndarray, np.ndarray]) -> None:
    fit = fit_friction(*lab, "linear")
    assert fit.n == 34
    # docs/lab-fit.md: R^2 = 0.03 on the 34 raw values
    assert fit.r2 == pytest.approx(0.029, abs=1e-3)
    interval = fit.confidence_intervals["b"]
    assert interval is not None
    assert interval[0] < 0.0 < interval[1]
    assert fit.temperature_significant is False
    assert "NOT significant" in fit.verdict and "includes zero" in fit.verdict
    # the slope's uncertainty is as large as the slope itself
    error = fit.standard_errors["b"]
    assert error is not None and error > fit.coefficients["b"] * 0.9


def test_linear_statistics_against_scipy_linregress(
        lab: tuple[np.ndarray, np.ndarray]) -> None:
    # independent implementation: scipy.stats.linregress
    reference = stats.linregress(*lab)
    fit = fit_friction(*lab, "linear")
    assert fit.coefficients["b"] == pytest.approx(reference.slope, rel=1e-10)
    assert fit.coefficients["a"] == pytest.approx(reference.intercept, rel=1e-10)
    assert fit.standard_errors["b"] == pytest.approx(reference.stderr, rel=1e-8)
    assert fit.standard_errors["a"] == pytest.approx(reference.intercept_stderr, rel=1e-8)
    assert fit.r == pytest.approx(abs(reference.rvalue), rel=1e-10)
    assert fit.p_values["b"] == pytest.approx(reference.pvalue, rel=1e-8)


def test_polynomials_compared_with_table_16() -> None:
    poly2 = fit_friction(TEMPERATURES, PRINTED_AVERAGES, "poly-2", data="averages")
    poly3 = fit_friction(TEMPERATURES, PRINTED_AVERAGES, "poly-3", data="averages")
    # Table 16: poly-2 R^2 0.63908, adj 0.27815, SE 0.01426; poly-3 R^2 0.75808,
    # adj 0.03232, SE 0.01651. On the printed averages (docs/lab-fit.md):
    assert poly2.r2 == pytest.approx(0.6432, abs=1e-4)
    assert poly2.stderr == pytest.approx(0.01426, abs=2e-5)
    assert poly3.r2 == pytest.approx(0.7572, abs=1e-4)
    assert poly3.r2 == pytest.approx(0.75808, abs=2e-3)
    assert poly3.adj_r2 == pytest.approx(0.0288, abs=1e-4)
    assert poly3.stderr == pytest.approx(0.01651, abs=2e-4)
    # eq. 23 prints the cubic coefficient -4.42857e-7, a copy of eq. 22's quadratic one; the
    # least-squares cubic coefficient is -3.0e-6 (the other three match eq. 23 to ~2 %)
    assert poly3.coefficients["a3"] == pytest.approx(-3.0e-6, rel=1e-6)
    assert poly3.coefficients["a0"] == pytest.approx(0.58088, rel=0.02)
    assert poly3.coefficients["a1"] == pytest.approx(-0.02096, rel=0.03)
    assert poly3.coefficients["a2"] == pytest.approx(0.00046, rel=0.03)
    assert poly2.temperature_significant is False and poly3.temperature_significant is False


# --------------------------------------------------------------------------- hand values

def test_aicc_and_loo_by_hand() -> None:
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    mu = np.array([0.20, 0.22, 0.23, 0.27, 0.28, 0.31])
    fit = fit_friction(t, mu, "linear")
    sse = float(fit.residuals @ fit.residuals)
    n, k = 6, 3
    assert fit.aicc == pytest.approx(n * math.log(sse / n) + 2 * k + 2 * k * (k + 1) / (n - k - 1))
    # leave-one-out for least squares: e_i / (1 - h_ii), h the hat matrix
    design = np.column_stack((np.ones(n), t))
    hat = design @ np.linalg.inv(design.T @ design) @ design.T
    loo = fit.residuals / (1.0 - np.diag(hat))
    assert fit.loo_rmse == pytest.approx(float(np.sqrt(np.mean(loo**2))), rel=1e-10)
    assert fit.temperature_significant is True
    assert "is significant" in fit.verdict


@pytest.mark.parametrize(
    ("model", "coefficients"),
    [
        ("exponential", {"a": 0.25, "b": 0.003}),
        ("power", {"a": 0.17, "b": 0.14}),
        ("saturation-growth", {"a": 0.34, "b": 7.0}),
    ],
)
def test_nonlinear_fit_recovers_exact_parameters(model: str,
                                                 coefficients: dict[str, float]) -> None:
    t = np.linspace(20.0, 90.0, 8)
    law = FrictionModel(model, coefficients)
    fit = fit_friction(t, law(t), model)
    assert fit.coefficients == pytest.approx(coefficients, rel=1e-6)
    assert fit.r2 == pytest.approx(1.0, abs=1e-9)
    # the fit is the model's own argument set: FrictionModel(family, coefficients) works
    assert fit.friction_model()(t) == pytest.approx(law(t), rel=1e-6)


def test_fit_output_feeds_friction_model_as_is(lab: tuple[np.ndarray, np.ndarray]) -> None:
    for fit in fit_friction_models(*lab):
        model = FrictionModel(fit.family, fit.coefficients)
        assert model(lab[0]) == pytest.approx(lab[1] - fit.residuals, abs=1e-12)


# --------------------------------------------------------------------------- ranking, output

def test_ranking_and_json(lab: tuple[np.ndarray, np.ndarray]) -> None:
    fits = fit_friction_models(TEMPERATURES, PRINTED_AVERAGES, data="averages")
    assert [fit.rank for fit in fits] == list(range(1, len(fits) + 1))
    assert fits[0].model == "linear"  # lowest AICc on the five averages
    ranked = [fit.aicc for fit in fits if fit.aicc is not None]
    assert ranked == sorted(ranked)
    # poly-2 and poly-3 have no AICc on five points (k + 1 >= n) and rank last
    assert {fit.model for fit in fits[-2:]} == {"poly-2", "poly-3"}
    text = json.dumps([fit.to_dict() for fit in fits], allow_nan=False)
    assert '"data": "averages"' in text
    raw = fit_friction_models(*lab)
    assert all(fit.temperature_significant is False for fit in raw)


def test_arrays_versus_scalars_shapes() -> None:
    column = fit_friction(TEMPERATURES.reshape(5, 1), PRINTED_AVERAGES.reshape(5, 1))
    flat = fit_friction(list(TEMPERATURES), list(PRINTED_AVERAGES))
    assert column.coefficients == pytest.approx(flat.coefficients)


# --------------------------------------------------------------------------- failures

def test_non_converging_fit_raises_fit_error_with_scipy_message() -> None:
    with pytest.raises(FitError, match=r"exponential fit did not converge: .*maxfev"):
        fit_friction(TEMPERATURES, PRINTED_AVERAGES, "exponential", max_evaluations=1)


def test_too_few_points_and_bad_models() -> None:
    with pytest.raises(FitError, match="4 coefficients but only 3 points"):
        fit_friction([30.0, 40.0, 50.0], [0.2, 0.3, 0.25], "poly-3")
    with pytest.raises(FitError, match="two distinct temperatures"):
        fit_friction([30.0, 30.0, 30.0], [0.2, 0.3, 0.25])
    with pytest.raises(FitError, match="unknown friction model"):
        fit_friction(TEMPERATURES, PRINTED_AVERAGES, "spline")
    with pytest.raises(FitError, match="finite"):
        fit_friction([30.0, float("nan")], [0.2, 0.3])
    with pytest.raises(FitError, match="5 temperatures but 4"):
        fit_friction(TEMPERATURES, PRINTED_AVERAGES[:4])
    with pytest.raises(FitError, match="all friction values are equal"):
        fit_friction(TEMPERATURES, np.full(5, 0.3))
    with pytest.raises(FitError, match="above 0 degC"):
        fit_friction([0.0, 20.0, 40.0], [0.2, 0.25, 0.3], "power")
    with pytest.raises(FitError, match="none of the models"):
        fit_friction_models([30.0, 40.0], [0.2, 0.3], models=["poly-3"])


def test_confidence_band_of_a_line_at_the_mean_temperature(
        lab: tuple[np.ndarray, np.ndarray]) -> None:
    # For a straight line, x0' (X'X)^-1 x0 = 1/n at the mean of the fitted temperatures, so the
    # band's half-width there is t(0.975, n - 2) s / sqrt(n) (hand formula, no matrix algebra).
    temperature, friction = lab
    fit = fit_friction(temperature, friction, "linear", data="raw")
    assert fit.stderr is not None
    centre = float(np.mean(temperature))
    band = confidence_band(fit, temperature, [centre, 30.0, 70.0])
    assert band is not None
    expected = stats.t.ppf(0.975, temperature.size - 2) * fit.stderr / np.sqrt(temperature.size)
    assert band[0] == pytest.approx(expected, rel=1e-9)
    assert band[1] > band[0] and band[2] > band[0]  # wider away from the data's centre
    nonlinear = fit_friction(temperature, friction, "exponential", data="raw")
    assert confidence_band(nonlinear, temperature, [centre]) is None
