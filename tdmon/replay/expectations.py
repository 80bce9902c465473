"""Expectations of a replay: what the daemon must (and must not) find in it, checked afterwards.

An expectations file (TOML, ``replays/expectations/<replay>.toml``) names the replay and the
daemon configuration and states, all optional:

* ``[input]``: decoded ``messages`` (exact), at most ``rejected`` rejections;
* ``[states]``: rig-state ``agreement`` with ``/truth/state`` (simulated files) or with the
  rig contractor's ``/reference/rig_activity`` codes (Volve files), ignoring ``settle`` seconds
  after each reference change; ``required`` states that must be reported at least once;
* ``[[friction]]``: back-calculated window friction of one ``operation`` (optionally within
  ``depth`` = [top, bottom] m, ``section``) between ``min`` and ``max`` (median of the windows),
  and/or within ``truth_abs`` of ``/truth/friction`` at the window's end (median abs error),
  and/or at least a share ``within_2_std`` of the windows within two of their ``mu_std`` of
  the median;
* ``[[joint]]``: the joint estimates (kind ``joint``) from ``after`` [s] on: for each
  estimated parameter (:data:`tdmon.calib.parameters.JOINT_PARAMETERS`), its median in
  ``<name> = [low, high]`` (``mu``, ``weight_factor``) and/or, where the simulator records its
  truth, within ``<key>_truth_abs`` or ``<key>_truth_rel`` (relative) of it (``mu_truth_abs``
  against ``/truth/friction``'s pick-up value, ``weight_truth_rel`` against ``/truth/weight``);
  median ``weight_difference_kN`` in [low, high], and the last estimate's ``identifiable`` and
  ``identifiability`` (its verdict starts with it);
* ``[[alarm]]``: an alarm that must be raised: ``event`` names a ``/truth/alarm`` kind (its
  ``nth`` occurrence, with its ``accept`` list and time), and/or ``kinds`` lists daemon kinds
  (with ``at`` [s from the replay's first message] when there is no event); ``window`` =
  [before, after] [s] around that time (default: the whole replay). One raised alarm answers
  one expectation only (in file order), so two events cannot be met by the same alarm.
  ``known_issue`` = "why": the expectation is checked and reported but does not fail the run
  (a daemon limitation on record: reported in the summary, never failing the run);
* ``[drilling]``: the drilling frames' ``model`` messages (docs/drilling.md): the weight at
  the bit from the hook load (``wob_estimated_N``) within ``wob_abs`` of ``wob`` (median abs
  error) and the drilling curve's hook-load residual's median within ``residual_abs`` of zero,
  over at least ``min_frames`` frames;
* ``[estimates] minimum``: at least so many estimates of each kind (``window``, ``profile``,
  ``mu_T``);
* ``[forbidden]``: daemon alarm ``kinds`` that must not occur at all;
* ``finite`` (default true): no NaN or infinity in anything published.

The file is read and validated by :mod:`tdmon.config.expectations`. Checking reads the replay
(truth, references) and the daemon's flight recording, and returns one :class:`Check` per
expectation with what was measured, so a failure says by how much.
"""

from __future__ import annotations

import bisect
import itertools
import math
import os
import statistics
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tdmon.calib.parameters import JOINT_PARAMETERS, EstimatedParameter
from tdmon.config.expectations import (
    AlarmExpectation,
    DrillingExpectation,
    Expectations,
    ForbiddenAlarms,
    FrictionExpectation,
    JointExpectation,
    StatesExpectation,
)
from tdmon.vocabulary import EstimateKind, Operation, RigState

__all__ = [
    "VOLVE_ACTIVITY_STATES",
    "Check",
    "check_replay",
    "failed",
    "find_expectations",
]

