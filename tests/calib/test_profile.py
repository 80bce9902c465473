"""Friction profile along MD (EKF): the update by hand, the adjoint bin Jacobian against central
differences, a missing measurement keeps the prior, and a local anomaly (+0.1 over 100 m)
located within +/-50 m after the bit passed it once."""

from __future__ import annotations

import copy
import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from tdmon.calib.profile import (
    NO_CONTACT,
    NO_WINDOW_YET,
    NOT_REACHED,
    NOT_SEPARATED,
    FrictionProfile,
    ProfileState,
    describe_information,
    information,
    initial_state,
    measurement_jacobian,
    predict,
    profile_grid,
    update,
)
from tdmon.model.torque_drag import WellModel


def test_scalar_update_by_hand() -> None:
    # P = 0.01, H = 1000, R = 100: S = 10100, K = 10/10100, P+ = 0.01 (1 - 10000/10100)
    state = ProfileState(np.array([0.2]), np.array([[0.01]]))
    posterior = update(state, 1050.0, 1000.0, np.array([1000.0]), 100.0)
    gain = 10.0 / 10100.0
    assert posterior.mu[0] == pytest.approx(0.2 + gain * 50.0)
    assert posterior.covariance[0, 0] == pytest.approx(0.01 * (1 - 10000 / 10100))
    assert posterior.innovation == 50.0
    assert posterior.innovation_variance == pytest.approx(10100.0)
    assert posterior.updates == 1


def test_two_bins_share_a_measurement_by_their_sensitivity() -> None:
    state = ProfileState(np.array([0.2, 0.2]), np.eye(2) * 0.01)
    posterior = update(state, 1100.0, 1000.0, np.array([1000.0, 3000.0]), 1.0)
    shift = posterior.mu - state.mu
    assert shift[1] == pytest.approx(3 * shift[0])
    # the bins become negatively correlated: the data fix their weighted sum only
    assert posterior.covariance[0, 1] < 0


def test_missing_measurement_keeps_the_prior() -> None:
    state = ProfileState(np.array([0.2, 0.3]), np.eye(2) * 0.01)
    assert update(state, math.nan, 1000.0, np.array([1.0, 1.0]), 1.0) is state
    assert update(state, 1.0, 1000.0, np.array([math.inf, 1.0]), 1.0) is state
    assert update(state, 1.0, 1000.0, np.array([1.0, 1.0]), 0.0) is state
    drifted = predict(state, 0.01)
    assert np.allclose(np.diag(drifted.covariance), 0.01 + 1e-4)
    assert np.array_equal(drifted.mu, state.mu)


def test_jacobian_matches_a_uniform_change(model_open: WellModel) -> None:
    grid = profile_grid(model_open, 50.0)
    mu = np.full(grid.n_bins, 0.25)
    predicted, jacobian = measurement_jacobian(model_open, grid, mu, "pick_up", 4000.0)
    assert predicted == pytest.approx(model_open.evaluate("pick_up", 4000.0, 0.25)[0])
    uniform = (model_open.evaluate("pick_up", 4000.0, 0.26)[0] - predicted) / 0.01
    assert jacobian.sum() == pytest.approx(uniform, rel=0.02)
    # the vertical part above the kick-off point carries no friction
    assert np.all(jacobian[grid.mid_md < 1400.0] == 0.0)
    assert np.all(jacobian[grid.edges[:-1] >= 4000.0] == 0.0)


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
@pytest.mark.parametrize(("operation", "quantity"),
                         [("pick_up", 0), ("slack_off", 0), ("rotating", 1)])
