"""Fit mu(T) laws to tribometer (pin-on-disk) friction measurements.

The fit returns coefficients keyed like the friction family's own arguments, so
``FrictionModel(fit.family, fit.coefficients)`` is the fitted law, with the statistics needed
to judge it: standard errors, 95 % confidence intervals, R, R^2, adjusted R^2, the standard
error of the regression, AICc, leave-one-out RMSE, a ranking, and a plain statement whether the
temperature effect is significant at all.

Linear-in-parameters families (linear, polynomial) are ordinary least squares; the others
(power, exponential, saturation growth) use :func:`scipy.optimize.curve_fit`, started from a
linearised fit, with Wald intervals from the covariance and Student's t.

Pure: the data come in as rows (:func:`tribometer_from_table`); reading a tribometer CSV file
is :func:`tdmon.ingest.lab.read_tribometer_csv`.

References
----------
.. [1] Thesis "Torque and Drag Friction Model: Implemented Friction Factor Dependency of
   Temperature" (University of Stavanger), section 3.4 (Tables 14-16, eq. 17-23).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize, stats

from tdmon.errors import FitError, TdmonError
from tdmon.model.friction import FAMILIES, FrictionModel

__all__ = [
    "DEFAULT_MODELS",
    "MODELS",
    "FrictionFit",
    "TribometerData",
    "fit_friction",
    "fit_friction_models",
    "temperature_averages",
    "tribometer_from_table",
]

Array = NDArray[np.float64]
DataKind = Literal["raw", "averages"]

MODELS: tuple[str, ...] = ("linear", "poly-2", "poly-3", "power", "exponential",
                           "saturation-growth")
"""Model names :func:`fit_friction` accepts; "poly-m" is the degree-m polynomial."""

DEFAULT_MODELS: tuple[str, ...] = ("linear", "poly-2", "poly-3", "exponential", "power",
                                   "saturation-growth")

_CONFIDENCE = 0.95


@dataclass(frozen=True)
class TribometerData:
    """Friction measurements at controlled temperatures.

    Attributes
    ----------
    temperature : ndarray
        Fluid temperature of each successful run [degC].
    friction : ndarray
        Measured friction coefficient of each successful run [-].
    test : ndarray
        Test (material sample) number of each successful run.
    failed_runs : int
        Runs with an empty friction value, dropped.
    """

    temperature: Array
    friction: Array
    test: NDArray[np.int64]
    failed_runs: int


@dataclass(frozen=True)
class FrictionFit:
    """One mu(T) law fitted to data, with its statistics.

    Attributes
    ----------
    model : str
        Model name ("linear", "poly-2", "exponential", ...).
    family : str
        The :class:`~tdmon.model.friction.FrictionModel` family ("polynomial" for "poly-m").
    data : {"raw", "averages"}
        Fitted to the individual runs or to per-temperature averages.
    coefficients : dict
        Estimates keyed like the family's arguments (a, b or a0, a1, ...).
    standard_errors : dict
        Standard error of each coefficient.
    confidence_intervals : dict
        95 % interval (low, high) of each coefficient (Student's t, n - p degrees of freedom).
    p_values : dict
        Two-sided p-value of each coefficient against zero.
    n : int
        Number of points.
    n_parameters : int
        Number of fitted coefficients p.
    r, r2, adj_r2 : float
        sqrt(R^2), R^2 = 1 - SSE/SST (eq. 19 in [1]), adjusted R^2 = 1 - (1 - R^2)(n-1)/(n-p)
        (eq. 20 in [1] with p counting the intercept).
    stderr : float or None
        Standard error of the regression sqrt(SSE/(n - p)); None when n = p.
    aicc : float or None
        Corrected Akaike criterion n ln(SSE/n) + 2k + 2k(k+1)/(n-k-1), k = p + 1 (the variance
        counts); None when n - k - 1 <= 0.
    loo_rmse : float or None
        Leave-one-out root-mean-square prediction error; None when a point cannot be left out.
    temperature_significant : bool or None
        Whether the temperature effect differs from zero at the 95 % level (None if the test
        has no degrees of freedom).
    verdict : str
        A sentence saying so, with the numbers.
    rank : int
        1 = best by AICc (then adjusted R^2) among the fits it was ranked with; 0 = not ranked.
    """

    model: str
    family: str
    data: DataKind
    coefficients: dict[str, float]
    standard_errors: dict[str, float | None]
    confidence_intervals: dict[str, tuple[float, float] | None]
    p_values: dict[str, float | None]
    n: int
    n_parameters: int
    r: float
    r2: float
    adj_r2: float | None
    stderr: float | None
    aicc: float | None
    loo_rmse: float | None
    temperature_significant: bool | None
    verdict: str
    rank: int = 0
    residuals: Array = field(default_factory=lambda: np.empty(0), repr=False)

    def friction_model(self) -> FrictionModel:
        """The fitted law as a :class:`~tdmon.model.friction.FrictionModel`."""
        return FrictionModel(self.family, self.coefficients)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready summary (no NaN or infinity; undefined statistics are None)."""
        return {
            "model": self.model, "family": self.family, "data": self.data,
            "coefficients": dict(self.coefficients),
            "standard_errors": dict(self.standard_errors),
            "confidence_intervals": {k: list(v) if v else None
                                     for k, v in self.confidence_intervals.items()},
            "p_values": dict(self.p_values), "n": self.n, "n_parameters": self.n_parameters,
            "r": self.r, "r2": self.r2, "adj_r2": self.adj_r2, "stderr": self.stderr,
            "aicc": self.aicc, "loo_rmse": self.loo_rmse,
            "temperature_significant": self.temperature_significant, "verdict": self.verdict,
            "rank": self.rank,
        }


# ---------------------------------------------------------------------------- data handling

def tribometer_from_table(rows: Iterable[Sequence[object]],
                          header: Sequence[str]) -> TribometerData:
    """Validate tribometer rows (test, temperature_C, friction_coefficient) into arrays.

    Parameters
    ----------
    rows : sequence of rows
        Cell values as read (strings, numbers or None); an empty friction cell is a failed run.
    header : sequence of str
        Column names; must contain ``temperature_C`` and ``friction_coefficient`` (``test``
        optional).

    Returns
    -------
    TribometerData

    Raises
    ------
    FitError
        A missing column, a non-numeric or non-finite value (naming the data row, 1-based), a
        missing temperature.
    """
    columns = [str(name).strip() for name in header]
    for needed in ("temperature_C", "friction_coefficient"):
        if needed not in columns:
            raise FitError(f"tribometer data has no '{needed}' column (columns: "
                           f"{', '.join(columns)})")
    i_t = columns.index("temperature_C")
    i_mu = columns.index("friction_coefficient")
    i_test = columns.index("test") if "test" in columns else None
    temperature: list[float] = []
    friction: list[float] = []
    tests: list[int] = []
    failed = 0
    for number, row in enumerate(rows, start=1):
        cells = list(row) + [None] * (len(columns) - len(row))
        mu_cell = cells[i_mu]
        if _is_empty(mu_cell):
            failed += 1
            continue
        t_value = _number(cells[i_t], number, "temperature_C")
        mu_value = _number(mu_cell, number, "friction_coefficient")
        test_value = number
        if i_test is not None and not _is_empty(cells[i_test]):
            test_value = int(_number(cells[i_test], number, "test"))
        temperature.append(t_value)
        friction.append(mu_value)
        tests.append(test_value)
    if not friction:
        raise FitError("tribometer data holds no successful run")
    return TribometerData(np.array(temperature), np.array(friction),
                          np.array(tests, dtype=np.int64), failed)


def _is_empty(cell: object) -> bool:
    if cell is None:
        return True
    if isinstance(cell, float) and math.isnan(cell):
        return True
    return isinstance(cell, str) and cell.strip() == ""


def _number(cell: object, row: int, column: str) -> float:
    if _is_empty(cell):
        raise FitError(f"data row {row}: '{column}' is empty")
    try:
        value = float(str(cell).strip())
    except ValueError:
        raise FitError(f"data row {row}: '{column}' is not a number: {cell!r}") from None
    if not math.isfinite(value):
        raise FitError(f"data row {row}: '{column}' is not finite: {cell!r}")
    return value


def temperature_averages(temperature: ArrayLike,
                         friction: ArrayLike) -> tuple[Array, Array, NDArray[np.int64]]:
    """Mean friction per distinct temperature.

    Returns
    -------
    temperatures, means, counts : ndarray
        Sorted distinct temperatures [degC], mean friction [-], number of runs averaged.
    """
    t, mu = _xy(temperature, friction)
    levels, inverse, counts = np.unique(t, return_inverse=True, return_counts=True)
    sums = np.bincount(inverse, weights=mu)
    return levels, sums / counts, counts.astype(np.int64)


def _xy(temperature: ArrayLike, friction: ArrayLike) -> tuple[Array, Array]:
    t = np.asarray(temperature, dtype=np.float64).ravel()
    mu = np.asarray(friction, dtype=np.float64).ravel()
    if t.shape != mu.shape:
        raise FitError(f"{t.size} temperatures but {mu.size} friction values")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(mu))):
        raise FitError("temperatures and friction values must be finite numbers")
    return t, mu


