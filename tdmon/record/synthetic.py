"""A synthetic message stream of every recorded topic, for tests, benchmarks and demos.

Not physics: plausible numbers of the right shapes (a J-shaped well, a trip out then a trip in,
a broomstick band widening with depth, friction estimates near 0.25) so that the recorder, the
Rerun views and the report can be exercised before the daemon exists. The real replays in
replays/ replace it once the daemon records them.
"""

from __future__ import annotations

import base64
import json
import math
import random
from collections.abc import Iterator
from typing import Any, Final

from tdmon.messages import alarm_message, estimate_message, status_message
from tdmon.record.reader import RecordedMessage
from tdmon.vocabulary import (
    OPERATION_FOR_STATE,
    AlarmKind,
    ConnectionState,
    EstimateKind,
    Operation,
    RigState,
    Severity,
)

T0_NS: Final = 1_475_600_400 * 10**9  # 2016-10-04 17:00 UTC, a Volve-era date
T0: Final = T0_NS / 1e9
BAND_MU: Final = (0.1, 0.2, 0.3, 0.4)
TRUE_MU: Final = 0.25
BLOCK_N: Final = 300e3
BUOYED_WEIGHT_N_PER_M: Final = 250.0
_CHANNELS: Final = (("hookload", "N"), ("torque", "N m"), ("bit_depth", "m"))


def well_message(t: float, total_md: float = 3000.0, step: float = 30.0) -> dict[str, Any]:
    """Vertical to 500 m, build 3 deg/30 m to 60 deg, then hold; tangent integration."""
    md, tvd, north, east = [0.0], [0.0], [0.0], [0.0]
    azimuth = math.radians(40.0)
    steps = round(total_md / step)
    for i in range(1, steps + 1):
        depth = i * step
        inclination = math.radians(min(60.0, max(0.0, (depth - 500.0) / 30.0 * 3.0)))
        md.append(depth)
        tvd.append(tvd[-1] + step * math.cos(inclination))
        horizontal = step * math.sin(inclination)
        north.append(north[-1] + horizontal * math.cos(azimuth))
        east.append(east[-1] + horizontal * math.sin(azimuth))
    return {"t": t, "name": "synthetic J well", "md_m": md, "tvd_m": tvd, "north_m": north,
            "east_m": east}


def profile_message(t: float, well: dict[str, Any]) -> dict[str, Any]:
    """Temperature along MD from a 30 degC/km gradient, local friction wavy around TRUE_MU."""
    md = well["md_m"]
    temperature = [15.0 + 0.03 * tvd for tvd in well["tvd_m"]]
    mu = [TRUE_MU + 0.05 * math.sin(depth / 400.0) for depth in md]
    mu_std = [0.02 + 0.01 * depth / md[-1] for depth in md]
    return {"t": t, "md_m": md, "temperature_C": temperature, "mu": mu, "mu_std": mu_std}


def _loads(bit_depth: float, mu: float) -> tuple[float, float, float, float]:
    weight = BUOYED_WEIGHT_N_PER_M * bit_depth
    drag = 0.9 * mu * weight
    pick_up = BLOCK_N + weight + drag
    slack_off = BLOCK_N + weight - drag
    rotating = BLOCK_N + weight
    torque = 6.0e3 + 4.0 * mu * bit_depth
    return pick_up, slack_off, rotating, torque


def _bit_depth(second: int, duration: int) -> tuple[float, RigState]:
    half = duration / 2
    if second < half:
        return 3000.0 - 1000.0 * second / half, RigState.PICK_UP
    return 2000.0 + 1000.0 * (second - half) / half, RigState.SLACK_OFF


