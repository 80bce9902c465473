"""The shared Kalman filter: the Joseph-form update against the closed-form (information form)
posterior, the batch helper against the joint posterior, the iterated EKF against the MAP found
independently with scipy, gating by the normalised innovation, and states of the estimators'
classes passing through unchanged but for the filter's fields."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.optimize import brentq, root

from tdmon.calib.kalman import (
    KalmanState,
    Linearisation,
    iterated_update,
    noise_with_model_error,
    predict,
    update,
    update_batch,
)
from tdmon.calib.mu_calibration import MuTState
from tdmon.calib.profile import ProfileState

Array = NDArray[np.float64]


def _spd(n: int, seed: int, scale: float) -> Array:
    """A well-conditioned random covariance, entries of order ``scale``."""
    a = np.random.default_rng(seed).normal(size=(n, n))
    return scale * (a @ a.T / n + np.eye(n))


def _information_posterior(mean: Array, covariance: Array, rows: Array, noise: Array,
                           residual: Array) -> tuple[Array, Array]:
    """Closed form: P+ = (P^-1 + H^T R^-1 H)^-1, x+ = x + P+ H^T R^-1 (z - h)."""
    r_inv = np.diag(1.0 / noise)
    posterior = np.linalg.inv(np.linalg.inv(covariance) + rows.T @ r_inv @ rows)
    return mean + posterior @ rows.T @ r_inv @ residual, posterior


def test_joseph_update_equals_the_information_form() -> None:
    # profile-like scales: friction 0.25 +/- 0.1 in 4 bins, a hook load sensitivity of order
    # 1e5 N per unit friction, a window's error of 2 kN
    mean = np.array([0.25, 0.22, 0.3, 0.27])
    covariance = _spd(4, 3, 0.01)
    h = np.array([4.0e4, 1.1e5, 7.0e4, 0.0])
    noise, measured, predicted = 4.0e6, 251.3e3, 243.0e3
    posterior = update(KalmanState(mean, covariance), measured, predicted, h, noise)
    expected_mean, expected_cov = _information_posterior(
        mean, covariance, h[None, :], np.array([noise]), np.array([measured - predicted]))
    np.testing.assert_allclose(posterior.mean, expected_mean, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(posterior.covariance, expected_cov, rtol=0.0,
                               atol=1e-12 * np.abs(expected_cov).max())
    assert np.array_equal(posterior.covariance, posterior.covariance.T)
    assert posterior.innovation == measured - predicted
    assert posterior.innovation_variance == pytest.approx(h @ covariance @ h + noise,
                                                          rel=1e-14)
    assert posterior.updates == 1
    # what the measurement sees, h x, is known to h P h R / S afterwards
    seen = float(h @ covariance @ h)
    assert float(h @ posterior.covariance @ h) == pytest.approx(seen * noise / (seen + noise),
                                                                rel=1e-10)


def test_a_profile_sized_update_is_the_joseph_product_and_stays_positive() -> None:
    # 141 bins as the friction profile has: the Joseph form multiplied out (O(n^2)) against
    # its two matrix products and against the information form
    n = 141
    rng = np.random.default_rng(11)
    mean, covariance = np.full(n, 0.25), _spd(n, 5, 0.01)
    h = rng.uniform(0.0, 2.0e4, n) * (rng.uniform(size=n) < 0.7)
    noise, measured, predicted = 4.0e6, 251.3e3, 243.0e3
    posterior = update(KalmanState(mean, covariance), measured, predicted, h, noise)
    gain = covariance @ h / (h @ covariance @ h + noise)
    a = np.eye(n) - np.outer(gain, h)
    product = a @ covariance @ a.T + noise * np.outer(gain, gain)
    scale = np.abs(product).max()
    np.testing.assert_allclose(posterior.covariance, product, rtol=0.0, atol=1e-13 * scale)
    expected_mean, expected_cov = _information_posterior(
        mean, covariance, h[None, :], np.array([noise]), np.array([measured - predicted]))
    np.testing.assert_allclose(posterior.mean, expected_mean, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(posterior.covariance, expected_cov, rtol=0.0,
                               atol=1e-11 * scale)
    # a long session of precise windows, each on a few bins: the covariance stays symmetric
    # and positive definite
    state = KalmanState(mean, np.diag(np.full(n, 0.01)))
    for step in range(3000):
        row = np.zeros(n)
        lo = int(rng.integers(0, n - 5))
        row[lo:lo + 5] = rng.uniform(1.0e4, 2.0e4, 5)
        state = update(predict(state, 1e-4), float(rng.normal(0.0, 50.0)), 0.0, row,
                       2.5e3 if step % 2 else 1.0e2)
    assert np.array_equal(state.covariance, state.covariance.T)
    assert np.linalg.eigvalsh(state.covariance).min() > 0.0


def test_update_clips_to_bounds_and_rejects_bad_input() -> None:
    state = KalmanState(np.array([0.2, 0.3]), np.eye(2) * 0.01)
    # an innovation of 1000 with gain 1e-3 / 1.01 per unit would push both bins past 1
    posterior = update(state, 1000.0, 0.0, np.array([1.0, 1.0]), 1e-4, bounds=(0.0, 0.5))
    assert np.array_equal(posterior.mean, [0.5, 0.5])
    unclipped = update(state, 1000.0, 0.0, np.array([1.0, 1.0]), 1e-4)
    assert unclipped.mean[0] == pytest.approx(0.2 + 0.01 * 1000.0 / (0.02 + 1e-4), rel=1e-12)
    assert update(state, math.nan, 0.0, np.array([1.0, 1.0]), 1.0) is state
    assert update(state, 1.0, math.inf, np.array([1.0, 1.0]), 1.0) is state
    assert update(state, 1.0, 0.0, np.array([math.nan, 1.0]), 1.0) is state
    assert update(state, 1.0, 0.0, np.array([1.0, 1.0]), 0.0) is state
    assert update(state, 1.0, 0.0, np.array([1.0, 1.0]), math.nan) is state


def test_batch_equals_the_joint_posterior_in_any_order() -> None:
    mean = np.array([0.3, -0.1, 0.05])
    covariance = _spd(3, 5, 0.04)
    rows = np.random.default_rng(8).normal(size=(5, 3)) * np.array([[10.0], [3.0], [1.0],
                                                                    [5.0], [2.0]])
    noise = np.array([0.5, 0.2, 0.1, 1.0, 0.3])
    truth = np.array([0.25, 0.0, 0.1])
    offset = np.array([1.0, -2.0, 0.5, 0.0, 3.0])  # h(x) = c + H x
    measured = offset + rows @ truth + np.array([0.3, -0.2, 0.05, 0.4, -0.1])
    predicted = offset + rows @ mean
    posterior = update_batch(KalmanState(mean, covariance), measured, predicted, rows, noise)
    expected_mean, expected_cov = _information_posterior(mean, covariance, rows, noise,
                                                         measured - predicted)
    np.testing.assert_allclose(posterior.mean, expected_mean, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(posterior.covariance, expected_cov, rtol=0.0,
                               atol=1e-12 * np.abs(expected_cov).max())
    assert posterior.updates == 5
    order = [3, 0, 4, 2, 1]
    shuffled = update_batch(KalmanState(mean, covariance), measured[order], predicted[order],
                            rows[order], noise[order])
    np.testing.assert_allclose(shuffled.mean, expected_mean, rtol=1e-12, atol=1e-14)
    # a missing measurement is skipped, the others still count
    measured[2] = math.nan
    partial = update_batch(KalmanState(mean, covariance), measured, predicted, rows, noise)
    keep = [0, 1, 3, 4]
    expected_mean, _ = _information_posterior(mean, covariance, rows[keep], noise[keep],
                                              (measured - predicted)[keep])
    assert partial.updates == 4
    np.testing.assert_allclose(partial.mean, expected_mean, rtol=1e-12, atol=1e-14)


# a capstan-like scalar measurement: h(x) = W exp(c x) (hook load pulled round a bend)
W, C = 100.0, 3.0


def _capstan(x: Array) -> Linearisation:
    value = W * math.exp(C * float(x[0]))
    return Linearisation(value, np.array([C * value]), 4.0)


def test_iterated_ekf_converges_to_the_map() -> None:
    x0, p0, measured, noise = 0.2, 0.01, 230.0, 4.0
    prior = KalmanState(np.array([x0]), np.array([[p0]]))

    def gradient(x: float) -> float:  # of the negative log posterior, d/dx
        h = W * math.exp(C * x)
        return (x - x0) / p0 - (measured - h) * C * h / noise

    x_map = brentq(gradient, 0.0, 0.5, xtol=1e-15, rtol=1e-15)
    assert x_map == pytest.approx(0.2776, abs=1e-4)  # a well-identified, curved case
    once = iterated_update(prior, measured, _capstan, iterations=1)
    many = iterated_update(prior, measured, _capstan, iterations=30)
    assert once.accepted and many.accepted and not many.gated
    # one linearisation at the prior is off by the curvature; the iterations remove that
    assert abs(float(once.state.mean[0]) - x_map) > 5e-3
    assert float(many.state.mean[0]) == pytest.approx(x_map, abs=1e-12)
    # the covariance is the last iterate's: the inverse Gauss-Newton Hessian at the MAP
    h_map = C * W * math.exp(C * x_map)
    assert float(many.state.covariance[0, 0]) == pytest.approx(
        1.0 / (1.0 / p0 + h_map**2 / noise), rel=1e-10)
    assert many.state.updates == 1  # one measurement, however many iterations
    assert many.linearisation is not None
    assert many.linearisation.predicted == pytest.approx(W * math.exp(C * x_map), rel=1e-10)


def test_iterated_ekf_converges_to_the_map_in_two_dimensions() -> None:
    # h(x) = x1 exp(x2): the relinearisation term H_i (x0 - x_i) has two components
    x0 = np.array([1.0, 0.1])
    p0 = np.array([[0.04, 0.01], [0.01, 0.09]])
    measured, noise = 1.6, 0.01
    info = np.linalg.inv(p0)

    def linearise(x: Array) -> Linearisation:
        value = float(x[0] * math.exp(x[1]))
        return Linearisation(value, np.array([math.exp(x[1]), value]), noise)

    def gradient(x: Array) -> Array:
        lin = linearise(x)
        return np.asarray(info @ (x - x0) - (measured - lin.predicted) * lin.jacobian / noise)

    solution = root(gradient, x0, tol=1e-14)
    assert solution.success
    result = iterated_update(KalmanState(x0, p0), measured, linearise, iterations=40)
    assert result.accepted
    np.testing.assert_allclose(result.state.mean, solution.x, rtol=0.0, atol=1e-11)
    assert float(np.abs(iterated_update(KalmanState(x0, p0), measured, linearise).state.mean
                        - solution.x).max()) > 1e-3


def _full_iterated_update(prior: KalmanState, measured: float, linearise: object, *,
                          iterations: int, gate: float | None,
                          bounds: tuple[float, float] | None) -> tuple[KalmanState, bool]:
    """The iterated EKF with a whole update (covariance too) at every iterate: what
    iterated_update computed before it kept only the last iterate's covariance."""
    estimate, posterior = prior.mean, prior
    for _ in range(iterations):
        lin = linearise(estimate)  # type: ignore[operator]
        h = lin.jacobian
        posterior = update(prior, measured, lin.predicted + float(h @ (prior.mean - estimate)),
                           h, lin.noise_variance, bounds=bounds)
        if posterior is prior:
            return prior, False
        if gate is not None and posterior.innovation**2 > gate**2 * posterior.innovation_variance:
            return prior, False
        estimate = posterior.mean
    return posterior, True