#: Which tdmon rig states count as agreeing with a Volve activity (the code's last digit's
#: name). "off bottom" is any of the stationary states: the contractor's code does not say
#: whether the string turns or mud flows reliably enough to tell them apart.
VOLVE_ACTIVITY_STATES: dict[str, frozenset[RigState]] = {
    "in slips": frozenset({RigState.IN_SLIPS}),
    "tripping out": frozenset({RigState.PICK_UP, RigState.BACK_REAMING}),
    "tripping in": frozenset({RigState.SLACK_OFF, RigState.REAMING}),
    "reaming": frozenset({RigState.REAMING, RigState.BACK_REAMING}),
    "off bottom": frozenset({RigState.ROTATING_OFF_BOTTOM, RigState.STATIC,
                             RigState.CIRCULATING}),
    "drilling": frozenset({RigState.DRILLING}),
}

#: The ``/truth/friction`` field holding the true friction factor of a window's operation
#: (a drilling window's friction is the rotating string's, from its torque).
_TRUTH_FRICTION: dict[str, str] = {Operation.PICK_UP: "mu_pick_up",
                                   Operation.SLACK_OFF: "mu_slack_off",
                                   Operation.ROTATING: "mu_rotating",
                                   RigState.DRILLING: "mu_rotating"}


def find_expectations(replay: str | os.PathLike[str]) -> Path | None:
    """The expectations of a replay found by its name: ``<dir>/expectations/<stem>.toml``, or
    ``<dir>/<stem>.expect.toml``."""
    path = Path(replay)
    for candidate in (path.parent / "expectations" / f"{path.stem}.toml",
                      path.parent / f"{path.stem}.expect.toml"):
        if candidate.is_file():
            return candidate
    return None


@dataclass(frozen=True)
class Check:
    """One expectation checked: ``measured`` against ``expected``, and by how much it missed."""

    name: str
    passed: bool
    measured: str
    expected: str
    detail: str = ""
    known_issue: str | None = None

    @property
    def fails(self) -> bool:
        """Fails the run: not met, and not a known issue."""
        return not self.passed and self.known_issue is None

    def line(self) -> str:
        mark = "ok  " if self.passed else "FAIL" if self.known_issue is None else "KNOWN"
        text = f"{mark} {self.name}: {self.measured} (expected {self.expected})"
        if self.detail:
            text += f"; {self.detail}"
        if self.known_issue is not None:
            text += f" [known issue: {self.known_issue}" + \
                ("; met now, the note can go]" if self.passed else "]")
        return text


@dataclass
class _Recorded:
    """What checking needs from the daemon's recording and the replay."""

    start: float = math.inf
    states: list[tuple[float, str]] = field(default_factory=list)
    estimates: list[dict[str, Any]] = field(default_factory=list)
    alarms: list[dict[str, Any]] = field(default_factory=list)
    samples: int = 0
    rejected: int = 0
    non_finite: int = 0
    truth_states: list[tuple[float, str]] = field(default_factory=list)
    truth_friction: list[dict[str, Any]] = field(default_factory=list)
    truth_alarms: list[dict[str, Any]] = field(default_factory=list)
    #: per estimated parameter with a simulated truth, (t, true value)
    truth_parameters: dict[str, list[tuple[float, float | None]]] = field(default_factory=dict)
    activities: list[tuple[float, str]] = field(default_factory=list)
    #: the drilling frames' ``drilling`` and ``residual`` fields of the model messages
    drilling: list[tuple[dict[str, Any], dict[str, Any]]] = field(default_factory=list)


def _non_finite(value: Any) -> bool:
    if isinstance(value, float):
        return not math.isfinite(value)
    if isinstance(value, dict):
        return any(_non_finite(v) for v in value.values())
    if isinstance(value, list):
        return any(_non_finite(v) for v in value)
    return False


