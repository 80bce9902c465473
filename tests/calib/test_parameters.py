"""The joint estimate's parameters declared once (tdmon.calib.parameters): the declaration's
checks, the message it gives (the field names and order recordings have always had), the
filter it sets up, and a third parameter carried through the filter and its message."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from tdmon.calib.estimator import FrictionEstimator
from tdmon.calib.joint import (
    JointSettings,
    initial_joint,
    joint_fields,
    mean_and_covariance,
    update_joint,
)
from tdmon.calib.parameters import (
    FRICTION,
    FRICTION_AND_WEIGHT,
    JOINT_PARAMETERS,
    WEIGHT_FACTOR,
    EstimatedParameter,
    EstimatedParameters,
)
from tdmon.calib.windows import Window
from tdmon.config.well import load_well_model
from tdmon.model.torque_drag import WellModel

#: The joint estimate message as recordings have it since the estimate was added: the names
#: and the order the declaration must keep for the friction and the weight factor.
RECORDED_FIELDS = [
    "t", "kind", "operation", "mu", "mu_std", "bit_depth_m", "weight_factor",
    "weight_factor_std", "correlation", "identifiable", "identifiability", "mu_joint",
    "mu_joint_std", "mu_at_prior_weight", "mu_at_prior_weight_std", "weight_variance_ratio",
    "windows", "residuals", "gated", "resolvable", "friction_signal", "sensor_uncertainty",
    "weight_difference_N", "scatter", "mu_single",
]
# (resolvable, friction_signal, sensor_uncertainty: whether the well can resolve friction
# above the sensor's uncertainty, added with the hook-load measurement model)

#: A spare offset, as a next parameter may be added: a force, shown in kN (its measurement
#: model is not written, so the windows leave it at its prior).
OFFSET = EstimatedParameter(
    name="spare_offset", key="spare", unit="N", prior=0.0, prior_std=20e3,
    drift_per_hour=2e3, drift_per_100m=0.0, bounds=(-2e5, 2e5), label="spare offset",
    noun="spare offset", words="what the hook-load sensor reads with nothing on the hook",
    shown="force", reference=0.0,
    reading=("the hook load reads {} low", "the hook load reads {} high"), truth=None)


def _window(state: str, t: float, depth: float, hookload: float) -> Window:
    return Window(state, t - 30.0, t, 30, depth, depth, depth, hookload, 3e3)


def _joint_messages(model: WellModel, settings: JointSettings | None = None
                    ) -> list[dict[str, Any]]:
    """The joint estimates of pick-ups and slack-offs at friction 0.22 and 0.33 (the Volve
    trip-out's figures: one friction with a lighter string explains both)."""
    from tdmon.calib.estimator import CalibrationSettings

    # friction and weight alone unless told (a new tuple: the estimator would otherwise fit
    # the rig's hook-load measurement parameters in, tdmon.calib.joint.for_rig)
    estimator = FrictionEstimator(model, CalibrationSettings(
        joint=settings or JointSettings(parameters=EstimatedParameters(
            tuple(FRICTION_AND_WEIGHT)))))
    state = estimator.initial_state()
    joint = []
    for k in range(6):
        for name, mu in (("pick_up", 0.22), ("slack_off", 0.33)):
            depth = 2400.0 - 2.5 * k
            hook = model.evaluate(name, depth, mu)[0]
            t = 1.6e9 + 120.0 * k + (60.0 if name == "slack_off" else 0.0)
            state, outputs = estimator.update(state, _window(name, t, depth, hook))
            joint += [m for _, m in outputs if m.get("kind") == "joint"]
    return joint


@pytest.fixture(scope="module")
def volve() -> WellModel:
    return WellModel(load_well_model("config/wells/volve-f4.toml"))


def test_the_message_keeps_its_recorded_fields_and_order(volve: WellModel) -> None:
    assert [f.name for f in FRICTION_AND_WEIGHT.message_fields()] == RECORDED_FIELDS[6:16]
    joint = _joint_messages(volve)
    assert joint and all(list(m) == RECORDED_FIELDS for m in joint)
    assert type(joint[0]["kind"]) is str and joint[0]["kind"] == "joint"
    assert joint[-1]["identifiable"] and 0.24 <= joint[-1]["mu"] <= 0.29


def test_the_prior_and_drift_are_the_declared_ones(volve: WellModel) -> None:
    settings = JointSettings()
    state = initial_joint(settings)
    assert state.mean.tolist() == [0.25, 1.0]
    assert state.covariance.tolist() == [[0.1**2, 0.0], [0.0, 0.05**2]]
    # a daemon file's prior replaces the declared one, nothing else
    changed = settings.with_prior("weight_factor", 0.97, 0.02)
    assert initial_joint(changed).mean.tolist() == [0.25, 0.97]
    assert changed.parameters.get("weight_factor") == replace(WEIGHT_FACTOR, prior=0.97,
                                                              prior_std=0.02)
    with pytest.raises(ValueError, match="unknown estimated parameter 'weight'"):
        settings.with_prior("weight", 1.0, 0.1)
    # the bounds: a friction far below any the model gives is held at the declared 0
    hook = volve.evaluate("pick_up", 2400.0, 0.0)[0]
    state = update_joint(state, volve, _window("pick_up", 60.0, 2400.0, hook - 200e3),
                         volve.well.block_weight, {}, settings)
    assert state.mean[0] == 0.0


def test_a_declaration_says_everything_and_says_it_once() -> None:
    with pytest.raises(TypeError, match="truth"):
        EstimatedParameter(**{k: v for k, v in vars(OFFSET).items() if k != "truth"})
    with pytest.raises(ValueError, match="shown 'kN'"):
        replace(OFFSET, shown="kN")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="its unit is N, not 'kN'"):
        replace(OFFSET, unit="kN")
    with pytest.raises(ValueError, match="bounds around the prior"):
        replace(OFFSET, bounds=(1.0, 2e5))
    with pytest.raises(ValueError, match="positive prior_std"):
        replace(OFFSET, prior_std=0.0)
    with pytest.raises(ValueError, match="lower-case"):
        replace(OFFSET, name="Hookload offset")
    with pytest.raises(ValueError, match="each reading has one"):
        replace(OFFSET, reading=("low", "high by {}"))
    with pytest.raises(ValueError, match="needs a reference"):
        replace(OFFSET, reference=None)
    with pytest.raises(ValueError, match="names given twice: weight_factor"):
        EstimatedParameters((FRICTION, WEIGHT_FACTOR, WEIGHT_FACTOR))
    with pytest.raises(ValueError, match="keys given twice: weight"):
        EstimatedParameters((FRICTION, WEIGHT_FACTOR, replace(OFFSET, key="weight")))
    with pytest.raises(ValueError, match="first parameter is the friction factor"):
        EstimatedParameters((WEIGHT_FACTOR, FRICTION))
    with pytest.raises(ValueError, match="unknown estimated parameter 'spare'"):
        JOINT_PARAMETERS.index("spare")
    with pytest.raises(ValueError, match="unknown estimated parameter 'weight_factor'"):
        JointSettings(parameters=EstimatedParameters((FRICTION, OFFSET)))  # the model needs w