# ---------------------------------------------------------------------------- fitting

@dataclass(frozen=True)
class _Estimate:
    names: tuple[str, ...]
    params: Array
    covariance_unscaled: Array  # (J^T J)^-1 at the optimum
    predict: Callable[[Array], Array]


def _family_of(model: str) -> tuple[str, int]:
    if model == "linear":
        return "linear", 1
    if model.startswith("poly-"):
        try:
            degree = int(model[5:])
        except ValueError:
            degree = -1
        if degree < 1:
            raise FitError(f"polynomial model '{model}' needs a degree >= 1 (e.g. poly-2)")
        return "polynomial", degree
    if model in ("power", "exponential", "saturation-growth"):
        return model, 0
    raise FitError(f"unknown friction model '{model}' (expected one of {', '.join(MODELS)})")


def _ols(t: Array, mu: Array, degree: int, linear_names: bool) -> _Estimate:
    design = np.vander(t, degree + 1, increasing=True)
    params, _, rank, _ = np.linalg.lstsq(design, mu, rcond=None)
    if rank < degree + 1:
        raise FitError(f"a degree-{degree} fit needs at least {degree + 1} distinct temperatures")
    names = ("a", "b") if linear_names else tuple(f"a{k}" for k in range(degree + 1))
    covariance = np.linalg.inv(design.T @ design)

    def predict(x: Array) -> Array:
        return np.asarray(np.vander(x, degree + 1, increasing=True) @ params, dtype=np.float64)

    return _Estimate(names, np.asarray(params, dtype=np.float64),
                     np.asarray(covariance, dtype=np.float64), predict)