def _read(replay: Path, recording: Path) -> _Recorded:  # noqa: C901  (complex today; simplify when next touched)
    from tdmon.record.reader import read_messages

    data = _Recorded()
    # each estimated parameter's truth, where the simulator records one (its declaration)
    truths: dict[str, list[tuple[str, str]]] = {}
    for parameter in JOINT_PARAMETERS:
        if parameter.truth is not None:
            topic, key = parameter.truth
            truths.setdefault(topic, []).append((parameter.name, key))
    topics = ["/truth/state", "/truth/friction", "/truth/alarm", "/reference/rig_activity",
              "/tdmon/raw"]
    for item in read_messages(replay, [*topics, *(t for t in truths if t not in topics)]):
        message = item.message
        for name, key in truths.get(item.topic, ()):
            value = message.get(key)
            data.truth_parameters.setdefault(name, []).append(
                (float(message["t"]), None if value is None else float(value)))
        if item.topic == "/tdmon/raw":
            data.start = min(data.start, float(message.get("receive_time", math.inf)))
        elif item.topic == "/truth/state":
            data.truth_states.append((float(message["t"]), str(message["state"])))
        elif item.topic == "/truth/friction":
            data.truth_friction.append(message)
        elif item.topic == "/truth/alarm":
            data.truth_alarms.append(message)
        elif item.topic == "/reference/rig_activity":
            data.activities.append((float(message["t"]), str(message["activity"])))
    recorded_nulls = 0
    for item in read_messages(recording, ["/tdmon/state", "/tdmon/estimate", "/tdmon/alarm",
                                           "/tdmon/sample", "/tdmon/rejected", "/tdmon/model"]):
        message = item.message
        if item.topic == "/tdmon/sample":
            data.samples += 1
            continue
        if item.topic == "/tdmon/rejected":
            data.rejected += 1
            continue
        if _non_finite(message):
            recorded_nulls += 1
        if item.topic == "/tdmon/state":
            data.states.append((float(message["t"]), str(message["state"])))
        elif item.topic == "/tdmon/estimate":
            data.estimates.append(message)
        elif item.topic == "/tdmon/alarm":
            data.alarms.append(message)
        elif item.topic == "/tdmon/model" and "drilling" in message:
            data.drilling.append((message["drilling"], message["residual"]))
    data.non_finite = recorded_nulls
    data.truth_states.sort()
    data.activities.sort()
    if not math.isfinite(data.start):
        data.start = data.states[0][0] if data.states else 0.0
    return data


def _step_lookup(series: Sequence[tuple[float, str]], t: float) -> tuple[str | None, float]:
    """The value in force at ``t`` of a step series, and how long since it changed [s]."""
    times = [s[0] for s in series]
    index = bisect.bisect_right(times, t) - 1
    if index < 0:
        return None, math.inf
    # walk back over repeats (a reference sampled every 15 s repeats its value)
    value = series[index][1]
    first = index
    while first > 0 and series[first - 1][1] == value:
        first -= 1
    return value, t - series[first][0]


def _state_agreement(spec: StatesExpectation, data: _Recorded) -> list[Check]:
    checks: list[Check] = []
    reference = data.truth_states if spec.reference == "truth" else data.activities
    if not reference:
        return [Check("states", False, "no reference in the replay",
                      f"/truth/state or /reference/rig_activity ({spec.reference})")]
    times = [s[0] for s in reference]
    if spec.reference == "volve":
        # a code holds until the next row: compare only within one sample interval of it
        gaps = [b - a for a, b in itertools.pairwise(times) if b > a]
        horizon = 2.0 * statistics.median(gaps) if gaps else math.inf
    else:
        horizon = math.inf
    agree = total = 0
    confusion: dict[tuple[str, str], int] = {}
    for t, state in data.states:
        expected, since = _step_lookup(reference, t)
        if expected is None or since < spec.settle:
            continue
        if spec.reference == "volve":
            index = bisect.bisect_right(times, t) - 1
            if t - times[index] > horizon:
                continue
            accepted = VOLVE_ACTIVITY_STATES.get(expected)
            if accepted is None:
                continue  # "none": the contractor did not say
            ok = state in accepted
        else:
            ok = state == expected
        total += 1
        agree += ok
        if not ok:
            confusion[(expected, state)] = confusion.get((expected, state), 0) + 1
    share = agree / total if total else 0.0
    worst = sorted(confusion.items(), key=lambda item: -item[1])[:3]
    detail = "; ".join(f"{exp} reported as {got} x{n}" for (exp, got), n in worst)
    passed = share >= spec.agreement
    checks.append(Check(
        f"states vs {spec.reference}", passed, f"{100 * share:.1f} % of {total} state messages",
        f">= {100 * spec.agreement:.0f} %",
        (f"{100 * (spec.agreement - share):.1f} points short; " if not passed else "") + detail))
    seen = {state for _, state in data.states}
    for state in spec.required:
        checks.append(Check(f"state {state} reported", state in seen,
                            "yes" if state in seen else "never", "at least once"))
    return checks