def synthetic_messages(duration_s: int = 600, seed: int = 1) -> Iterator[RecordedMessage]:
    """About 12 messages per second of every topic, in log-time order (1 s frames)."""
    rng = random.Random(seed)
    well = well_message(T0)
    yield RecordedMessage("/tdmon/well", T0_NS, well)
    yield RecordedMessage("/tdmon/profile", T0_NS, profile_message(T0, well))
    for second in range(duration_s):
        t = T0 + second
        ns = T0_NS + second * 10**9
        bit_depth, state = _bit_depth(second, duration_s)
        operation = OPERATION_FOR_STATE[state].value
        pick_up, slack_off, rotating, torque = _loads(bit_depth, TRUE_MU)
        measured_hookload = ((pick_up if operation == Operation.PICK_UP else slack_off)
                             + rng.gauss(0, 2e3))
        measured_torque = torque + rng.gauss(0, 100.0)
        values = (measured_hookload, measured_torque, bit_depth)
        for (channel, unit), value in zip(_CHANNELS, values, strict=True):
            topic = f"rig/F4/{channel}"
            payload = json.dumps({"t": t, "value": value, "unit": unit})
            yield RecordedMessage("/tdmon/raw", ns, {
                "source": "mqtt", "topic": topic, "receive_time": t + 0.05,
                "payload": payload, "payload_encoding": "utf-8"})
            yield RecordedMessage("/tdmon/sample", ns, {
                "channel": channel, "t": t, "value": value, "unit": unit, "source": "mqtt",
                "topic": topic})
        yield RecordedMessage("/tdmon/state", ns, {
            "t": t, "state": state.value, "steady": second % 90 > 5, "bit_depth_m": bit_depth})
        band = [_loads(bit_depth, mu) for mu in BAND_MU]
        modelled = pick_up if operation == Operation.PICK_UP else slack_off
        yield RecordedMessage("/tdmon/model", ns, {
            "t": t, "bit_depth_m": bit_depth,
            "hookload_N": {"pick_up": pick_up, "slack_off": slack_off, "rotating": rotating},
            "torque_Nm": {"rotating": torque},
            "band": {"mu": list(BAND_MU), "pick_up_N": [b[0] for b in band],
                     "slack_off_N": [b[1] for b in band]},
            "measured": {"hookload_N": measured_hookload, "torque_Nm": measured_torque},
            "residual": {"hookload_N": measured_hookload - modelled,
                         "torque_Nm": measured_torque - torque}})
        if second % 30 == 29:
            yield RecordedMessage("/tdmon/estimate", ns, estimate_message(
                t, EstimateKind.WINDOW, operation, TRUE_MU + rng.gauss(0, 0.02), 0.02,
                bit_depth_m=bit_depth))
        if second % 60 == 59:
            yield RecordedMessage("/tdmon/status", ns, status_message(
                t, 3 * (second + 1), second // 100, 0, 0.05,
                {"mqtt": ConnectionState.CONNECTED}))
        if second % 100 == 50:
            bad = b"\xff{not json"
            yield RecordedMessage("/tdmon/rejected", ns, {
                "reason": "invalid JSON", "source": "mqtt", "topic": "rig/F4/hookload",
                "receive_time": t, "payload": base64.b64encode(bad).decode(),
                "payload_encoding": "base64"})
        if second % 200 == 120:
            yield RecordedMessage("/tdmon/alarm", ns, alarm_message(
                t, AlarmKind.BAND, Severity.WARNING,
                f"hook load {measured_hookload / 1e3:.0f} kN above the band", measured_hookload,
                pick_up))
    t_end = T0 + duration_s
    # the daemon's mu_T estimate (tdmon.calib.mu_calibration): a linear law a + b T fitted
    # over 40..100 degC, identifiable
    yield RecordedMessage("/tdmon/estimate", T0_NS + duration_s * 10**9, {
        "t": t_end, "kind": EstimateKind.MU_T.value, "operation": Operation.PICK_UP.value,
        "mu": 0.18 + 0.001 * 70.0, "mu_std": 0.004, "model": "mu = 0.18 + 0.001 T",
        "params": {"a": 0.18, "b": 0.001}, "params_std": {"a": 0.01, "b": 0.0002},
        "mu_at_temperature_C": 70.0, "temperature_C": [40.0, 100.0],
        "slope_per_K": 0.001, "slope_std_per_K": 0.0002,
        "slope_interval_per_K": [0.001 - 1.96 * 0.0002, 0.001 + 1.96 * 0.0002],
        "identifiable": True,
        "identifiability": "slope 0.001 1/K, 95 % interval 0.000608..0.00139, over 60.0 K"})
    profile = profile_message(t_end, well)
    yield RecordedMessage("/tdmon/estimate", T0_NS + duration_s * 10**9, {
        "t": t_end, "kind": EstimateKind.PROFILE.value, "operation": Operation.PICK_UP.value,
        "mu": TRUE_MU, "mu_std": 0.03,
        "md_m": profile["md_m"], "mu_profile": profile["mu"],
        "mu_profile_std": profile["mu_std"]})
