"""JSON Schemas (draft 2020-12) of the daemon's messages, one per recorded topic.

Each schema is registered once per MCAP file (``encoding="jsonschema"``) and its channel carries
JSON messages, which Foxglove can plot. The shapes are those of docs/architecture.md ("Daemon
messages"); ``/tdmon/well`` and ``/tdmon/profile`` are extra topics proposed in
docs/recording.md for the 3D and profile views.

Numbers cannot be NaN or infinite in these messages: JSON has no spelling for them and the
recorder serialises with ``allow_nan=False`` (it replaces a non-finite value by ``null`` and
counts it). Fields where a value may honestly be missing (a measurement not yet received, a
standard deviation from one sample) are therefore typed ``number | null``; everything else that
feeds a plot or a fit must be a finite number.

Extra properties are allowed everywhere: the estimate message has kind-specific fields, and a
newer daemon may add fields without breaking older readers.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Mapping
from typing import Any, Final

from tdmon.calib.parameters import JOINT_PARAMETERS, EstimatedParameters
from tdmon.vocabulary import AlarmKind, EstimateKind, RigState, Severity

JsonSchema = dict[str, Any]

DRAFT: Final = "https://json-schema.org/draft/2020-12/schema"

TOPIC_PREFIX: Final = "/tdmon/"

SOURCES: Final = ("mqtt", "zenoh", "mcap", "wits0", "opcua")
PAYLOAD_ENCODINGS: Final = ("utf-8", "base64")
# The enumerations of the vocabulary, as plain strings (the schema is serialised to JSON).
RIG_STATES: Final = tuple(state.value for state in RigState)
ESTIMATE_KINDS: Final = tuple(kind.value for kind in EstimateKind)
SEVERITIES: Final = tuple(severity.value for severity in Severity)
ALARM_KINDS: Final = tuple(kind.value for kind in AlarmKind)

_NUMBER: Final[JsonSchema] = {"type": "number"}
_OPTIONAL_NUMBER: Final[JsonSchema] = {"type": ["number", "null"]}
_TIME: Final[JsonSchema] = {"type": "number", "minimum": 0, "description": "Unix time [s]"}
_COUNT: Final[JsonSchema] = {"type": "integer", "minimum": 0}
_TEXT: Final[JsonSchema] = {"type": "string"}
_NUMBERS: Final[JsonSchema] = {"type": "array", "items": {"type": "number"}}
_OPTIONAL_NUMBERS: Final[JsonSchema] = {"type": "array", "items": {"type": ["number", "null"]}}
_BOOLEANS: Final[JsonSchema] = {"type": "array", "items": {"type": "boolean"}}
_OPTIONAL_TEXTS: Final[JsonSchema] = {"type": "array", "items": {"type": ["string", "null"]}}


# Optional fields of a payload recorded only in part (tdmon.ingest.types.bounded_payload): a
# payload longer than the recording's bound keeps its first bytes, its size and its hash.
_BOUNDED_PAYLOAD: Final[JsonSchema] = {
    "payload_bytes": {**_COUNT, "description": "size of the whole payload [bytes]"},
    "payload_sha256": {"type": "string", "pattern": "^[0-9a-f]{64}$",
                       "description": "SHA-256 of the whole payload (hex)"},
    "payload_truncated": {"const": True,
                          "description": "payload holds only the first bytes"},
}


# Optional fields of a topic recorded only in part (tdmon.ingest.types.bounded_topic), as for
# payloads: a topic longer than the recording's bound keeps its first bytes and its size.
_BOUNDED_TOPIC: Final[JsonSchema] = {
    "topic_bytes": {**_COUNT, "description": "size of the whole topic [bytes]"},
    "topic_truncated": {"const": True, "description": "topic holds only the first bytes"},
}


def _object(
    name: str,
    title: str,
    properties: Mapping[str, JsonSchema],
    required: tuple[str, ...],
    **extra: Any,
) -> JsonSchema:
    schema: JsonSchema = {
        "$schema": DRAFT,
        "$id": f"https://tdmon.invalid/schemas/{name}.json",
        "title": title,
        "type": "object",
        "properties": dict(properties),
        "required": list(required),
    }
    schema.update(extra)
    return schema


def _sub(properties: Mapping[str, JsonSchema], required: tuple[str, ...]) -> JsonSchema:
    return {"type": "object", "properties": dict(properties), "required": list(required)}


RAW: Final = _object(
    "raw",
    "tdmon raw input, as received",
    {
        "source": {"enum": list(SOURCES)},
        "topic": _TEXT,
        "receive_time": _TIME,
        "payload": _TEXT,
        "payload_encoding": {"enum": list(PAYLOAD_ENCODINGS)},
        **_BOUNDED_PAYLOAD,
        **_BOUNDED_TOPIC,
    },
    ("source", "topic", "receive_time", "payload", "payload_encoding"),
)

SAMPLE: Final = _object(
    "sample",
    "tdmon decoded sample (SI)",
    {
        "channel": _TEXT,
        "t": _TIME,
        "value": _NUMBER,
        "unit": _TEXT,
        "source": {"enum": list(SOURCES)},
        "topic": _TEXT,
    },
    ("channel", "t", "value", "unit", "source", "topic"),
)

REJECTED: Final = _object(
    "rejected",
    "tdmon rejected input and the reason",
    {
        "reason": _TEXT,
        "source": {"enum": list(SOURCES)},
        "topic": _TEXT,
        "receive_time": _TIME,
        "payload": _TEXT,
        "payload_encoding": {"enum": list(PAYLOAD_ENCODINGS)},
        **_BOUNDED_PAYLOAD,
        **_BOUNDED_TOPIC,
    },
    ("reason", "source", "topic", "receive_time", "payload", "payload_encoding"),
)

STATE: Final = _object(
    "state",
    "tdmon rig state",
    {
        "t": _TIME,
        "state": {"enum": list(RIG_STATES)},
        "steady": {"type": "boolean"},
        # Unknown until the first bit-depth sample arrives.
        "bit_depth_m": _OPTIONAL_NUMBER,
    },
    ("t", "state", "steady", "bit_depth_m"),
)

_OPTIONAL_SOURCE: Final[JsonSchema] = {"enum": [None, "downhole", "surface", "tag", "model"]}

MODEL: Final = _object(
    "model",
    "tdmon modelled loads at the current bit depth, with the broomstick band",
    {
        "t": _TIME,
        "bit_depth_m": _NUMBER,
        # "drilling" on drilling frames only: the drilling curve (docs/drilling.md), null
        # without a weight on bit (or, for the torque, a bit torque)
        "hookload_N": _sub(
            {"pick_up": _NUMBER, "slack_off": _NUMBER, "rotating": _NUMBER,
             "drilling": _OPTIONAL_NUMBER},
            ("pick_up", "slack_off", "rotating"),
        ),
        "torque_Nm": _sub({"rotating": _NUMBER, "drilling": _OPTIONAL_NUMBER}, ("rotating",)),
        "band": _sub(
            {"mu": _NUMBERS, "pick_up_N": _NUMBERS, "slack_off_N": _NUMBERS},
            ("mu", "pick_up_N", "slack_off_N"),
        ),
        # A measurement may be missing (channel not received yet): null, never NaN.
        "measured": _sub(
            {"hookload_N": _OPTIONAL_NUMBER, "torque_Nm": _OPTIONAL_NUMBER},
            ("hookload_N", "torque_Nm"),
        ),
        "residual": _sub(
            {"hookload_N": _OPTIONAL_NUMBER, "torque_Nm": _OPTIONAL_NUMBER},
            ("hookload_N", "torque_Nm"),
        ),
        # drilling frames only: the weights on bit and the bit torque (docs/drilling.md)
        "drilling": _sub(
            {"wob_N": _OPTIONAL_NUMBER, "wob_source": _OPTIONAL_SOURCE,
             "wob_surface_N": _OPTIONAL_NUMBER, "wob_downhole_N": _OPTIONAL_NUMBER,
             "wob_estimated_N": _OPTIONAL_NUMBER, "wob_estimated_std_N": _OPTIONAL_NUMBER,
             "bit_torque_Nm": _OPTIONAL_NUMBER, "bit_torque_source": _OPTIONAL_SOURCE},
            ("wob_N", "wob_source", "wob_surface_N", "wob_downhole_N", "wob_estimated_N",
             "wob_estimated_std_N", "bit_torque_Nm", "bit_torque_source"),
        ),
    },
    ("t", "bit_depth_m", "hookload_N", "torque_Nm", "band", "measured", "residual"),
)

def _joint_properties(parameters: EstimatedParameters) -> dict[str, JsonSchema]:
    """The schema of each field the joint estimate's parameters give its message."""
    kinds: dict[str, JsonSchema] = {"number": _NUMBER, "boolean": {"type": "boolean"},
                                    "text": _TEXT}
    return {field.name: {**kinds[field.kind], "description": f"joint: {field.description}"}
            for field in parameters.message_fields()}