def _start(family: str, t: Array, mu: Array) -> Array:
    """Initial values from a linearised fit."""
    positive = (t > 0) & (mu > 0)
    if family == "power":
        if positive.sum() < 2:
            raise FitError("the power model needs positive temperatures and friction values")
        slope, intercept = np.polyfit(np.log(t[positive]), np.log(mu[positive]), 1)
        return np.array([math.exp(intercept), slope])
    if family == "exponential":
        if positive.sum() < 2:
            raise FitError("the exponential model needs positive friction values")
        slope, intercept = np.polyfit(t[positive], np.log(mu[positive]), 1)
        return np.array([math.exp(intercept), slope])
    # saturation growth: 1/mu = 1/a + (b/a) (1/T)
    if positive.sum() < 2:
        raise FitError("the saturation-growth model needs positive temperatures and friction")
    slope, intercept = np.polyfit(1.0 / t[positive], 1.0 / mu[positive], 1)
    a = 1.0 / intercept if intercept > 0 else float(np.max(mu)) * 2.0
    return np.array([a, max(slope * a, 1e-6)])


def _nonlinear(family: str, t: Array, mu: Array, max_evaluations: int | None) -> _Estimate:
    function = FAMILIES[family].function

    def curve(x: Array, a: float, b: float) -> Array:
        try:
            return function(x, a=a, b=b)
        except TdmonError:
            return np.full(x.shape, 1e6)  # outside the law's domain: steer the optimiser away

    p0 = _start(family, t, mu)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optimize.OptimizeWarning)  # covariance handled below
            params, covariance = optimize.curve_fit(curve, t, mu, p0=p0, method="lm",
                                                    maxfev=max_evaluations or 0)
    except (RuntimeError, ValueError) as exc:
        raise FitError(f"{family} fit did not converge: {exc}") from exc
    if not np.all(np.isfinite(params)):
        raise FitError(f"{family} fit did not converge: non-finite parameters {params}")
    residual = mu - curve(t, *params)
    dof = t.size - 2
    s2 = float(residual @ residual) / dof if dof > 0 else float("nan")
    if dof > 0 and s2 > 0 and np.all(np.isfinite(covariance)):
        unscaled = covariance / s2
    else:  # exact fit or no degrees of freedom: rebuild (J^T J)^-1 from a numerical Jacobian
        unscaled = _unscaled_covariance(curve, t, params)

    def predict(x: Array) -> Array:
        return curve(x, *params)

    return _Estimate(("a", "b"), np.asarray(params, dtype=np.float64), unscaled, predict)