def test_iterated_update_is_the_whole_update_at_every_iterate_to_the_last_bit() -> None:
    # 30 bins seen through a capstan-like nonlinear measurement, bounded, with and without a
    # gate: the iterates before the last skip their covariance, nothing else may change
    n = 30
    p0 = _spd(n, 5, 0.01)
    x0 = np.full(n, 0.25)
    weights = np.linspace(0.2, 1.0, n) / 18.0  # the string's mean friction at the prior: 0.25

    def linearise(x: Array) -> Linearisation:
        friction = float(weights @ x)
        value = 1e6 * math.exp(0.8 * friction)
        return Linearisation(value, 0.8 * value * weights, 1e8 + (0.02 * value) ** 2)

    outcomes = []
    for measured, gate, iterations in [(1.25e6, None, 2), (1.28e6, 3.0, 3), (1.26e6, 3.0, 5),
                                       (1e9, 3.0, 2), (1e9, 3.0, 1), (1.3e6, None, 1)]:
        prior = KalmanState(x0, p0, updates=3)
        got = iterated_update(prior, measured, linearise, iterations=iterations, gate=gate,
                              bounds=(0.0, 1.0))
        want, accepted = _full_iterated_update(prior, measured, linearise,
                                               iterations=iterations, gate=gate,
                                               bounds=(0.0, 1.0))
        assert got.accepted == accepted
        outcomes.append((got.accepted, got.gated))
        assert np.array_equal(got.state.mean, want.mean)
        assert np.array_equal(got.state.covariance, want.covariance)
        assert (got.state.innovation, got.state.innovation_variance, got.state.updates) == (
            want.innovation, want.innovation_variance, want.updates)
    assert outcomes.count((False, True)) == 2 and outcomes.count((True, False)) == 4