def test_values_in_words() -> None:
    assert WEIGHT_FACTOR.text(1.0234, 0.0041) == "weight factor 1.023 ± 0.004"
    assert WEIGHT_FACTOR.read(1.0234) == "the string 2.3 % heavier than modelled"
    assert WEIGHT_FACTOR.read(0.9) == "the string 10.0 % lighter than modelled"
    assert OFFSET.text(-12_340.0, 2_000.0) == "spare offset -12.3 ± 2.0 kN"
    assert OFFSET.read(-12_340.0) == "the hook load reads 12.3 kN low"
    efficiency = replace(OFFSET, name="sheave_efficiency", key="sheave", unit="1", prior=0.97,
                         prior_std=0.02, bounds=(0.5, 1.0), label="sheave efficiency",
                         shown="percent", reference=1.0,
                         reading=("{} lost in the sheaves", "{} gained in the sheaves"))
    assert efficiency.text(0.962, 0.011) == "sheave efficiency 96.2 ± 1.1 %"
    assert efficiency.read(0.962) == "3.8 % lost in the sheaves"
    assert FRICTION.read(0.3) is None


def test_a_third_parameter_is_estimated_beside_and_published(volve: WellModel) -> None:
    three = EstimatedParameters((*FRICTION_AND_WEIGHT, OFFSET))
    settings = JointSettings(parameters=three)
    assert [f.name for f in three.message_fields()] == [
        "weight_factor", "weight_factor_std", "spare_offset", "spare_offset_std",
        "correlation", "correlation_mu_spare", "correlation_weight_spare", "identifiable",
        "identifiability", "mu_joint", "mu_joint_std", "mu_at_prior_weight",
        "mu_at_prior_weight_std", "mu_at_prior_spare", "mu_at_prior_spare_std",
        "weight_variance_ratio", "spare_variance_ratio"]
    two, joint = _joint_messages(volve), _joint_messages(volve, settings)
    assert len(two) == len(joint)
    last, before = joint[-1], two[-1]
    assert list(last) == [*RECORDED_FIELDS[:8], "spare_offset", "spare_offset_std",
                          "correlation", "correlation_mu_spare", "correlation_weight_spare",
                          *RECORDED_FIELDS[9:15], "mu_at_prior_spare",
                          "mu_at_prior_spare_std", "weight_variance_ratio",
                          "spare_variance_ratio", *RECORDED_FIELDS[16:]]
    # no window sees the offset yet: its prior, grown by the declared drift over the 11 min
    # between the first and the last window; uncorrelated with the others
    hours = (last["t"] - joint[0]["t"]) / 3600.0
    assert last["spare_offset"] == 0.0
    assert last["spare_offset_std"] == pytest.approx(math.sqrt(20e3**2 + 2e3**2 * hours),
                                                        rel=1e-12)
    assert last["correlation_mu_spare"] == last["correlation_weight_spare"] == 0.0
    assert last["spare_variance_ratio"] == pytest.approx(1.0 + (2e3 / 20e3) ** 2 * hours)
    # so friction and weight are the two-parameter filter's, and the friction published is
    # the one at the offset's prior (not identified), which is the joint one
    for name in ("mu_joint", "weight_factor", "weight_factor_std", "correlation",
                 "mu_at_prior_weight"):
        assert last[name] == pytest.approx(before[name], rel=1e-12), name
    assert not last["identifiable"] and before["identifiable"]
    assert last["identifiability"] == ("weakly identifiable: the spare offset rests mostly "
                                       f"on its prior (variance "
                                       f"{100 * last['spare_variance_ratio']:.0f} % of the "
                                       "prior's)")
    assert last["mu"] == last["mu_at_prior_spare"] == pytest.approx(last["mu_joint"],
                                                                    rel=1e-12)
    state = initial_joint(settings)
    fields = joint_fields(state, settings)
    assert fields["identifiability"] == ("no window yet: friction, weight factor and spare "
                                         "offset are the prior")
    # (the filter keeps forces in kN; in SI the declared priors)
    assert np.diag(state.covariance).tolist() == pytest.approx([0.1**2, 0.05**2, 20.0**2])
    assert np.diag(mean_and_covariance(state, settings)[1]).tolist() == pytest.approx(
        [0.1**2, 0.05**2, 20e3**2])