def _unscaled_covariance(curve: Callable[..., Array], t: Array, params: Array) -> Array:
    jac = np.empty((t.size, params.size))
    for k in range(params.size):
        step = 1e-6 * max(abs(params[k]), 1e-6)
        up, down = params.copy(), params.copy()
        up[k] += step
        down[k] -= step
        jac[:, k] = (curve(t, *up) - curve(t, *down)) / (2 * step)
    try:
        return np.asarray(np.linalg.inv(jac.T @ jac), dtype=np.float64)
    except np.linalg.LinAlgError as exc:
        raise FitError(f"the fit's parameters are not identifiable from the data: {exc}") from exc


def _estimate(model: str, t: Array, mu: Array, max_evaluations: int | None) -> _Estimate:
    family, degree = _family_of(model)
    if family in ("linear", "polynomial"):
        return _ols(t, mu, degree, family == "linear")
    return _nonlinear(family, t, mu, max_evaluations)


def fit_friction(temperature: ArrayLike, friction: ArrayLike, model: str = "linear", *,
                 data: DataKind = "raw", max_evaluations: int | None = None) -> FrictionFit:
    """Fit one mu(T) law to friction measurements.

    Parameters
    ----------
    temperature : array_like
        Temperature of each point [degC].
    friction : array_like
        Friction coefficient of each point [-] (individual runs, or per-temperature averages
        such as :func:`temperature_averages` returns or a publication prints).
    model : str
        "linear" (eq. 5), "poly-m" (eq. 11, degree m), "power" (eq. 8), "exponential" (eq. 9)
        or "saturation-growth" (eq. 10).
    data : {"raw", "averages"}
        Label of what the points are (reported; the statistics treat every point alike).
    max_evaluations : int, optional
        Function-evaluation limit of the nonlinear optimiser (scipy's default when None).

    Returns
    -------
    FrictionFit

    Raises
    ------
    FitError
        Too few points or distinct temperatures, a law undefined for the data, or an optimiser
        that does not converge (with scipy's message).

    Notes
    -----
    R^2 and adjusted R^2 follow eq. 19-20 in [1]. The temperature effect is tested on the slope
    b (linear, power, exponential, saturation growth: b = 0 makes mu independent of T) with a
    t-test, and for polynomials with the F-test of all non-constant terms together.
    """
    if data not in ("raw", "averages"):
        raise FitError(f"data must be 'raw' or 'averages', got {data!r}")
    t, mu = _xy(temperature, friction)
    family, degree = _family_of(model)
    p = degree + 1 if family in ("linear", "polynomial") else 2
    n = t.size
    if n < p:
        raise FitError(f"{model} has {p} coefficients but only {n} points are given")
    if np.unique(t).size < 2:
        raise FitError("friction versus temperature needs at least two distinct temperatures")
    if family == "power" and np.any(t <= 0.0):
        raise FitError("the power law mu = a T^b needs temperatures above 0 degC")
    estimate = _estimate(model, t, mu, max_evaluations)
    fitted = estimate.predict(t)
    residual = mu - fitted
    sse = float(residual @ residual)
    sst = float(((mu - mu.mean()) ** 2).sum())
    if sst == 0.0:
        raise FitError("all friction values are equal: R^2 is not defined")
    r2 = 1.0 - sse / sst
    dof = n - p
    adj_r2 = 1.0 - (1.0 - r2) * (n - 1) / dof if dof > 0 else None
    s2 = sse / dof if dof > 0 else None
    names = estimate.names
    coefficients = {name: float(v) for name, v in zip(names, estimate.params, strict=True)}
    errors: dict[str, float | None] = {}
    intervals: dict[str, tuple[float, float] | None] = {}
    p_values: dict[str, float | None] = {}
    t_crit = float(stats.t.ppf(0.5 + _CONFIDENCE / 2, dof)) if dof > 0 else None
    for k, name in enumerate(names):
        if s2 is None or t_crit is None:
            errors[name], intervals[name], p_values[name] = None, None, None
            continue
        se = math.sqrt(max(s2 * float(estimate.covariance_unscaled[k, k]), 0.0))
        errors[name] = se
        value = coefficients[name]
        intervals[name] = (value - t_crit * se, value + t_crit * se)
        p_values[name] = (float(2 * stats.t.sf(abs(value) / se, dof)) if se > 0 else 0.0)
    k_aic = p + 1
    aicc = None
    if n - k_aic - 1 > 0 and sse > 0:
        aicc = n * math.log(sse / n) + 2 * k_aic + 2 * k_aic * (k_aic + 1) / (n - k_aic - 1)
    significant, verdict = _significance(model, family, coefficients, intervals, p_values,
                                         r2, n, p, sse, sst)
    return FrictionFit(
        model=model, family=family, data=data, coefficients=coefficients,
        standard_errors=errors, confidence_intervals=intervals, p_values=p_values,
        n=n, n_parameters=p, r=math.sqrt(max(r2, 0.0)), r2=r2, adj_r2=adj_r2,
        stderr=math.sqrt(s2) if s2 is not None else None, aicc=aicc,
        loo_rmse=_loo_rmse(model, t, mu, p, max_evaluations),
        temperature_significant=significant, verdict=verdict, residuals=residual,
    )