ESTIMATE: Final = _object(
    "estimate",
    "tdmon friction estimate (per window, profile along MD, mu(T) fit, or joint with the "
    "string weight)",
    {
        "t": _TIME,
        "kind": {"enum": list(ESTIMATE_KINDS)},
        "operation": _TEXT,
        # null where the data cannot resolve friction ("resolvable": false, "resolution" says
        # why: docs/hookload.md)
        "mu": _OPTIONAL_NUMBER,
        # One sample has no spread.
        "mu_std": _OPTIONAL_NUMBER,
        "resolvable": {"type": "boolean",
                       "description": "window, joint: the load can show friction above the "
                                      "sensor's uncertainty at this depth"},
        "resolution": {**_TEXT, "description": "window: why friction is not resolvable"},
        "friction_signal": {**_NUMBER, "description": "joint: change of the pick-up/slack-off "
                                                      "split between friction 0.1 and 0.3 [N]"},
        "sensor_uncertainty": {**_NUMBER, "description": "joint: one standard deviation of "
                                                         "that split from the sensor [N]"},
        # Kind-specific fields read by the views and the report (all optional, see
        # docs/recording.md): where a window was taken, the profile arrays, the mu(T) fit.
        "bit_depth_m": _NUMBER,
        "md_m": _NUMBERS,
        "mu_profile": _NUMBERS,
        "mu_profile_std": _OPTIONAL_NUMBERS,
        # per bin: posterior over no-window variance, whether below INFORMED_RATIO, and why not
        "variance_ratio": _NUMBERS,
        "informed": _BOOLEANS,
        "uninformed_reason": _OPTIONAL_TEXTS,
        "model": _TEXT,
        "params": {"type": "object", "additionalProperties": {"type": "number"}},
        "temperature_C": _NUMBERS,
        "mu_points": _NUMBERS,
        # the joint estimate (kind "joint", docs/back-calculation.md): its parameters' fields,
        # from their declaration (tdmon.calib.parameters), and the estimator's own
        **_joint_properties(JOINT_PARAMETERS),
        "windows": {"type": "object", "additionalProperties": _COUNT,
                    "description": "joint: measurements per kind within the horizon"},
        "residuals": {"type": "object", "additionalProperties": _NUMBER,
                      "description": "joint: mean residual per measurement kind [N or N m]"},
        "gated": {**_COUNT, "description": "joint: measurements left out by the gate"},
        "weight_difference_N": {**_OPTIONAL_NUMBER,
                                "description": "joint: (weight factor - 1) times the modelled "
                                               "static string weight at the bit depth [N]"},
        "scatter": {"type": "object", "additionalProperties": _NUMBER,
                    "description": "joint: between-window friction scatter per kind [-]"},
        "mu_single": {"type": "object", "additionalProperties": _NUMBER,
                      "description": "joint: median single-window friction per kind [-]"},
        # a window's friction spread: the measurement's and the between-window scatter
        "mu_std_measurement": _OPTIONAL_NUMBER,
        "scatter_std": _OPTIONAL_NUMBER,
        # a drilling window's weight on bit and bit torque, and whose where the MWD gave
        # either (docs/drilling.md)
        "wob_N": _OPTIONAL_NUMBER,
        "bit_torque_Nm": _OPTIONAL_NUMBER,
        "wob_source": {**_OPTIONAL_SOURCE,
                       "description": "drilling window: whose weight on bit (downhole: the "
                                      "MWD's, surface: the rig's); absent: surface"},
        "bit_torque_source": {**_OPTIONAL_SOURCE,
                              "description": "drilling window: whose bit torque (downhole: "
                                             "the MWD's, tag: the torque step at the last "
                                             "tag); absent: tag"},
    },
    ("t", "kind", "operation", "mu", "mu_std"),
)

