"""Shared pieces of the replay tests: scenario files written on the fly and an MCAP reader."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

REPO = Path(__file__).resolve().parents[2]
SCENARIO_WELL = REPO / "replays" / "scenarios" / "wells" / "example-7-1-glydril.toml"
VOLVE_DATA = Path(__file__).resolve().parents[2] / "data" / "volve-f4"

#: Every rig state in a few minutes, no noise: static, circulating, rotating off bottom,
#: reaming (with a connection), drilling, back-reaming, pick-up and slack-off with connections.
ALL_STATES_PHASES = """
[[phase]]
kind = "static"
duration = "30 s"

[[phase]]
kind = "circulate"
duration = "30 s"
flow = "2000 L/min"

[[phase]]
kind = "rotate"
duration = "30 s"
rpm = "100 rpm"
flow = "2000 L/min"

[[phase]]
kind = "ream"
to = "4150 m"
speed = "0.25 m/s"
rpm = "60 rpm"
flow = "2000 L/min"
slips_time = "30 s"

[[phase]]
kind = "drill"
to = "4152 m"
rop = "36 m/h"
wob = "80 kN"
rpm = "100 rpm"
flow = "2000 L/min"

[[phase]]
kind = "back_ream"
to = "4140 m"
speed = "0.2 m/s"
rpm = "60 rpm"
flow = "2000 L/min"

[[phase]]
kind = "trip_out"
to = "4100 m"
speed = "0.5 m/s"
slips_time = "30 s"

[[phase]]
kind = "trip_in"
to = "4130 m"
speed = "0.5 m/s"
slips_time = "30 s"
"""


def scenario_toml(*, seed: int = 5, interval: str = "2 s", extra: str = "",
                  phases: str = ALL_STATES_PHASES, start: str = "2024-05-01T08:00:00Z",
                  bit_depth: str = "4100 m", hole_depth: str = "4150 m",
                  block_position: str = "30 m", friction: str = "") -> str:
    """A scenario file's text; ``extra`` adds tables (noise, faults, tight spots...)."""
    return f"""
[scenario]
name = "test"
well = "{SCENARIO_WELL.as_posix()}"
seed = {seed}
start = "{start}"
prefix = "sim/test"
bit_depth = "{bit_depth}"
hole_depth = "{hole_depth}"
block_position = "{block_position}"

{friction}

[sampling]
interval = "{interval}"

{extra}

{phases}
"""


@pytest.fixture
def write_scenario(tmp_path: Path) -> Callable[..., Path]:
    """Writes a scenario (see :func:`scenario_toml`) to a file and returns its path."""
    counter = iter(range(1000))

    def write(**kwargs: Any) -> Path:
        path = tmp_path / f"scenario-{next(counter)}.toml"
        path.write_text(scenario_toml(**kwargs))
        return path

    return write


@dataclass(frozen=True)
class Read:
    """One message read back: topic, log time [ns], raw bytes, decoded JSON, schema encoding."""

    topic: str
    log_time: int
    data: bytes
    message: dict[str, Any]
    schema_encoding: str
    schema: dict[str, Any]


def read_mcap(path: Path) -> list[Read]:
    """Every message of a finished MCAP file, in file order."""
    out: list[Read] = []
    with path.open("rb") as handle:
        reader = make_reader(handle)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert schema is not None
            out.append(Read(channel.topic, message.log_time, bytes(message.data),
                            json.loads(message.data), schema.encoding,
                            json.loads(schema.data)))
    return out


def payloads(messages: list[Read], prefix: str) -> dict[str, list[dict[str, Any]]]:
    """Input payloads per channel (``{"t", "value", "unit"}``) from ``/tdmon/raw`` messages."""
    channels: dict[str, list[dict[str, Any]]] = {}
    for read in messages:
        if read.topic != "/tdmon/raw":
            continue
        topic = read.message["topic"]
        assert topic.startswith(prefix + "/")
        channels.setdefault(topic[len(prefix) + 1:], []).append(
            json.loads(read.message["payload"]))
    return channels