def _significance(model: str, family: str, coefficients: dict[str, float],
                  intervals: dict[str, tuple[float, float] | None],
                  p_values: dict[str, float | None], r2: float, n: int, p: int, sse: float,
                  sst: float) -> tuple[bool | None, str]:
    if family == "polynomial":
        dof = n - p
        if dof <= 0:
            return None, (f"{model}: as many coefficients as points, so there is no test of the "
                          "temperature effect (the curve passes through every point).")
        f_stat = ((sst - sse) / (p - 1)) / (sse / dof) if sse > 0 else math.inf
        p_value = float(stats.f.sf(f_stat, p - 1, dof)) if math.isfinite(f_stat) else 0.0
        significant = p_value < 1 - _CONFIDENCE
        word = "significant" if significant else "NOT significant"
        return significant, (f"{model}: the temperature terms together are {word} at the 95 % "
                             f"level (F-test p = {p_value:.3g}, R^2 = {r2:.3f}, n = {n}).")
    interval = intervals["b"]
    if interval is None:
        return None, (f"{model}: two coefficients and two points, so there is no test of the "
                      "temperature effect.")
    low, high = interval
    significant = not (low <= 0.0 <= high)
    p_b = p_values["b"]
    b = coefficients["b"]
    numbers = f"b = {b:.4g}, 95 % interval [{low:.4g}, {high:.4g}], p = {p_b:.3g}, n = {n}"
    if significant:
        return True, (f"{model}: the temperature effect is significant at the 95 % level "
                      f"({numbers}).")
    return False, (f"{model}: the temperature effect is NOT significant at the 95 % level: the "
                   f"interval of b includes zero ({numbers}); these data cannot tell this law "
                   "from a constant friction factor.")