ALARM: Final = _object(
    "alarm",
    "tdmon alarm",
    {
        "t": _TIME,
        "kind": {"enum": list(ALARM_KINDS)},
        "severity": {"enum": list(SEVERITIES)},
        "message": _TEXT,
        "value": _OPTIONAL_NUMBER,
        "limit": _OPTIONAL_NUMBER,
    },
    ("t", "kind", "severity", "message"),
)

STATUS: Final = _object(
    "status",
    "tdmon daemon status",
    {
        "t": _TIME,
        "samples_in": _COUNT,
        "rejected": _COUNT,
        "dropped": _COUNT,
        "lag_s": _OPTIONAL_NUMBER,
        "connections": {"type": "object", "additionalProperties": {"type": "string"}},
    },
    ("t", "samples_in", "rejected", "dropped", "lag_s", "connections"),
)

WELL: Final = _object(
    "well",
    "tdmon well trajectory (survey stations, minimum curvature) for the 3D view",
    {
        "t": _TIME,
        "name": _TEXT,
        "md_m": {**_NUMBERS, "minItems": 2},
        "tvd_m": {**_NUMBERS, "minItems": 2},
        "north_m": {**_NUMBERS, "minItems": 2},
        "east_m": {**_NUMBERS, "minItems": 2},
        "file": {**_TEXT, "description": "the well file's name"},
        "string_length_m": {**_NUMBER, "description": "the well file's string tally [m]"},
        "change": {**_TEXT, "description": "start, or why a new well file was taken (a run "
                   "from a rig time, a reload on SIGHUP)"},
        # which run this is, for reports (optional: older recordings lack them)
        "daemon_file": {"type": ["string", "null"]},
        "method": {"type": ["string", "null"], "description": "monitor curves' method"},
        "backcalc_method": {"type": ["string", "null"],
                            "description": "back-calculation's method (null: off)"},
        "mu_t_mode": {"type": "string"},
        "mu_t_law": {"type": ["string", "null"]},
        "sections": {"type": "array", "items": {
            "type": "object",
            "properties": {"name": _TEXT, "kind": {"enum": ["cased", "open"]},
                           "top_m": _NUMBER, "bottom_m": _NUMBER,
                           "friction": {"type": ["string", "null"]}},
            "required": ["kind", "top_m", "bottom_m"],
        }},
        "notes": {"type": "array", "items": _TEXT},
    },
    ("t", "md_m", "tvd_m", "north_m", "east_m"),
)