def _resolvable(name: str, expected: bool, windows: list[dict[str, Any]],
                unresolved: list[dict[str, Any]]) -> Check:
    """Whether the windows publish a friction (``expected`` true) or none does (false)."""
    measured = f"{len(windows) - len(unresolved)} of {len(windows)} windows resolved friction"
    if unresolved:
        measured += f" (e.g. '{unresolved[0].get('resolution', '')}')"
    passed = not unresolved if expected else len(unresolved) == len(windows)
    return Check(name, passed, measured, "every window resolves friction" if expected
                 else "no window publishes a friction")


def _friction(spec: FrictionExpectation, data: _Recorded) -> Check:  # noqa: C901  (complex today; simplify when next touched)
    windows = [e for e in data.estimates
               if e.get("kind") == EstimateKind.WINDOW and e.get("operation") == spec.operation
               and (spec.include_revised or not e.get("revised"))
               and (spec.section is None or e.get("section") == spec.section)
               and (spec.depth is None
                    or spec.depth[0] <= float(e.get("bit_depth_m", math.nan)) <= spec.depth[1])]
    where = f" {spec.depth[0]:.0f}-{spec.depth[1]:.0f} m" if spec.depth else ""
    name = f"friction {spec.operation}{where}"
    if len(windows) < spec.min_windows:
        return Check(name, False, f"{len(windows)} windows", f">= {spec.min_windows} windows")
    unresolved = [e for e in windows if e.get("mu") is None]
    if spec.resolvable is not None:
        check = _resolvable(name, spec.resolvable, windows, unresolved)
        if not check.passed or spec.resolvable is False:
            return check
    windows = [e for e in windows if e.get("mu") is not None]
    if not windows:
        return Check(name, False, f"{len(unresolved)} windows, none resolved friction",
                     "a friction published")
    mus = [float(e["mu"]) for e in windows]
    median = statistics.median(mus)
    parts: list[str] = []
    expected: list[str] = []
    passed = True
    if spec.min is not None or spec.max is not None:
        low = -math.inf if spec.min is None else spec.min
        high = math.inf if spec.max is None else spec.max
        expected.append(f"median in [{spec.min}, {spec.max}]")
        if not low <= median <= high:
            passed = False
            off = low - median if median < low else median - high
            parts.append(f"median off by {off:.3f}")
    measured = f"median {median:.3f} of {len(windows)} windows (range {min(mus):.3f}-" \
               f"{max(mus):.3f})"
    if spec.within_2_std is not None:
        inside = sum(abs(float(e["mu"]) - median) <= 2.0 * float(e.get("mu_std") or 0.0)
                     for e in windows) / len(windows)
        measured += f", {100 * inside:.0f} % within 2 sigma of the median"
        expected.append(f">= {100 * spec.within_2_std:.0f} % within 2 sigma")
        if inside < spec.within_2_std:
            passed = False
            parts.append("uncertainty too small for the scatter")
    if spec.truth_abs is not None:
        truth_key = _TRUTH_FRICTION.get(spec.operation)
        truth_t = [float(m["t"]) for m in data.truth_friction]
        errors = []
        for e in windows:
            if truth_key is None or not truth_t:
                break
            index = min(max(bisect.bisect_left(truth_t, float(e["t"])), 0), len(truth_t) - 1)
            truth = data.truth_friction[index].get(truth_key)
            if truth is not None:
                errors.append(abs(float(e["mu"]) - float(truth)))
        expected.append(f"median |mu - truth| <= {spec.truth_abs}")
        if not errors:
            passed = False
            parts.append("no truth to compare with")
        else:
            error = statistics.median(errors)
            measured += f", median |error| {error:.3f}"
            if error > spec.truth_abs:
                passed = False
                parts.append(f"error {error - spec.truth_abs:.3f} over")
    return Check(name, passed, measured, " and ".join(expected), "; ".join(parts))