def test_adjoint_jacobian_matches_central_differences_per_bin(
    model_open: WellModel, method: str, operation: str, quantity: int,
) -> None:
    # the finite differences the filter used before, made central (forward differences of
    # 0.01 are off by O(step)): every element of a bin moved together; bit mid-bin
    grid = profile_grid(model_open, 30.0)
    depth = 4012.0
    mu = np.random.default_rng(2).uniform(0.15, 0.35, grid.n_bins)
    predicted, jacobian = measurement_jacobian(model_open, grid, mu, operation, depth,
                                               quantity_index=quantity, method=method)
    friction = mu[grid.element_bin]
    assert predicted == model_open.evaluate(operation, depth, friction, method=method)[quantity]
    step = 1e-5
    expected = np.zeros(grid.n_bins)
    for k in np.flatnonzero(grid.edges[:-1] < depth):
        bump = np.where(grid.element_bin == k, step, 0.0)
        high = model_open.evaluate(operation, depth, friction + bump, method=method)[quantity]
        low = model_open.evaluate(operation, depth, friction - bump, method=method)[quantity]
        expected[k] = (high - low) / (2 * step)
    # central differences: rounding ~ 1e-5 N / 1e-5 against bin sensitivities of ~1e4 N
    assert np.abs(jacobian - expected).max() <= 1e-6 * np.abs(expected).max()
    assert np.all(jacobian[grid.edges[:-1] >= depth] == 0.0)


def test_anomaly_located_within_50_m(model_open: WellModel, trip: Any, windows_of: Any) -> None:
    mid = model_open.grid.element_mid_md
    anomaly = (mid > 3000.0) & (mid < 3100.0)
    mu = np.where(anomaly, 0.35, 0.25)
    session = trip(model_open, mu, start=4200.0, end=2400.0, seed=21)
    _, windows = windows_of(session)
    profile = FrictionProfile(model_open, bin_length=20.0, prior_mu=0.25, prior_std=0.1,
                              process_std=0.0)
    used = sum(profile.add_window(w) for w in windows if w.state == "pick_up")
    assert used >= 50
    md, estimate = profile.grid.mid_md, profile.state.mu
    seen = (md > 2450.0) & (md < 4150.0)
    smooth = np.convolve(estimate, np.ones(3) / 3, mode="same")
    peak = md[seen][np.argmax(smooth[seen])]
    assert abs(peak - 3050.0) <= 50.0
    # the anomaly stands out of the background by more than the filter's own uncertainty
    inside = (md > 3010.0) & (md < 3090.0)
    background = seen & ~((md > 2950.0) & (md < 3150.0))
    excess = float(np.mean(estimate[inside]) - np.median(estimate[background]))
    assert excess > 0.05
    # single 20 m bins are uncertain (neighbours trade friction), their mean much less
    weights = inside / inside.sum()
    mean_std = math.sqrt(float(weights @ profile.state.covariance @ weights))
    assert excess > 3 * mean_std
    fields = profile.message_fields()
    assert all(math.isfinite(x) for x in fields["mu_profile"])  # type: ignore[attr-defined]


def test_uncertainty_shrinks_where_the_string_was(model_open: WellModel, trip: Any,
                                                  windows_of: Any) -> None:
    session = trip(model_open, np.full(model_open.n_elements, 0.25), start=4200.0, end=3600.0)
    _, windows = windows_of(session)
    profile = FrictionProfile(model_open, bin_length=100.0, prior_std=0.1, process_std=0.0)
    for window in windows:
        profile.add_window(window)
    std = profile.state.std
    md = profile.grid.mid_md
    assert np.all(std[md < 1400.0] == pytest.approx(0.1))  # vertical: nothing learnt
    # bins the bit (with its heavy 200 m BHA) has passed are known one by one; bins above
    # the highest BHA position are only known as a weighted sum: each stays near the prior,
    # their correlations carry the information
    assert np.mean(std[(md > 3650.0) & (md < 4150.0)]) < 0.06
    assert np.min(std[(md > 2100.0) & (md < 3350.0)]) > 0.09
    state = initial_state(profile.grid, 0.25, 0.1)
    assert state.std == pytest.approx(np.full(profile.grid.n_bins, 0.1))