PROFILE: Final = _object(
    "profile",
    "tdmon profiles along MD: temperature and/or local friction",
    {
        "t": _TIME,
        "md_m": {**_NUMBERS, "minItems": 1},
        "temperature_C": _NUMBERS,
        "mu": _NUMBERS,
        "mu_std": _OPTIONAL_NUMBERS,
        "variance_ratio": _NUMBERS,
        "informed": _BOOLEANS,
        "uninformed_reason": _OPTIONAL_TEXTS,
    },
    ("t", "md_m"),
    anyOf=[{"required": ["temperature_C"]}, {"required": ["mu"]}],
)

_AT_BIT_AND_SHOE: Final[JsonSchema] = _sub({"bit": _OPTIONAL_NUMBER, "shoe": _OPTIONAL_NUMBER},
                                           ("bit", "shoe"))

HYDRAULICS: Final = _object(
    "hydraulics",
    "tdmon fluid forces at the current bit depth: surge or swab, trip-speed limits, the force "
    "at the bit and what the fluid terms change in the frame's load (docs/hydraulics.md)",
    {
        "t": _TIME,
        "bit_depth_m": _NUMBER,
        "trip_speed_m_s": {**_NUMBER, "description": "block speed, > 0 running in"},
        "flow_m3_s": _NUMBER,
        "surge_Pa": _AT_BIT_AND_SHOE,
        "density_kg_m3": _AT_BIT_AND_SHOE,
        "trip_speed_limit_m_s": _sub({"running_in": _OPTIONAL_NUMBER,
                                      "pulling_out": _OPTIONAL_NUMBER},
                                     ("running_in", "pulling_out")),
        "bit_force_N": _NUMBER,
        "bit_pressure_drop_Pa": _OPTIONAL_NUMBER,
        "fluid_hookload_N": _NUMBER,
        "fluid_torque_Nm": _NUMBER,
    },
    ("t", "bit_depth_m", "trip_speed_m_s", "flow_m3_s", "surge_Pa", "density_kg_m3",
     "trip_speed_limit_m_s", "bit_force_N", "bit_pressure_drop_Pa", "fluid_hookload_N",
     "fluid_torque_Nm"),
)

#: Schema of every topic the daemon records, keyed by MCAP topic.
TOPIC_SCHEMAS: Final[Mapping[str, JsonSchema]] = {
    TOPIC_PREFIX + name: schema
    for name, schema in (
        ("raw", RAW),
        ("sample", SAMPLE),
        ("rejected", REJECTED),
        ("state", STATE),
        ("model", MODEL),
        ("estimate", ESTIMATE),
        ("alarm", ALARM),
        ("status", STATUS),
        ("well", WELL),
        ("profile", PROFILE),
        ("hydraulics", HYDRAULICS),
    )
}

#: Schema given to a topic nobody registered: any JSON object (so the message is still kept).
UNTYPED: Final = _object("untyped", "tdmon message on an unregistered topic", {}, ())


def schema_name(topic: str) -> str:
    """Name of a topic's schema in MCAP (Foxglove shows it as the datatype): ``tdmon.model``."""
    return topic.strip("/").replace("/", ".") or "untyped"


def schema_bytes(schema: Mapping[str, Any]) -> bytes:
    """Serialised schema as stored in the MCAP Schema record."""
    return json.dumps(schema, separators=(",", ":"), sort_keys=True).encode()


def schema_for(topic: str) -> JsonSchema:
    """A copy of a topic's schema (``UNTYPED`` for topics that have none)."""
    return copy.deepcopy(dict(TOPIC_SCHEMAS.get(topic, UNTYPED)))
