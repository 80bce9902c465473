"""A simulated session, or any list of input messages, written as an MCAP file.

Input samples are written as ``/tdmon/raw`` messages exactly as the daemon's flight recorder
keeps them (``source``, ``topic``, ``receive_time``, ``payload``, ``payload_encoding``), so the
replay source (:mod:`tdmon.ingest.mcap_source`) treats recorded, imported and simulated files
alike. The truth of a simulation goes on ``/truth/...`` topics, each with a JSON Schema
(:data:`TRUTH_SCHEMAS`); the replay source ignores them.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, Final

import numpy as np
from tqdm import tqdm

from tdmon.channels import CHANNEL_UNITS
from tdmon.errors import RecordError
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.schemas import DRAFT
from tdmon.replay.session import STATES, Scenario, Session, simulate_session
from tdmon.vocabulary import RigState, Severity

__all__ = [
    "RAW_TOPIC",
    "SOURCE",
    "TRUTH_SCHEMAS",
    "MessageRecord",
    "payload_unit",
    "raw_input",
    "session_messages",
    "simulate_to_mcap",
    "write_mcap",
]

RAW_TOPIC: Final = "/tdmon/raw"
#: ``source`` of the raw messages written here: they come from a file, not a broker.
SOURCE: Final = "mcap"

#: (log time [ns since the Unix epoch], topic, message)
MessageRecord = tuple[int, str, dict[str, Any]]

_NUMBER: Final = {"type": "number"}
_OPTIONAL: Final = {"type": ["number", "null"]}
_TIME: Final = {"type": "number", "minimum": 0, "description": "Unix time [s]"}
_NUMBERS: Final = {"type": "array", "items": {"type": "number"}}
_OPTIONAL_NUMBERS: Final = {"type": "array", "items": {"type": ["number", "null"]}}
_TEXT: Final = {"type": "string"}


def _schema(name: str, title: str, properties: Mapping[str, Any],
            required: tuple[str, ...]) -> dict[str, Any]:
    return {"$schema": DRAFT, "$id": f"https://tdmon.invalid/schemas/{name}.json",
            "title": title, "type": "object", "properties": dict(properties),
            "required": list(required)}


_STATES: Final = {"enum": [s.value for s in STATES]}

#: JSON Schemas of the truth topics of a simulated file.
TRUTH_SCHEMAS: Final[dict[str, dict[str, Any]]] = {
    "/truth/scenario": _schema(
        "truth.scenario", "simulated session: what it was generated from",
        {"t": _TIME, "name": _TEXT, "seed": {"type": "integer"}, "well": _TEXT,
         "method": _TEXT, "prefix": _TEXT, "block_weight_N": _NUMBER, "duration_s": _NUMBER,
         "sample_interval_s": {"type": "object", "additionalProperties": _NUMBER},
         "hookload_sensor": {"type": "object", "properties": {
             "location": {"enum": ["deadline", "hook", "top_drive"]},
             "lines": {"type": "integer"}, "efficiency": _NUMBER, "above_sensor_N": _NUMBER,
             "offset_start_N": _NUMBER, "offset_end_N": _NUMBER}}},
        ("t", "name", "seed", "method", "prefix", "block_weight_N", "duration_s")),
    "/truth/state": _schema(
        "truth.state", "true rig state, at the start and at every change",
        {"t": _TIME, "state": _STATES, "bit_depth_m": _NUMBER, "hole_depth_m": _NUMBER},
        ("t", "state", "bit_depth_m", "hole_depth_m")),
    "/truth/load": _schema(
        "truth.load", "noise-free surface loads and depths at every true hook-load sample time",
        {"t": _TIME, "state": _STATES, "bit_depth_m": _NUMBER, "hole_depth_m": _NUMBER,
         "block_position_m": _NUMBER, "hookload_N": _NUMBER, "torque_Nm": _NUMBER},
        ("t", "state", "bit_depth_m", "hookload_N", "torque_Nm")),
    "/truth/sensor": _schema(
        "truth.sensor",
        "the hook-load channel against the load on the hook at every true hook-load sample "
        "time: the block's motion (+1 hoisting, -1 lowering, 0 still), the sensor's factor on "
        "the load for that motion, its zero offset and its noise-free reading (only in "
        "sessions whose hook-load sensor does not read the load on the hook)",
        {"t": _TIME, "state": _STATES, "block_motion": {"type": "integer"},
         "factor": _NUMBER, "offset_N": _NUMBER, "hookload_N": _NUMBER, "reading_N": _NUMBER,
         "efficiency": _NUMBER, "block_weight_N": _NUMBER},
        ("t", "block_motion", "factor", "offset_N", "hookload_N", "reading_N")),
    "/truth/friction": _schema(
        "truth.friction",
        "uniform friction factors reproducing the true pick-up and slack-off hook load and the "
        "rotating torque at the bit depth; mean of the profile over the string in the hole",
        {"t": _TIME, "state": _STATES, "bit_depth_m": _NUMBER, "mu_pick_up": _OPTIONAL,
         "mu_slack_off": _OPTIONAL, "mu_rotating": _OPTIONAL, "mu_mean": _NUMBER},
        ("t", "state", "bit_depth_m", "mu_pick_up", "mu_slack_off", "mu_rotating", "mu_mean")),
    "/truth/profile": _schema(
        "truth.profile", "true friction factor (and annulus temperature) per hole element",
        {"t": _TIME, "md_m": _NUMBERS, "mu": _NUMBERS, "mu_base": _NUMBERS,
         "temperature_C": _NUMBERS},
        ("t", "md_m", "mu", "mu_base")),
    "/truth/alarm": _schema(
        "truth.alarm", "an alarm the daemon is expected to raise at about t",
        {"t": _TIME, "kind": _TEXT, "severity": {"enum": [s.value for s in Severity]},
         "message": _TEXT, "channel": {"type": ["string", "null"]}, "md_m": _OPTIONAL,
         "accept": {"type": "array", "items": _TEXT,
                    "description": "daemon alarm kinds that count as raising it"}},
        ("t", "kind", "severity", "message")),
    "/truth/model_error": _schema(
        "truth.model_error",
        "how the rig's true fluid and string differ from the well file the daemon reads",
        {"t": _TIME, "well": _TEXT, "density_factor": _NUMBER,
         "true_density_kg_m3": _NUMBER, "model_density_kg_m3": _NUMBER,
         "fill_level_m": _OPTIONAL, "string_extra_length_m": _NUMBER,
         "string_extra_component": _TEXT, "true_string_length_m": _NUMBER,
         "model_string_length_m": _NUMBER},
        ("t", "density_factor", "fill_level_m", "string_extra_length_m")),
    "/truth/weight": _schema(
        "truth.weight",
        "weight factor the injected model error implies: true over modelled buoyed string "
        "weight at the hook (static hook loads less the block), at every true hook-load sample "
        "time out of slips",
        {"t": _TIME, "state": _STATES, "bit_depth_m": _NUMBER, "weight_factor": _NUMBER},
        ("t", "state", "bit_depth_m", "weight_factor")),
    "/truth/fault": _schema(
        "truth.fault", "a sensor fault injected into the data (spike, stuck, dropout)",
        {"t": _TIME, "kind": {"enum": ["spike", "stuck", "dropout"]}, "channel": _TEXT,
         "until": _OPTIONAL},
        ("t", "kind", "channel")),
}


def payload_unit(channel: str) -> str:
    """The SI unit written in payloads of ``channel`` (a pint expression, e.g. ``N*m``)."""
    return CHANNEL_UNITS[channel][0]


def _ns(seconds: float) -> int:
    return round(seconds * 1e9)


def raw_input(topic: str, t: float | str, value: float, unit: str,
              receive_time: float) -> dict[str, Any]:
    """A ``/tdmon/raw`` message carrying one ``{"t", "value", "unit"}`` payload.

    ``t`` is Unix seconds (written to the millisecond) or an ISO 8601 string; ``value`` is
    written with 7 significant digits, about what a rig sensor resolves.
    """
    stamp: float | str = round(t, 3) if isinstance(t, float | int) else t
    payload = json.dumps({"t": stamp, "value": float(f"{value:.7g}"), "unit": unit},
                         separators=(",", ":"), allow_nan=False)
    return {"source": SOURCE, "topic": topic, "receive_time": round(receive_time, 3),
            "payload": payload, "payload_encoding": "utf-8"}


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _model_error(scenario: Scenario) -> dict[str, Any]:
    """The ``/truth/model_error`` message of a scenario with an injected model error."""
    paper = scenario.model_well
    assert paper is not None
    error = scenario.mismatch
    return {"t": scenario.start, "well": paper.name, "density_factor": error.density_factor,
            "true_density_kg_m3": scenario.well.fluid.density,
            "model_density_kg_m3": paper.fluid.density, "fill_level_m": error.fill_level,
            "string_extra_length_m": error.extra_length,
            "string_extra_component": paper.string.components[error.extra_component].name,
            "true_string_length_m": scenario.well.string.length,
            "model_string_length_m": paper.string.length}


def _sensor_fields(scenario: Scenario) -> dict[str, Any]:
    """The hook-load sensor's truth for ``/truth/scenario`` (nothing when the channel reads
    the load on the hook, as in sessions made before the sensor was modelled)."""
    measurement = scenario.measurement
    if not measurement.any:
        return {}
    sensor = measurement.sensor
    return {"hookload_sensor": {
        "location": str(sensor.location), "lines": sensor.lines,
        "efficiency": sensor.efficiency, "above_sensor_N": sensor.above_sensor,
        "offset_start_N": measurement.offset_start, "offset_end_N": measurement.offset_end}}


def _truth_sample_records(session: Session) -> list[MessageRecord]:
    """The truth at every true hook-load sample: ``/truth/load``, ``/truth/sensor`` (when the
    hook-load channel is not the load on the hook), and off the slips ``/truth/friction`` and
    ``/truth/weight`` (with an injected model error)."""
    scenario = session.scenario
    truth = session.truth
    records: list[MessageRecord] = []
    for k, t in enumerate(session.truth_t.tolist()):
        state = str(truth["state"][k])
        bit = float(truth["bit_depth"][k])
        records.append((_ns(t), "/truth/load", {
            "t": t, "state": state, "bit_depth_m": bit,
            "hole_depth_m": float(truth["hole_depth"][k]),
            "block_position_m": float(truth["block_position"][k]),
            "hookload_N": float(truth["hookload"][k]), "torque_Nm": float(truth["torque"][k])}))
        if "hookload_reading" in truth:
            motion = int(truth["block_motion"][k])
            sensor = scenario.measurement.sensor
            records.append((_ns(t), "/truth/sensor", {
                "t": t, "state": state, "block_motion": motion,
                "factor": sensor.factor(motion),
                "offset_N": float(truth["hookload_offset"][k]),
                "hookload_N": float(truth["hookload"][k]),
                "reading_N": float(truth["hookload_reading"][k]),
                # the joint estimate's parameters: the sheave efficiency and the travelling
                # equipment as the sensor weighs it
                "efficiency": sensor.efficiency,
                "block_weight_N": scenario.well.block_weight - sensor.above_sensor}))
        if state == RigState.IN_SLIPS:
            continue
        records.append((_ns(t), "/truth/friction", {
            "t": t, "state": state, "bit_depth_m": bit,
            "mu_pick_up": _finite_or_none(float(truth["mu_pick_up"][k])),
            "mu_slack_off": _finite_or_none(float(truth["mu_slack_off"][k])),
            "mu_rotating": _finite_or_none(float(truth["mu_rotating"][k])),
            "mu_mean": float(truth["mu_mean"][k])}))
        if "weight_factor" in truth:
            records.append((_ns(t), "/truth/weight", {
                "t": t, "state": state, "bit_depth_m": bit,
                "weight_factor": float(truth["weight_factor"][k])}))
    return records


def session_messages(session: Session) -> list[MessageRecord]:
    """Every message of a simulated session, in log-time order (inputs and truth)."""
    scenario = session.scenario
    start = scenario.start
    records: list[MessageRecord] = []
    records.append((_ns(start), "/truth/scenario", {
        "t": start, "name": scenario.name, "seed": scenario.seed, "well": scenario.well.name,
        "method": scenario.method, "prefix": scenario.prefix,
        "block_weight_N": scenario.well.block_weight,
        "duration_s": session.timeline.duration,
        "sample_interval_s": dict(scenario.sample_interval),
        **_sensor_fields(scenario)}))
    profile: dict[str, Any] = {"t": start, "md_m": session.profile_md.tolist(),
                               "mu": session.profile_mu.tolist(),
                               "mu_base": list(map(float, scenario.friction))}
    if session.profile_temperature is not None:
        profile["temperature_C"] = session.profile_temperature.tolist()
    records.append((_ns(start), "/truth/profile", profile))
    if scenario.model_well is not None:
        records.append((_ns(start), "/truth/model_error", _model_error(scenario)))

    for name, series in session.channels.items():
        topic = f"{scenario.prefix}/{name}"
        unit = payload_unit(name)
        for t, receive, value in zip(series.t, series.receive_time, series.value, strict=True):
            records.append((_ns(round(float(receive), 3)), RAW_TOPIC,
                            raw_input(topic, float(t), float(value), unit, float(receive))))

    timeline_at = session.timeline.at
    for t, changed_to in session.state_changes:
        where = timeline_at(np.asarray([t - start]))
        records.append((_ns(t), "/truth/state", {
            "t": t, "state": changed_to, "bit_depth_m": float(where.bit_depth[0]),
            "hole_depth_m": float(where.hole_depth[0])}))
    records += _truth_sample_records(session)
    for alarm in session.alarms:
        records.append((_ns(alarm.t), "/truth/alarm", {
            "t": alarm.t, "kind": alarm.kind, "severity": alarm.severity,
            "message": alarm.message, "channel": alarm.channel, "md_m": alarm.md,
            "accept": list(alarm.accept)}))
    for fault in session.faults:
        records.append((_ns(fault.t), "/truth/fault", {
            "t": fault.t, "kind": fault.kind, "channel": fault.channel, "until": fault.until}))
    # stable: at equal times the order above (truth of the sample before the sample) is kept
    records.sort(key=lambda record: record[0])
    return records


def write_mcap(path: str | os.PathLike[str], records: Iterable[MessageRecord],
               topics: Mapping[str, Mapping[str, Any]] | None = None, *,
               total: int | None = None, progress: bool = False,
               description: str = "writing") -> int:
    """Write messages to ``path`` through the project's recorder; returns how many.

    The file appears complete or not at all: it is written beside ``path`` and renamed, so a
    failed run never leaves a half file (and an existing ``path`` is replaced).

    Parameters
    ----------
    path : output file
    records : (log time [ns], topic, message), in the order they should replay
    topics : extra topics and their JSON Schemas (the daemon's own are always registered)
    total : number of records, for the progress bar
    progress : show a tqdm progress bar on stderr (only when it is a terminal)
    description : label of the progress bar

    Raises
    ------
    RecordError
        The file cannot be written or a message was not recorded.
    """
    target = Path(path)
    partial = target.with_name(f".{target.name}.partial")
    with contextlib.suppress(FileNotFoundError):
        partial.unlink()
    recorder = McapRecorder(path=partial, extra_topics=topics, flush_interval_s=3600.0,
                            background_flush=False, recover=False, min_free_bytes=1024 * 1024)
    count = 0
    try:
        bar: Iterator[MessageRecord] = iter(tqdm(
            records, total=total, desc=description, unit="msg", disable=not progress or None,
            leave=False))
        for log_time_ns, topic, message in bar:
            recorder.write(topic, log_time_ns, message)
            count += 1
            if recorder.error is not None:
                break
    except BaseException:
        # e.g. a bad cell in an import: no half file stays behind
        recorder.close()
        with contextlib.suppress(FileNotFoundError):
            partial.unlink()
        raise
    recorder.close()
    stats = recorder.stats
    error = recorder.error
    if error is not None or stats.lost or stats.untyped_topics:
        with contextlib.suppress(FileNotFoundError):
            partial.unlink()
        reason = str(error) if error else (
            f"{stats.lost} messages not recorded" if stats.lost
            else "a topic without a schema was written")
        raise RecordError(f"cannot write {target}: {reason}")
    try:
        os.replace(partial, target)
    except OSError as exc:
        raise RecordError(f"cannot write {target}: {exc.strerror or exc}") from exc
    return count


def simulate_to_mcap(scenario: Scenario, path: str | os.PathLike[str], *,
                     progress: bool = False) -> tuple[Session, int]:
    """Generate a session and write it to ``path``; returns the session and the message count.

    Raises
    ------
    ModelError
        The scenario cannot be simulated.
    RecordError
        The file cannot be written.
    """
    session = simulate_session(scenario)
    records = session_messages(session)
    count = write_mcap(path, records, TRUTH_SCHEMAS, total=len(records), progress=progress,
                       description="simulate")
    return session, count