def _loo_rmse(model: str, t: Array, mu: Array, p: int,
              max_evaluations: int | None) -> float | None:
    n = t.size
    if n - 1 < p:
        return None
    errors = np.empty(n)
    for i in range(n):
        keep = np.arange(n) != i
        if np.unique(t[keep]).size < p or np.unique(t[keep]).size < 2:
            return None
        try:
            estimate = _estimate(model, t[keep], mu[keep], max_evaluations)
        except FitError:
            return None
        errors[i] = mu[i] - estimate.predict(t[i:i + 1])[0]
    return float(np.sqrt(np.mean(errors**2)))


def fit_friction_models(temperature: ArrayLike, friction: ArrayLike,
                        models: Sequence[str] = DEFAULT_MODELS, *, data: DataKind = "raw",
                        skip_failures: bool = True) -> list[FrictionFit]:
    """Fit several mu(T) laws to the same points and rank them.

    Parameters
    ----------
    temperature, friction : array_like
        Points [degC], [-].
    models : sequence of str
        Model names (see :data:`MODELS`).
    data : {"raw", "averages"}
        Label of the points.
    skip_failures : bool
        Leave out a model whose fit fails (too many coefficients for the points, no
        convergence) instead of raising.

    Returns
    -------
    list of FrictionFit
        Best first: lowest AICc, then highest adjusted R^2 (a fit with neither comes last),
        with ``rank`` set 1, 2, ...
    """
    fits: list[FrictionFit] = []
    for model in models:
        try:
            fits.append(fit_friction(temperature, friction, model, data=data))
        except FitError:
            if not skip_failures:
                raise
    if not fits:
        raise FitError(f"none of the models {', '.join(models)} could be fitted to the data")

    def key(fit: FrictionFit) -> tuple[int, float, float]:
        if fit.aicc is not None:
            return (0, fit.aicc, 0.0)
        if fit.adj_r2 is not None:
            return (1, -fit.adj_r2, 0.0)
        return (2, 0.0, 0.0)

    ordered = sorted(fits, key=key)
    return [_with_rank(fit, rank) for rank, fit in enumerate(ordered, start=1)]


def _with_rank(fit: FrictionFit, rank: int) -> FrictionFit:
    return replace(fit, rank=rank)


def confidence_band(fit: FrictionFit, temperature: ArrayLike, at: ArrayLike) -> Array | None:
    """Half-width of the 95 % confidence band of the mean of a linear or polynomial fit.

    t(0.975, n - p) s sqrt(x0' (X'X)^-1 x0), X the fit's design matrix on ``temperature``
    [degC] (the data the fit was made on), evaluated at ``at`` [degC]; None for the
    nonlinear families or without degrees of freedom.
    """
    if fit.family not in ("linear", "polynomial") or fit.stderr is None:
        return None
    columns = fit.n_parameters
    design = np.vander(np.asarray(temperature, dtype=np.float64), columns, increasing=True)
    unscaled = np.linalg.inv(design.T @ design)
    rows = np.vander(np.asarray(at, dtype=np.float64), columns, increasing=True)
    spread = np.sqrt(np.einsum("ij,jk,ik->i", rows, unscaled, rows))
    t_crit = float(stats.t.ppf(0.975, fit.n - columns))
    return np.asarray(t_crit * fit.stderr * spread, dtype=np.float64)