def _truth_at(series: Sequence[tuple[float, float | None]], t: float) -> float | None:
    """The truth series' value nearest after ``t`` (None: no series, or no value there)."""
    if not series:
        return None
    index = min(bisect.bisect_left([s[0] for s in series], t), len(series) - 1)
    return series[index][1]


def _joint(spec: JointExpectation, data: _Recorded) -> Check:  # noqa: C901  (complex today; simplify when next touched)
    estimates = [e for e in data.estimates if e.get("kind") == EstimateKind.JOINT
                 and float(e["t"]) >= data.start + spec.after]
    name = "joint estimate" + (f" after {spec.after:.0f} s" if spec.after else "")
    if len(estimates) < spec.min_estimates:
        return Check(name, False, f"{len(estimates)} estimates", f">= {spec.min_estimates}")
    # the parameters this rig estimates (the sheave efficiency only for a deadline sensor),
    # each over the estimates that publish it (no friction where it is not resolvable)
    present = [p for p in JOINT_PARAMETERS if p.name in estimates[-1]]
    medians = {p.name: statistics.median(values) for p in present
               if (values := [float(e[p.name]) for e in estimates if e.get(p.name) is not None])}
    last = estimates[-1]
    measured = [", ".join(_median_text(p, medians[p.name]) for p in present
                          if p.name in medians) + f" (median of {len(estimates)})"]
    expected: list[str] = []
    problems: list[str] = []

    def within(label: str, value: float, bounds: tuple[float, float]) -> None:
        expected.append(f"{label} in [{bounds[0]:g}, {bounds[1]:g}]")
        if not bounds[0] <= value <= bounds[1]:
            problems.append(f"{label} {value:.4g} outside")

    for parameter in JOINT_PARAMETERS:  # the median in a range: ``<name> = [low, high]``
        bounds = getattr(spec, parameter.name)
        if bounds is None:
            continue
        if parameter.name not in medians:
            expected.append(f"{_label(parameter)} in [{bounds[0]:g}, {bounds[1]:g}]")
            problems.append(f"no {_label(parameter)} published")
            continue
        within(_label(parameter), medians[parameter.name], bounds)
    if spec.weight_difference_kN is not None:
        differences = [float(e["weight_difference_N"]) / 1e3 for e in estimates
                       if e.get("weight_difference_N") is not None]
        if differences:
            within("weight difference [kN]", statistics.median(differences),
                   spec.weight_difference_kN)
        else:
            problems.append("no weight difference")
    for parameter in JOINT_PARAMETERS:  # against the truth: ``<key>_truth_abs``, ``_rel``
        if parameter.truth is None:
            continue
        series = data.truth_parameters.get(parameter.name, [])
        for relative in (False, True):
            tolerance = getattr(spec, f"{parameter.key}_truth_{'rel' if relative else 'abs'}")
            if tolerance is None:
                continue
            errors = []
            for e in estimates:
                truth = _truth_at(series, float(e["t"]))
                if truth is not None and e.get(parameter.name) is not None:
                    value = float(e[parameter.name])
                    errors.append(abs(value / truth - 1.0) if relative else abs(value - truth))
            what = (f"median |{parameter.name} / truth - 1|" if relative
                    else f"median |{parameter.name} - truth|")
            force = parameter.shown == "force" and not relative
            expected.append(f"{what} <= {tolerance / 1e3:g} kN" if force
                            else f"{what} <= {tolerance}")
            if not errors:
                problems.append(f"no {parameter.noun} truth")
                continue
            measured.append(f"{what} {statistics.median(errors) / 1e3:.2f} kN" if force
                            else f"{what} {statistics.median(errors):.4f}")
            if statistics.median(errors) > tolerance:
                problems.append(f"{parameter.noun} off the truth")
    if spec.identifiable is not None:
        expected.append(f"identifiable {spec.identifiable}")
        if bool(last.get("identifiable")) != spec.identifiable:
            problems.append(f"last verdict: {last.get('identifiability')}")
    if spec.identifiability is not None:
        expected.append(f"verdict '{spec.identifiability}...'")
        if not str(last.get("identifiability", "")).startswith(spec.identifiability):
            problems.append(f"last verdict: {last.get('identifiability')}")
    return Check(name, not problems, "; ".join(measured), " and ".join(expected),
                 "; ".join(problems))