def _linear(value: float) -> Linearisation:
    return Linearisation(value, np.array([1.0]), 1.0)


def test_gate_rejects_an_innovation_beyond_it_and_keeps_the_prior() -> None:
    # P = 1, H = 1, R = 1: S = 2; gate 2 closes beyond |innovation| = 2 sqrt(2) = 2.83
    prior = KalmanState(np.array([0.0]), np.array([[1.0]]), updates=7, innovation=0.5,
                        innovation_variance=2.0)
    gated = iterated_update(prior, 2.9, lambda x: _linear(float(x[0])), gate=2.0)
    assert gated.gated and not gated.accepted
    assert gated.state is prior
    kept = iterated_update(prior, 2.8, lambda x: _linear(float(x[0])), gate=2.0)
    assert kept.accepted and not kept.gated
    assert float(kept.state.mean[0]) == pytest.approx(1.4, rel=1e-15)
    assert kept.state.innovation == 2.8 and kept.state.innovation_variance == 2.0
    # no gate: the same outlier is used
    ungated = iterated_update(prior, 2.9, lambda x: _linear(float(x[0])))
    assert ungated.accepted and float(ungated.state.mean[0]) == pytest.approx(1.45)


def test_iterated_update_rejects_an_unseen_state_or_bad_input() -> None:
    prior = KalmanState(np.array([0.2, 0.3]), np.eye(2))
    blind = iterated_update(prior, 1.0, lambda x: Linearisation(0.0, np.zeros(2), 1.0))
    assert not blind.accepted and not blind.gated and blind.state is prior
    nan = iterated_update(prior, math.nan, lambda x: Linearisation(0.0, np.ones(2), 1.0))
    assert not nan.accepted and not nan.gated and nan.state is prior


