"""The expectations file of a replay as pydantic models, and ``load_expectations(path)``.

An expectations file (TOML, ``replays/expectations/<replay>.toml``) names the replay and the
daemon configuration and states what the daemon must (and must not) find in the replay: see
:mod:`tdmon.replay.expectations`, which checks them, for the tables and keys. Paths in the file
are relative to it. Every mistake is a :class:`tdmon.errors.ConfigError` naming the file, the
key and the reason.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import Field, create_model, model_validator

from tdmon.calib.parameters import JOINT_PARAMETERS, EstimatedParameters
from tdmon.config.common import Force, Length, StrictModel, load_model, quantity
from tdmon.vocabulary import RigState

__all__ = [
    "AlarmExpectation",
    "DrillingExpectation",
    "EstimatesExpectation",
    "Expectations",
    "ForbiddenAlarms",
    "FrictionExpectation",
    "InputExpectation",
    "JointExpectation",
    "StatesExpectation",
    "load_expectations",
]


#: seconds (in the file with a unit: "10 s")
Duration = Annotated[float, quantity("s")]


class InputExpectation(StrictModel):
    messages: int | None = Field(default=None, ge=0)
    rejected: int = Field(default=0, ge=0, description="at most this many rejections")


class StatesExpectation(StrictModel):
    reference: Literal["truth", "volve"] = "truth"
    agreement: float = Field(default=0.9, ge=0, le=1)
    settle: Duration = Field(default=10.0, ge=0, description="seconds ignored after a change")
    required: list[RigState] = Field(default_factory=list)


class FrictionExpectation(StrictModel):
    # a window estimate's operation: pick_up, slack_off, rotating, or the combined-motion
    # states reaming and back_reaming
    operation: str
    depth: tuple[Length, Length] | None = None
    section: str | None = None
    min: float | None = None
    max: float | None = None
    truth_abs: float | None = Field(default=None, gt=0)
    min_windows: int = Field(default=1, ge=1)
    include_revised: bool = True
    # at least this share of the windows lies within 2 of its mu_std of the windows' median
    # (the published uncertainty is honest about the scatter)
    within_2_std: float | None = Field(default=None, gt=0, le=1)
    # false: no window publishes a friction (each says why it cannot resolve it); true: every
    # window does (docs/hookload.md, "Can the data resolve friction?")
    resolvable: bool | None = None

    @model_validator(mode="after")
    def _something(self) -> FrictionExpectation:
        if (self.min is None and self.max is None and self.truth_abs is None
                and self.within_2_std is None and self.resolvable is None):
            raise ValueError("give min, max, truth_abs, within_2_std or resolvable")
        if self.resolvable is False and not (self.min is None and self.max is None
                                             and self.truth_abs is None
                                             and self.within_2_std is None):
            raise ValueError("resolvable = false claims that no friction is published: give "
                             "no range or truth with it")
        return self


class _JointExpectation(StrictModel):
    # the joint estimates (kind "joint") from `after` [s from the replay's first message] on:
    # medians in ranges and/or against the simulated truth (each estimated parameter's keys,
    # below), the weight difference, and the identifiability verdict of the last one
    after: Duration = Field(default=0.0, ge=0)
    min_estimates: int = Field(default=1, ge=1)
    weight_difference_kN: tuple[float, float] | None = None
    identifiable: bool | None = None
    identifiability: str | None = None  # the last verdict starts with this


def _parameter_keys(parameters: EstimatedParameters) -> dict[str, Any]:
    """Each estimated parameter's keys: ``<name> = [low, high]`` for its median, and where a
    simulated replay records its truth, ``<key>_truth_abs`` and ``<key>_truth_rel`` (the
    median absolute or relative difference from it)."""
    keys: dict[str, Any] = {}
    for parameter in parameters:
        # a force is written with its unit ("20 kN"), a factor as a number
        value: Any = Force if parameter.unit == "N" else float
        keys[parameter.name] = (tuple[value, value] | None, None)
        if parameter.truth is not None:
            keys[f"{parameter.key}_truth_abs"] = (value | None, Field(default=None, gt=0))
            keys[f"{parameter.key}_truth_rel"] = (float | None, Field(default=None, gt=0))
    return keys


if TYPE_CHECKING:
    JointExpectation = _JointExpectation
else:
    JointExpectation = create_model(
        "JointExpectation", __base__=_JointExpectation, __module__=__name__,
        **_parameter_keys(JOINT_PARAMETERS))


class AlarmExpectation(StrictModel):
    event: str | None = None
    nth: int = Field(default=1, ge=1, description="which /truth/alarm of that kind (1: first)")
    kinds: list[str] = Field(default_factory=list)
    at: Duration | None = None
    window: tuple[Duration, Duration] | None = None
    known_issue: str | None = None

    @model_validator(mode="after")
    def _what(self) -> AlarmExpectation:
        if self.event is None and not self.kinds:
            raise ValueError("give event (a /truth/alarm kind) or kinds (daemon alarm kinds)")
        return self


class DrillingExpectation(StrictModel):
    """What the drilling frames' ``model`` messages must show (docs/drilling.md): the weight
    at the bit from the hook load near the scenario's, the drilling curve's hook-load
    residual centred on zero."""

    wob: Force = Field(gt=0, description="the weight on the bit the scenario drills with")
    wob_abs: Force = Field(gt=0, description="median |estimated - wob| at most this")
    residual_abs: Force = Field(gt=0, description="|median hook-load residual| at most this")
    min_frames: int = Field(default=10, ge=1)


class EstimatesExpectation(StrictModel):
    minimum: dict[str, int] = Field(default_factory=dict,
                                    description="at least this many estimates of each kind")


class ForbiddenAlarms(StrictModel):
    kinds: list[str] = Field(default_factory=list)


class Expectations(StrictModel):
    """One replay's expectations (see the module docstring)."""

    replay: Path
    config: Path
    finite: bool = True
    input: InputExpectation = Field(default_factory=InputExpectation)
    states: StatesExpectation | None = None
    friction: list[FrictionExpectation] = Field(default_factory=list)
    joint: list[JointExpectation] = Field(default_factory=list)
    drilling: DrillingExpectation | None = None
    estimates: EstimatesExpectation = Field(default_factory=EstimatesExpectation)
    alarm: list[AlarmExpectation] = Field(default_factory=list)
    forbidden: ForbiddenAlarms = Field(default_factory=ForbiddenAlarms)
    source_file: Path | None = Field(default=None, exclude=True)

    def resolve(self, path: Path) -> Path:
        if path.is_absolute() or self.source_file is None:
            return path
        return self.source_file.parent / path

    @property
    def replay_path(self) -> Path:
        return self.resolve(self.replay)

    @property
    def config_path(self) -> Path:
        return self.resolve(self.config)


def load_expectations(path: str | os.PathLike[str]) -> Expectations:
    """Read and validate an expectations file (paths in it are relative to it).

    Raises
    ------
    ConfigError
        Missing, not TOML, or invalid; the message names the key and the reason.
    """
    file = Path(path)
    expectations = load_model(Expectations, file)
    return expectations.model_copy(update={"source_file": file.resolve()})