def test_overpull_window_is_gated_out(model_open: WellModel, trip: Any, windows_of: Any) -> None:
    session = trip(model_open, np.full(model_open.n_elements, 0.25), start=4200.0, end=3700.0,
                   seed=7)
    _, windows = windows_of(session)
    pulls = [w for w in windows if w.state == "pick_up"]
    profile = FrictionProfile(model_open, bin_length=30.0, prior_mu=0.25, process_std=0.0)
    for window in pulls[:-1]:
        profile.add_window(window)
    before = profile.state
    last = pulls[-1]
    overpull = replace(last, hookload=last.hookload + 200e3)  # a tight spot, not friction
    assert not profile.add_window(overpull)
    assert profile.gated == 1
    assert profile.state is before
    assert profile.add_window(last)


def test_information_per_bin(model_open: WellModel, trip: Any, windows_of: Any) -> None:
    # a trip out from 4200 to 3600 m with a 200 m BHA, and drift between windows: bins the bit
    # never reached, the vertical hole and the bins seen only through the whole string keep a
    # variance ratio of (about) 1; the bins the BHA swept are informed
    session = trip(model_open, np.full(model_open.n_elements, 0.25), start=4200.0, end=3600.0)
    _, windows = windows_of(session)
    profile = FrictionProfile(model_open, bin_length=100.0, prior_std=0.1, process_std=0.002)
    fields = profile.message_fields()
    assert fields["informed"] == [False] * profile.grid.n_bins
    assert set(fields["uninformed_reason"]) == {NO_WINDOW_YET}  # type: ignore[arg-type]
    used = sum(profile.add_window(w) for w in windows)
    assert used >= 20
    info = profile.information()
    md, top = profile.grid.mid_md, profile.grid.edges[:-1]
    # drift raised every variance by used * q^2; a bin no window depends on still has ratio 1
    assert profile.state.reference_variance == pytest.approx(np.full(md.size,
                                                                     0.01 + used * 0.002**2))
    below = top >= 4200.0
    assert below.any()
    assert info.variance_ratio[below] == pytest.approx(1.0, abs=1e-12)
    assert all(info.reason[k] == NOT_REACHED for k in np.flatnonzero(below))
    vertical = profile.grid.edges[1:] <= 1500.0  # above the kick-off point
    assert info.variance_ratio[vertical] == pytest.approx(1.0, abs=1e-12)
    assert all(info.reason[k] == NO_CONTACT for k in np.flatnonzero(vertical))
    # the stretch the BHA swept: many windows, ratio << 1
    swept = (md > 3650.0) & (md < 4150.0)
    assert np.all(profile.state.windows_seen[swept] >= 3)
    assert np.max(info.variance_ratio[swept]) < 0.3
    assert info.informed[swept].all()
    # above the BHA the windows saw the bins only together: seen many times, not informed
    together = (md > 2100.0) & (md < 3350.0)
    assert np.all(profile.state.windows_seen[together] == used)
    assert np.min(info.variance_ratio[together]) > 0.8
    assert all(info.reason[k] == NOT_SEPARATED for k in np.flatnonzero(together))
    fields = profile.message_fields()
    assert fields["variance_ratio"] == pytest.approx(info.variance_ratio.tolist())
    assert fields["informed"] == info.informed.tolist()
    text = describe_information(fields["md_m"], fields["informed"],  # type: ignore[arg-type]
                                fields["uninformed_reason"])  # type: ignore[arg-type]
    assert text.startswith(f"{int(info.informed.sum())} of {md.size} points informed")
    assert text.endswith(f"; {md[-1]:.0f} m {NOT_REACHED}")  # the one bin below 4200 m
    assert f"{md[0]:.0f}-{md[vertical][-1]:.0f} m {NO_CONTACT}" in text
    # kept until the state changes; a copy (the estimator's) updated apart gets its own
    assert profile.information() is info
    later = copy.copy(profile)
    assert any(later.add_window(w) for w in windows)
    moved = later.information()
    assert moved is not info and profile.information() is info
    np.testing.assert_array_equal(moved.variance_ratio,
                                  information(later.state, profile.grid.edges).variance_ratio)
    assert not np.array_equal(moved.variance_ratio, info.variance_ratio)