def _label(parameter: EstimatedParameter) -> str:
    """A parameter in a check's words: ``mu`` for the friction, else its label."""
    return parameter.name if parameter is JOINT_PARAMETERS.friction else parameter.label


def _median_text(parameter: EstimatedParameter, value: float) -> str:
    if parameter is JOINT_PARAMETERS.friction:
        return f"{parameter.name} {value:.3f}"
    if parameter.shown == "force":
        return f"{parameter.label} {value / 1e3:.2f} kN"
    if parameter.shown == "percent":
        return f"{parameter.label} {100 * value:.2f} %"
    return f"{parameter.label} {value:.4f}"


def _drilling(spec: DrillingExpectation, data: _Recorded) -> list[Check]:
    """The weight at the bit from the hook load and the drilling curve's residual."""
    wobs = [d["wob_estimated_N"] for d, _ in data.drilling
            if d.get("wob_estimated_N") is not None]
    residuals = [r["hookload_N"] for _, r in data.drilling if r.get("hookload_N") is not None]
    checks = []
    if len(wobs) < spec.min_frames:
        checks.append(Check("drilling weight at the bit", False, f"{len(wobs)} frames",
                            f">= {spec.min_frames} drilling frames with an estimate"))
    else:
        error = statistics.median(abs(w - spec.wob) for w in wobs)
        checks.append(Check(
            "drilling weight at the bit", error <= spec.wob_abs,
            f"median {statistics.median(wobs) / 1e3:.1f} kN of {len(wobs)} frames, median |error| "
            f"{error / 1e3:.1f} kN", f"within {spec.wob_abs / 1e3:g} kN of "
            f"{spec.wob / 1e3:g} kN"))
    if len(residuals) < spec.min_frames:
        checks.append(Check("drilling hook-load residual", False, f"{len(residuals)} frames",
                            f">= {spec.min_frames} drilling frames with a residual"))
    else:
        centre = statistics.median(residuals)
        checks.append(Check(
            "drilling hook-load residual", abs(centre) <= spec.residual_abs,
            f"median {centre / 1e3:+.1f} kN of {len(residuals)} frames",
            f"|median| <= {spec.residual_abs / 1e3:g} kN"))
    return checks


