"""The joint estimate's parameters, declared once: what each is, its prior, and how it is shown.

The joint estimator (:mod:`tdmon.calib.joint`) estimates a few parameters together from the
windows near each other in depth and time: today the friction factor and a factor on the
modelled string weight. Each is an :class:`EstimatedParameter` in :data:`JOINT_PARAMETERS`,
and everything else is derived from that list:

- the state vector, its prior, drift and bounds (:mod:`tdmon.calib.joint`);
- the fields of the ``joint`` estimate message (:meth:`EstimatedParameters.message_fields`)
  and their JSON Schema (:mod:`tdmon.record.schemas`);
- the report's and summary's verdict in words (:mod:`tdmon.record.digest`) and the fleet
  summary's table (:mod:`tdmon.replay.batch_summary`);
- the Rerun entities and views (:mod:`tdmon.record.rerun_views`) and the Foxglove layout
  (:mod:`tdmon.record.foxglove_layout`, written to ``config/foxglove/tdmon-layout.json``);
- the keys of a replay's ``[[joint]]`` expectations (:mod:`tdmon.config.expectations`).

A new parameter is a row here, its part of the measurement model in :mod:`tdmon.calib.joint`
and the layout file written again (docs/architecture.md, "Where to add"). As pvlib's
``_DC_MODEL_PARAMS``, nothing is optional by default: every attribute is given, a parameter
named twice or a name the list does not hold is an error.

The first parameter is the friction factor: its value is the estimate message's own ``mu``
(every estimate kind has one), its joint value ``mu_joint``; every other parameter is in the
message under its own name. The message keeps the field names and order it had before the
list (docs/recording.md), so recordings of the two parameters are unchanged.

This module imports nothing of tdmon: the config and record layers read it without the
estimator's numerical modules.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Final, Literal, NamedTuple, get_args, overload

__all__ = [
    "BLOCK_WEIGHT",
    "FRICTION",
    "FRICTION_AND_WEIGHT",
    "HOOKLOAD_OFFSET",
    "JOINT_PARAMETERS",
    "SHEAVE_EFFICIENCY",
    "WEIGHT_FACTOR",
    "EstimatedParameter",
    "EstimatedParameters",
    "MessageField",
    "Shown",
    "join_words",
    "rig_parameters",
]

Shown = Literal["factor", "percent", "force"]
"""How a value is shown to a person: ``factor`` as it is (3 decimals), ``percent`` times 100
with ``%``, ``force`` in the display unit of force (kN, klbf; the value is in N)."""

_IDENTIFIER: Final = re.compile(r"[a-z][a-z0-9_]*")


@dataclass(frozen=True, kw_only=True)
class EstimatedParameter:
    """One parameter of the joint estimate.

    Attributes
    ----------
    name : its key in the state and the estimate message, e.g. ``weight_factor``
    key : its short key in the names of fields that combine it with the friction
        (``mu_at_prior_<key>``, ``<key>_variance_ratio``) and in expectation keys
        (``<key>_truth_rel``), e.g. ``weight``
    unit : SI unit of the value, ``"1"`` when dimensionless
    prior, prior_std : prior mean and standard deviation [unit]
    drift_per_hour, drift_per_100m : random-walk drift between windows, per hour of rig time
        and per 100 m of bit travel (standard deviations) [unit]
    bounds : the filter's mean is kept within these [unit]
    label : what the number is called, e.g. ``weight factor``
    noun : what it measures, in sentences, e.g. ``string weight``
    words : what a value means, plain, e.g. ``the string's buoyed weight over the modelled one,
        1 = as modelled``
    shown : how a value is shown (see :data:`Shown`)
    reference : the value at which the model is right as configured (None: none, as for
        friction)
    reading : the words for a value below and above ``reference``, ``{}`` standing for the
        difference (in percent of ``reference`` for a factor, in percent for a percentage,
        in kN for a force), e.g. ``("the string {} lighter than modelled", "...")``; None:
        the value alone
    truth : where a simulated replay records the true value: ``(topic, field)`` (None: no
        truth is simulated)
    """

    name: str
    key: str
    unit: str
    prior: float
    prior_std: float
    drift_per_hour: float
    drift_per_100m: float
    bounds: tuple[float, float]
    label: str
    noun: str
    words: str
    shown: Shown
    reference: float | None
    reading: tuple[str, str] | None
    truth: tuple[str, str] | None

    def __post_init__(self) -> None:
        for attribute in ("name", "key"):
            value = getattr(self, attribute)
            if not _IDENTIFIER.fullmatch(value):
                raise ValueError(f"estimated parameter {attribute} {value!r}: lower-case letters, "
                                 "digits and underscores")
        if self.shown not in get_args(Shown):
            raise ValueError(f"estimated parameter {self.name}: shown {self.shown!r} is not one "
                             f"of {', '.join(get_args(Shown))}")
        if self.unit != ("N" if self.shown == "force" else "1"):
            raise ValueError(f"estimated parameter {self.name}: shown as {self.shown}, its unit "
                             f"is {'N' if self.shown == 'force' else '1'}, not {self.unit!r}")
        low, high = self.bounds
        numbers = (self.prior, self.prior_std, self.drift_per_hour, self.drift_per_100m, low,
                   high)
        if not all(math.isfinite(x) for x in numbers):
            raise ValueError(f"estimated parameter {self.name}: prior, drift and bounds must be "
                             "finite")
        if not (low <= self.prior <= high and self.prior_std > 0.0
                and self.drift_per_hour >= 0.0 and self.drift_per_100m >= 0.0):
            raise ValueError(f"estimated parameter {self.name}: needs bounds around the prior "
                             f"({low} <= {self.prior} <= {high}), a positive prior_std and "
                             "drifts >= 0")
        if self.reading is not None:
            if self.reference is None or (self.shown == "factor" and self.reference == 0.0):
                raise ValueError(f"estimated parameter {self.name}: a reading needs a "
                                 "reference (non-zero for a factor)")
            if not all(words.count("{}") == 1 for words in self.reading):
                raise ValueError(f"estimated parameter {self.name}: each reading has one {{}}")

    @property
    def std_field(self) -> str:
        """The message field of its standard deviation."""
        return f"{self.name}_std"

    @property
    def variance_ratio_field(self) -> str:
        """The message field of its posterior over prior variance."""
        return f"{self.key}_variance_ratio"

    def with_prior(self, prior: float, prior_std: float) -> EstimatedParameter:
        """The same parameter with another prior (a daemon file's ``[calibration]``)."""
        return replace(self, prior=prior, prior_std=prior_std)

    # -- how a value is shown ------------------------------------------------------------

    def display_unit(self, force_label: str = "kN") -> str:
        """The unit a value is shown in (``force_label``: the display unit of force)."""
        return {"factor": "-", "percent": "%", "force": force_label}[self.shown]

    def text(self, value: float, std: float) -> str:
        """``value +/- std`` in words (SI), e.g. ``weight factor 1.023 ± 0.004``."""
        if self.shown == "percent":
            return f"{self.label} {100 * value:.1f} ± {100 * std:.1f} %"
        if self.shown == "force":
            return f"{self.label} {value / 1e3:.1f} ± {std / 1e3:.1f} kN"
        return f"{self.label} {value:.3f} ± {std:.3f}"

    def read(self, value: float) -> str | None:
        """What ``value`` says against the reference, e.g. ``the string 2.3 % heavier than
        modelled`` (None: no reading declared)."""
        if self.reading is None or self.reference is None:
            return None
        below, above = self.reading
        difference = abs(value - self.reference)
        if self.shown == "factor":
            amount = f"{100 * difference / abs(self.reference):.1f} %"
        elif self.shown == "percent":
            amount = f"{100 * difference:.1f} %"
        else:
            amount = f"{difference / 1e3:.1f} kN"
        return (below if value < self.reference else above).format(amount)


class MessageField(NamedTuple):
    """A field of the ``joint`` estimate message."""

    name: str
    kind: Literal["number", "boolean", "text"]
    description: str


@dataclass(frozen=True)
class EstimatedParameters(Sequence[EstimatedParameter]):
    """The joint estimate's parameters, in the order of the state vector; the first is the
    friction factor (the message's ``mu``).

    Raises
    ------
    ValueError
        No parameter, the first not named ``mu``, or a name or key twice.
    """

    parameters: tuple[EstimatedParameter, ...]

    def __post_init__(self) -> None:
        if not self.parameters or self.parameters[0].name != "mu":
            raise ValueError("the joint estimate's first parameter is the friction factor, "
                             "named 'mu' (the estimate message's own mu)")
        for attribute in ("name", "key"):
            values = [getattr(p, attribute) for p in self.parameters]
            twice = sorted({v for v in values if values.count(v) > 1})
            if twice:
                raise ValueError(f"estimated parameter {attribute}s given twice: "
                                 f"{', '.join(twice)}")

    # -- the sequence ---------------------------------------------------------------------

    @overload
    def __getitem__(self, index: int) -> EstimatedParameter: ...

    @overload
    def __getitem__(self, index: slice) -> Sequence[EstimatedParameter]: ...

    def __getitem__(self, index: int | slice) -> EstimatedParameter | Sequence[
            EstimatedParameter]:
        return self.parameters[index]

    def __len__(self) -> int:
        return len(self.parameters)

    def __iter__(self) -> Iterator[EstimatedParameter]:
        return iter(self.parameters)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    def index(self, name: object, start: int = 0, stop: int = 2**63) -> int:
        """Position of parameter ``name`` in the state vector.

        Raises
        ------
        ValueError
            Not a parameter of this list.
        """
        for position, parameter in enumerate(self.parameters):
            if parameter.name == name and start <= position < stop:
                return position
        raise ValueError(f"unknown estimated parameter {name!r} (the joint estimate has "
                         f"{', '.join(self.names)})")

    def get(self, name: str) -> EstimatedParameter:
        """Parameter ``name`` (ValueError when the list has none of that name)."""
        return self.parameters[self.index(name)]

    @property
    def friction(self) -> EstimatedParameter:
        """The friction factor, first of the list."""
        return self.parameters[0]

    @property
    def others(self) -> tuple[EstimatedParameter, ...]:
        """Every parameter but the friction factor (what the friction is estimated beside)."""
        return self.parameters[1:]

    def with_prior(self, name: str, prior: float, prior_std: float) -> EstimatedParameters:
        """The list with parameter ``name``'s prior replaced (ValueError: unknown name)."""
        return self.replaced(name, prior=prior, prior_std=prior_std)

    def replaced(self, name: str, **changes: float) -> EstimatedParameters:
        """The list with attributes of parameter ``name`` replaced, e.g. its prior or drift
        (ValueError: unknown name; the parameter's own checks apply)."""
        k = self.index(name)
        changed = replace(self.parameters[k], **changes)  # type: ignore[arg-type]
        return EstimatedParameters((*self.parameters[:k], changed, *self.parameters[k + 1:]))

    # -- the message's fields -------------------------------------------------------------

    def correlation_field(self, i: int, j: int) -> str:
        """The message field of the correlation of parameters ``i < j``: ``correlation`` for
        the friction and the first other (its name before the list), else
        ``correlation_<key i>_<key j>``."""
        if (i, j) == (0, 1):
            return "correlation"
        return f"correlation_{self.parameters[i].key}_{self.parameters[j].key}"

    def pairs(self) -> Iterator[tuple[int, int]]:
        """Every pair ``i < j`` of parameters, in the message's order."""
        n = len(self.parameters)
        return ((i, j) for i in range(n) for j in range(i + 1, n))

    @property
    def joint_field(self) -> str:
        """The message field of the friction of the joint state (``mu_joint``)."""
        return f"{self.friction.name}_joint"

    def at_prior_field(self, parameter: EstimatedParameter) -> str:
        """The message field of the friction at ``parameter``'s prior (``mu_at_prior_weight``)."""
        return f"{self.friction.name}_at_prior_{parameter.key}"

    def message_fields(self) -> tuple[MessageField, ...]:
        """The ``joint`` estimate's fields after the common ones (``t``, ``kind``,
        ``operation``, ``mu``, ``mu_std``) and ``bit_depth_m``, in the message's order, up to
        the estimator's own (``windows``, ``residuals`` and after)."""
        return self._message_fields

    @cached_property
    def _message_fields(self) -> tuple[MessageField, ...]:
        # made once per list: the estimator asks for them with every joint estimate
        friction, others = self.friction, self.others
        fields: list[MessageField] = []

        def add(name: str, kind: Literal["number", "boolean", "text"], what: str) -> None:
            fields.append(MessageField(name, kind, what))

        for p in others:
            unit = "" if p.unit == "1" else f" [{p.unit}]"
            add(p.name, "number", f"{p.label}: {p.words}{unit}")
            add(p.std_field, "number", f"standard deviation of {p.name}{unit}")
        for i, j in self.pairs():
            add(self.correlation_field(i, j), "number",
                f"correlation of {self.parameters[i].label} and {self.parameters[j].label} [-]")
        add("identifiable", "boolean",
            join_words([friction.noun, *(p.noun for p in others)]) + " separated by the data")
        add("identifiability", "text", "the verdict in words")
        add(self.joint_field, "number", f"{friction.label} of the joint estimate [-]")
        add(f"{self.joint_field}_std", "number", "its standard deviation [-]")
        for p in others:
            add(self.at_prior_field(p), "number", f"{friction.label} at the prior {p.label} [-]")
            add(f"{self.at_prior_field(p)}_std", "number", "its standard deviation [-]")
        for p in others:
            add(p.variance_ratio_field, "number", f"posterior over prior variance of {p.name} [-]")
        return tuple(fields)

    # -- words ----------------------------------------------------------------------------

    def nouns(self) -> str:
        """What the parameters beside the friction measure, joined: ``string weight``."""
        return join_words(p.noun for p in self.others)


def join_words(words: Iterable[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    items = list(words)
    if len(items) < 2:
        return "".join(items)
    return ", ".join(items[:-1]) + " and " + items[-1]


FRICTION: Final = EstimatedParameter(
    name="mu", key="mu", unit="1",
    prior=0.25, prior_std=0.1, drift_per_hour=0.02, drift_per_100m=0.01, bounds=(0.0, 2.0),
    label="friction factor", noun="friction",
    words="one friction factor on the whole string (its average over cased and open hole)",
    shown="factor", reference=None, reading=None,
    truth=("/truth/friction", "mu_pick_up"),
)
"""The friction factor: the string's average (the window and profile estimates keep the
cased/open split)."""

WEIGHT_FACTOR: Final = EstimatedParameter(
    name="weight_factor", key="weight", unit="1",
    prior=1.0, prior_std=0.05, drift_per_hour=0.002, drift_per_100m=0.001, bounds=(0.0, 2.0),
    label="weight factor", noun="string weight",
    words="the string's buoyed weight over the modelled one, 1 = as modelled",
    shown="factor", reference=1.0,
    reading=("the string {} lighter than modelled", "the string {} heavier than modelled"),
    truth=("/truth/weight", "weight_factor"),
)
"""A factor on the modelled buoyed string weight: a fluid-density or mass-per-metre error is a
fixed fraction of the string's weight at any depth, so its prior carries from well to well
(docs/back-calculation.md, "Friction and weight together")."""

BLOCK_WEIGHT: Final = EstimatedParameter(
    name="block_weight", key="block", unit="N",
    prior=0.0, prior_std=20e3, drift_per_hour=0.0, drift_per_100m=0.0, bounds=(0.0, 5e6),
    label="block weight", noun="block weight",
    words="the travelling equipment as the hook-load sensor weighs it at rest, its zero "
          "offset aside (the well file's block weight, less what sits above a load pin)",
    shown="force", reference=None, reading=None,
    truth=("/truth/sensor", "block_weight_N"),
)
"""The travelling equipment's weight the sensor reads (its prior: the well file's block weight
with the daemon file's ``block_weight_std``). With the hook load's zero offset it makes what
a still, empty block reads; only their sum shows in slips, the sheave factor of a moving block
and the string's weight in the hangs tell them apart (docs/hookload.md)."""

HOOKLOAD_OFFSET: Final = EstimatedParameter(
    name="hookload_offset", key="offset", unit="N",
    prior=0.0, prior_std=20e3, drift_per_hour=20e3, drift_per_100m=0.0,
    bounds=(-500e3, 500e3),
    label="hook-load offset", noun="hook-load zero",
    words="what the hook-load sensor reads with nothing on it (its zero drift), 0 = true zero",
    shown="force", reference=0.0,
    reading=("the sensor reads {} low", "the sensor reads {} high"),
    truth=("/truth/sensor", "offset_N"),
)
"""The hook-load sensor's zero offset, drifting as a random walk (load cells drift by several
tonnes with temperature over a trip)."""

SHEAVE_EFFICIENCY: Final = EstimatedParameter(
    name="sheave_efficiency", key="sheave", unit="1",
    prior=0.9615, prior_std=0.02, drift_per_hour=0.001, drift_per_100m=0.0,
    bounds=(0.85, 1.0),
    label="sheave efficiency", noun="sheave friction",
    words="efficiency per turning sheave of the block and tackle a deadline sensor reads "
          "through (API RP 9B's design value 1/1.04 = 0.9615; 1 = no sheave friction)",
    shown="factor", reference=None, reading=None,
    truth=("/truth/sensor", "efficiency"),
)
"""Estimated only for a deadline sensor (the well file's ``[hookload_sensor]``): hoisting reads
low and lowering high by the sheave factor (:mod:`tdmon.model.hookload_sensor`)."""

#: Prior standard deviation of a block weight the well file does not give [N].
UNKNOWN_BLOCK_STD: Final = 1e6

JOINT_PARAMETERS: Final = EstimatedParameters((FRICTION, WEIGHT_FACTOR, BLOCK_WEIGHT,
                                               HOOKLOAD_OFFSET, SHEAVE_EFFICIENCY))
"""Every parameter the joint estimate may have, in the order of its state vector (what its
message, schema, views and expectations know); a rig's estimate takes those its hook-load sensor
calls for (:func:`rig_parameters`)."""

FRICTION_AND_WEIGHT: Final = EstimatedParameters((FRICTION, WEIGHT_FACTOR))
"""The joint estimate without the hook-load measurement (the sensor taken as configured): the
settings' default until they are fitted to a rig (:func:`tdmon.calib.joint.for_rig`)."""


def rig_parameters(*, reads_sheave_friction: bool, block_weight: float,
                   efficiency: float, parameters: EstimatedParameters = JOINT_PARAMETERS
                   ) -> EstimatedParameters:
    """The parameters of one rig's joint estimate: the sheave efficiency only for a sensor that
    reads the sheave friction (a deadline sensor), the block weight centred on ``block_weight``
    [N] (as the sensor weighs it), the sheave efficiency on ``efficiency`` (the well file's,
    below 1; API RP 9B's design value when the file gives 1)."""
    chosen = [p for p in parameters
              if p.name != SHEAVE_EFFICIENCY.name or reads_sheave_friction]
    out = EstimatedParameters(tuple(chosen))
    if BLOCK_WEIGHT.name in out.names:
        block = out.get(BLOCK_WEIGHT.name)
        # no block weight in the well file: the first in-slips readings give it
        out = out.with_prior(block.name, max(block_weight, 0.0),
                             block.prior_std if block_weight > 0.0 else UNKNOWN_BLOCK_STD)
    if SHEAVE_EFFICIENCY.name in out.names and efficiency < 1.0:
        sheave = out.get(SHEAVE_EFFICIENCY.name)
        out = out.with_prior(sheave.name, efficiency, sheave.prior_std)
    return out
