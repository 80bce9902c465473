"""One vocabulary: the schemas list what the code can emit, and the code emits only its words.

* the JSON Schemas' enumerations are the vocabulary's (states, estimate kinds, severities, alarm
  kinds);
* every ``Alarm(...)`` / ``alarm_message(...)`` in tdmon names its kind by a vocabulary member or
  a literal of the vocabulary, never by a built string; where the kind is a variable, the
  function is run over inputs that raise every alarm it can, and each kind must be a member;
* no alarm message is written out as a dict literal (they come from `tdmon.messages`);
* the maps of rig state to load case are the ones the daemon used before the vocabulary.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from tdmon import vocabulary
from tdmon.calib import backcalc, rigstate
from tdmon.calib.alarms import (
    Alarm,
    BandSettings,
    BandTrendState,
    JumpSettings,
    SensorSettings,
    SensorState,
    friction_jump,
    limit_alarms,
    profile_anomaly,
    sensor_alarms,
    update_band_trend,
)
from tdmon.calib.frozen import FROZEN_CHANNELS, FrozenChannel
from tdmon.config.well import load_well_model
from tdmon.messages import alarm_message, estimate_message, status_message
from tdmon.model.torque_drag import Operation as ModelOperation
from tdmon.model.torque_drag import WellModel
from tdmon.record import schemas
from tdmon.record.digest import alarm_rows
from tdmon.vocabulary import (
    FROZEN_ALARM_KINDS,
    AlarmKind,
    ConnectionState,
    EstimateKind,
    Operation,
    RigState,
    Severity,
)

ROOT = Path(__file__).resolve().parents[1]

#: Functions whose alarm kind is a variable: `test_dynamic_alarm_kinds_are_members` runs them.
VARIABLE_KIND_FUNCTIONS = frozenset({
    ("tdmon/calib/alarms.py", "limit_alarms"),
    ("tdmon/calib/alarms.py", "sensor_alarms"),
    ("tdmon/calib/alarms.py", "frozen_alarm"),
    ("tdmon/calib/alarms.py", "to_message"),  # Alarm.to_message: its kind is already a member
})


# -- schemas ----------------------------------------------------------------------------------

def test_schema_enums_are_the_vocabulary() -> None:
    topics = schemas.TOPIC_SCHEMAS
    assert topics["/tdmon/state"]["properties"]["state"]["enum"] == [s.value for s in RigState]
    assert topics["/tdmon/estimate"]["properties"]["kind"]["enum"] == ["window", "profile",
                                                                       "mu_T", "joint"]
    assert topics["/tdmon/alarm"]["properties"]["severity"]["enum"] == ["info", "warning",
                                                                        "critical"]
    alarm_kinds = topics["/tdmon/alarm"]["properties"]["kind"]["enum"]
    assert alarm_kinds == [k.value for k in AlarmKind]
    assert len(alarm_kinds) == len(set(alarm_kinds)) == 28
    # plain strings: the schema is serialised into every MCAP file
    assert all(type(k) is str for k in alarm_kinds)
    assert schemas.RIG_STATES == ("in_slips", "pick_up", "slack_off", "rotating_off_bottom",
                                  "reaming", "back_reaming", "drilling", "circulating",
                                  "static", "unknown")


def test_alarm_schema_rejects_a_kind_outside_the_vocabulary() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    schema = schemas.TOPIC_SCHEMAS["/tdmon/alarm"]
    good = alarm_message(1.7e9, AlarmKind.BAND, Severity.WARNING, "trend")
    jsonschema.validate(good, schema)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**good, "kind": "overpull"}, schema)


def test_every_alarm_kind_has_plain_words() -> None:
    """The report's and the summary's words for an alarm come from the vocabulary: a kind added
    to AlarmKind without its words in ALARM_WORDS fails here."""
    missing = [kind.value for kind in AlarmKind if not vocabulary.ALARM_WORDS.get(kind, "").strip()]
    assert not missing, f"alarm kinds without words in tdmon.vocabulary.ALARM_WORDS: {missing}"
    assert set(vocabulary.ALARM_WORDS) == set(AlarmKind)  # and none for a kind that is gone
    assert len(set(vocabulary.ALARM_WORDS.values())) == len(AlarmKind)  # each its own words
    # the report's rows say them, one per kind raised
    raised = [alarm_message(float(k), kind, Severity.WARNING, "x")
              for k, kind in enumerate(AlarmKind)]
    meanings = {row["kind"]: row["meaning"] for row in alarm_rows(raised)}
    assert meanings == {kind.value: vocabulary.ALARM_WORDS[kind] for kind in AlarmKind}
    assert meanings["weight_mismatch"].startswith("friction and weight estimated together")
    # a kind from a newer daemon's recording is still named, in its own words
    [row] = alarm_rows([{"t": 1.0, "kind": "sheave_slip", "severity": "info", "message": "x"}])
    assert row["meaning"] == "sheave slip"


# -- the kinds the code can raise -------------------------------------------------------------

def _alarm_calls() -> list[tuple[str, str, ast.expr]]:
    """(file, enclosing function, kind expression) of every Alarm(...)/alarm_message(...)."""
    found = []
    for path in sorted((ROOT / "tdmon").rglob("*.py")):
        tree = ast.parse(path.read_text(), filename=str(path))
        for function in ast.walk(tree):
            if not isinstance(function, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            for node in ast.walk(function):
                if not isinstance(node, ast.Call):
                    continue
                name = (node.func.id if isinstance(node.func, ast.Name)
                        else node.func.attr if isinstance(node.func, ast.Attribute) else "")
                if name not in ("Alarm", "alarm_message"):
                    continue
                kind = next((k.value for k in node.keywords if k.arg == "kind"),
                            node.args[1] if len(node.args) > 1 else None)
                assert kind is not None, f"{path}:{node.lineno}: alarm without a kind"
                found.append((str(path.relative_to(ROOT)), function.name, kind))
    return found


def test_the_scan_finds_the_alarm_producers() -> None:
    where = {(file, function) for file, function, _ in _alarm_calls()}
    assert ("tdmon/calib/alarms.py", "update_band_trend") in where
    assert ("tdmon/record/mcap_recorder.py", "_maybe_resume") in where
    assert ("tdmon/record/writer_process.py", "_child_gone") in where


def test_static_alarm_kinds_are_in_the_vocabulary() -> None:
    members = set(AlarmKind.__members__)
    values = {k.value for k in AlarmKind}
    for file, function, kind in _alarm_calls():
        where = f"{file} {function}(): kind {ast.unparse(kind)}"
        if isinstance(kind, ast.Attribute) and isinstance(kind.value, ast.Name) \
                and kind.value.id == "AlarmKind":
            assert kind.attr in members, where
        elif isinstance(kind, ast.Constant):
            assert kind.value in values, where
        elif isinstance(kind, ast.Name | ast.Attribute):
            assert (file, function) in VARIABLE_KIND_FUNCTIONS, \
                f"{where}: a variable kind; run the function in the dynamic test below"
        else:  # an f-string or a concatenation: a name nobody can check
            pytest.fail(f"{where}: built kind, pick an AlarmKind member")


def test_no_alarm_written_out_as_a_dict() -> None:
    for path in sorted((ROOT / "tdmon").rglob("*.py")):
        if path.name == "messages.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.Dict):
                continue
            fields = {k.value: v for k, v in zip(node.keys, node.values, strict=True)
                      if isinstance(k, ast.Constant)}
            # a hand-made alarm: a kind and a severity written as a word (a schema has a dict
            # there, the simulator's /truth/alarm copies an expected alarm's fields)
            severity = fields.get("severity")
            worded = isinstance(severity, ast.Constant) or (
                isinstance(severity, ast.Attribute) and isinstance(severity.value, ast.Name)
                and severity.value.id == "Severity")
            assert not ("kind" in fields and worded), \
                f"{path.relative_to(ROOT)}:{node.lineno}: use tdmon.messages.alarm_message"


def _limit_kinds() -> list[Alarm]:
    well = load_well_model(ROOT / "config" / "wells" / "aadnoy-example-7-1.toml")
    loads = WellModel(well).loads(2000.0, 0.3)
    # warn=0: every limit check reports its worst node, whatever the utilisation
    return [a for operation in ("pick_up", "slack_off")
            for a in limit_alarms(well, loads, operation, 1.0, warn=0.0)]


def _sensor_kinds() -> list[Alarm]:
    settings = SensorSettings(persist_time=2.0)
    state, raised = SensorState(), []
    frozen = tuple(FrozenChannel(channel, 1.0, 0.0, "while its neighbours move")
                   for channel in FROZEN_ALARM_KINDS)
    frames = [({"hookload": -1.0}, ("torque",), ()),
              *[({"hookload": 1e6, "torque": 5e3, "rpm": 10.0, "bit_depth": 3010.0,
                  "hole_depth": 3000.0}, (), frozen) for _ in range(6)]]
    for k, (values, stale, now) in enumerate(frames):
        state, alarms = sensor_alarms(state, float(k), values, stale, now, settings)
        raised += alarms
    return raised


def test_each_frozen_channel_has_its_alarm_kind_and_each_frozen_kind_its_channel() -> None:
    frozen_kinds = {kind for kind in AlarmKind if kind.endswith("_frozen")}
    assert set(FROZEN_ALARM_KINDS.values()) == frozen_kinds
    assert all(kind == f"sensor_{channel}_frozen" for channel, kind in FROZEN_ALARM_KINDS.items())
    assert tuple(FROZEN_ALARM_KINDS) == FROZEN_CHANNELS


def test_dynamic_alarm_kinds_are_members() -> None:
    raised = _limit_kinds() + _sensor_kinds()
    state, band = BandTrendState(), None
    for k in range(20):
        state, alarm = update_band_trend(state, float(k), 130.0, 90.0, 110.0, 1.0,
                                         BandSettings())
        band = band or alarm
    assert band is not None
    jump = friction_jump((0.2, 0.21, 0.2, 0.19), 0.4, 0.01, 1.0, JumpSettings(),
                         operation="pick_up", bit_depth=3000.0)
    mu = np.full(20, 0.25)
    mu[10:13] = 0.35
    anomaly, _ = profile_anomaly(1.0, np.arange(21) * 30.0, mu, np.eye(20) * 1e-4, 0.1,
                                 JumpSettings())
    raised += [band, jump, anomaly]
    assert all(type(a.kind) is AlarmKind and type(a.severity) is Severity for a in raised)
    assert {a.kind for a in raised} == {
        AlarmKind.LIMIT_TENSILE, AlarmKind.LIMIT_SINUSOIDAL_BUCKLING,
        AlarmKind.LIMIT_HELICAL_BUCKLING, AlarmKind.LIMIT_MAKEUP_TORQUE,
        AlarmKind.SENSOR_STALE, AlarmKind.SENSOR_HOOKLOAD_IMPLAUSIBLE,
        AlarmKind.SENSOR_BIT_BELOW_HOLE, *FROZEN_ALARM_KINDS.values(), AlarmKind.BAND,
        AlarmKind.FRICTION_JUMP}
    for alarm in raised:
        assert alarm.to_message()["kind"] in schemas.ALARM_KINDS


def test_an_alarm_outside_the_vocabulary_is_refused() -> None:
    with pytest.raises(ValueError, match="overpull"):
        Alarm(1.0, "overpull", "warning", "x")
    with pytest.raises(ValueError, match="loud"):
        Alarm(1.0, "band", "loud", "x")
    alarm = Alarm(1.0, "band", "warning", "x")  # plain names are accepted and become members
    assert alarm.kind is AlarmKind.BAND and alarm.severity is Severity.WARNING


# -- message constructors ---------------------------------------------------------------------

def test_alarm_message_shape() -> None:
    message = alarm_message(5, AlarmKind.LIMIT_TENSILE, Severity.CRITICAL, "too much",
                            value=2.5e6, limit=math.inf)
    assert message == {"t": 5.0, "kind": "limit_tensile", "severity": "critical",
                       "message": "too much", "value": 2.5e6, "limit": None}
    assert list(message) == ["t", "kind", "severity", "message", "value", "limit"]
    assert type(message["kind"]) is str and type(message["severity"]) is str
    assert type(message["t"]) is float
    with pytest.raises(ValueError):
        alarm_message(1.0, "limit_yield", Severity.INFO, "x")


def test_estimate_and_status_message_shapes() -> None:
    estimate = estimate_message(7.0, EstimateKind.WINDOW, Operation.PICK_UP, 0.21, None,
                                bit_depth_m=3000.0, section="open")
    assert list(estimate) == ["t", "kind", "operation", "mu", "mu_std", "bit_depth_m",
                              "section"]
    assert estimate["kind"] == "window" and type(estimate["operation"]) is str
    assert estimate["mu_std"] is None and estimate["mu"] == 0.21
    with pytest.raises(ValueError):
        estimate_message(7.0, "spline", "pick_up", 0.2, 0.01)
    connections = {"mqtt": ConnectionState.CONNECTED, "zenoh": "retrying in 2.0 s: refused"}
    status = status_message(9.0, 10, 1, 0, None, connections, frames=4)
    assert status == {"t": 9.0, "samples_in": 10, "rejected": 1, "dropped": 0, "lag_s": None,
                      "connections": {"mqtt": "connected",
                                      "zenoh": "retrying in 2.0 s: refused"},
                      "frames": 4}
    assert type(status["connections"]["mqtt"]) is str
    assert status["connections"] is not connections


# -- maps of rig state to load case -----------------------------------------------------------

def test_model_reexports_the_vocabulary_operation() -> None:
    assert ModelOperation is Operation
    assert [o.value for o in Operation] == ["static", "rotating", "pick_up", "slack_off",
                                            "on_bottom"]


def test_state_maps_match_the_daemon_tables_they_replace() -> None:
    # daemon/steps/monitor.py's CURVE_FOR_STATE before the vocabulary
    assert dict(vocabulary.CURVE_FOR_STATE) == {
        "pick_up": "pick_up", "back_reaming": "pick_up", "slack_off": "slack_off",
        "reaming": "slack_off", "rotating_off_bottom": "rotating", "drilling": "rotating",
        "circulating": "rotating", "static": "rotating"}
    assert sorted(vocabulary.ROTATING_STATES) == ["back_reaming", "drilling", "reaming",
                                                  "rotating_off_bottom"]
    # calib/backcalc.py's tables before the vocabulary
    assert dict(backcalc.OPERATION_FOR_STATE) == {
        "pick_up": ("pick_up", "hookload"), "slack_off": ("slack_off", "hookload"),
        "rotating_off_bottom": ("rotating", "torque")}
    assert dict(backcalc.REAMING_OPERATIONS) == {"reaming": "slack_off",
                                                 "back_reaming": "pick_up"}
    assert set(backcalc.OPERATION_FOR_STATE) == vocabulary.CALIBRATING_STATES
    # calib/rigstate.py
    assert list(rigstate.STATES) == list(RigState)
    assert sorted(rigstate.MOVING_STATES) == ["back_reaming", "pick_up", "reaming", "slack_off"]
    # in slips and unknown have no load case; every other state has one
    assert set(RigState) - set(vocabulary.OPERATION_FOR_STATE) == {RigState.IN_SLIPS,
                                                                   RigState.UNKNOWN}


def test_classify_returns_members() -> None:
    thresholds = rigstate.RigStateThresholds()
    state = rigstate.classify(1e6, -0.5, None, False, False, thresholds)
    assert state is RigState.PICK_UP
    assert rigstate.classify(None, None, None, False, False, thresholds) is RigState.UNKNOWN