def test_states_of_the_estimators_keep_their_class_and_fields() -> None:
    profile = ProfileState(np.array([0.2, 0.3]), np.eye(2) * 0.01)
    drifted = predict(profile, 0.1)
    assert type(drifted) is ProfileState
    np.testing.assert_array_equal(drifted.covariance, np.eye(2) * (0.01 + 0.1**2))
    assert drifted.mu is profile.mu
    mu_t = MuTState(np.array([0.23, 0.0013]), np.diag([0.01, 1e-6]), temperature_min=20.0,
                    temperature_max=60.0)
    posterior = update(predict(mu_t, [0.0, 1e-4]), 1.0, 0.0, np.array([1.0, 50.0]), 1.0)
    assert type(posterior) is MuTState
    assert (posterior.temperature_min, posterior.temperature_max) == (20.0, 60.0)
    assert posterior.theta is posterior.mean and posterior.updates == 1
    np.testing.assert_allclose(posterior.std, np.sqrt(np.diag(posterior.covariance)),
                               rtol=1e-15)


def test_noise_with_model_error() -> None:
    # se 3, 10 % of |H x| = |-40|: 9 + 16
    h, x = np.array([100.0, -200.0]), np.array([0.2, 0.3])
    assert noise_with_model_error(3.0, 0.1, h, x) == pytest.approx(25.0, rel=1e-15)
    assert noise_with_model_error(3.0, 0.0, h, x) == 9.0
    assert noise_with_model_error(0.0, 0.0, h, x) == 1e-12


def test_predict_adds_the_drift_to_the_diagonal_to_the_last_bit() -> None:
    # P + diag(q^2) as NumPy adds the two matrices, a -0.0 off the diagonal included
    for n, q in [(1, 0.01), (3, np.array([0.0, 0.01, 0.02])), (4, np.array([0.02])), (141, 0.003)]:
        p = _spd(n, n, 0.01)
        p[0, n - 1] = -0.0
        state = KalmanState(np.zeros(n), p)
        drifted = predict(state, q).covariance
        expected = p + np.diag(np.broadcast_to(np.asarray(q, dtype=np.float64), (n,)) ** 2)
        assert np.array_equal(drifted, expected)
        assert np.array_equal(np.signbit(drifted), np.signbit(expected))
        assert state.covariance is p and p[0, n - 1] == 0.0  # the prior is left alone