def _alarm(spec: AlarmExpectation, data: _Recorded, used: set[int]) -> Check:
    kinds = set(spec.kinds)
    at = None if spec.at is None else data.start + spec.at
    name = f"alarm {spec.event or '/'.join(spec.kinds)}"
    if spec.event is not None:
        name += f" #{spec.nth}" if spec.nth > 1 else ""
        truth = [a for a in data.truth_alarms if a.get("kind") == spec.event]
        if len(truth) < spec.nth:
            return Check(name, False, f"{len(truth)} such events on /truth/alarm",
                         f"event {spec.event} #{spec.nth}", known_issue=spec.known_issue)
        event = truth[spec.nth - 1]
        if not spec.kinds:
            kinds |= set(event.get("accept") or [])
        if at is None:
            at = float(event["t"])
    if spec.window is not None and at is not None:
        low, high = at + spec.window[0], at + spec.window[1]
    else:
        low, high = -math.inf, math.inf
    raised = [(i, a) for i, a in enumerate(data.alarms) if a.get("kind") in kinds]
    inside = [(i, a) for i, a in raised if low <= float(a["t"]) <= high and i not in used]
    where = "" if not math.isfinite(low) else \
        f" in [{low - data.start:.0f}, {high - data.start:.0f}] s"
    expected = f"one of {sorted(kinds)}{where}"
    if inside:
        index, first = inside[0]
        used.add(index)
        return Check(name, True, f"{first['kind']} at {float(first['t']) - data.start:.0f} s",
                     expected, known_issue=spec.known_issue)
    if raised:
        def distance(item: tuple[int, dict[str, Any]]) -> float:
            t = float(item[1]["t"])
            return 0.0 if low <= t <= high else min(abs(t - low), abs(t - high))

        index, nearest = min(raised, key=distance)
        t = float(nearest["t"])
        detail = ("already answers an earlier expectation" if index in used
                  else f"{distance((index, nearest)):.0f} s outside the window")
        return Check(name, False, f"{nearest['kind']} at {t - data.start:.0f} s", expected,
                     detail, known_issue=spec.known_issue)
    return Check(name, False, "not raised", expected, known_issue=spec.known_issue)


def _forbidden(spec: ForbiddenAlarms, data: _Recorded) -> list[Check]:
    checks = []
    for kind in spec.kinds:
        times = [float(a["t"]) - data.start for a in data.alarms if a.get("kind") == kind]
        detail = "" if not times else "first at " + ", ".join(f"{t:.0f} s" for t in times[:3])
        checks.append(Check(f"no {kind} alarm", not times, f"{len(times)} raised", "none",
                            detail))
    return checks


def check_replay(expectations: Expectations, recording: str | os.PathLike[str], *,
                 replay: str | os.PathLike[str] | None = None,
                 non_finite_published: int = 0) -> list[Check]:
    """Check the daemon's ``recording`` of ``replay`` (default: the expectations' replay).

    ``non_finite_published`` is the driver's count of results that held NaN or infinity
    when they were published (the recorder writes those as null, so the file alone cannot
    show them).
    """
    data = _read(Path(replay) if replay is not None else expectations.replay_path,
                 Path(recording))
    checks: list[Check] = []
    spec = expectations.input
    if spec.messages is not None:
        checks.append(Check("decoded samples", data.samples == spec.messages,
                            str(data.samples), str(spec.messages),
                            f"{data.samples - spec.messages:+d}"
                            if data.samples != spec.messages else ""))
    checks.append(Check("rejected", data.rejected <= spec.rejected, str(data.rejected),
                        f"<= {spec.rejected}"))
    if expectations.finite:
        bad = data.non_finite + non_finite_published
        checks.append(Check("finite results", bad == 0, f"{bad} messages with NaN/inf",
                            "0"))
    if expectations.states is not None:
        checks.extend(_state_agreement(expectations.states, data))
    checks.extend(_friction(f, data) for f in expectations.friction)
    checks.extend(_joint(j, data) for j in expectations.joint)
    if expectations.drilling is not None:
        checks.extend(_drilling(expectations.drilling, data))
    kinds = Counter(str(e.get("kind")) for e in data.estimates)
    for kind, minimum in expectations.estimates.minimum.items():
        checks.append(Check(f"{kind} estimates", kinds[kind] >= minimum, str(kinds[kind]),
                            f">= {minimum}"))
    used: set[int] = set()
    checks.extend(_alarm(a, data, used) for a in expectations.alarm)
    checks.extend(_forbidden(expectations.forbidden, data))
    return checks


def failed(checks: Iterable[Check]) -> list[Check]:
    """The checks that fail the run (known issues do not)."""
    return [c for c in checks if c.fails]
