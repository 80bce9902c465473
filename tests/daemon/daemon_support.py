"""Helpers for daemon tests: an in-memory sink, a stand-in load model, a running daemon."""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections import defaultdict
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
from numpy.typing import NDArray

from tdmon.config.daemon import DaemonConfig, parse_daemon_config
from tdmon.daemon.build import Built, build_daemon
from tdmon.daemon.steps.monitor import GridLoadModel, LoadModel
from tdmon.daemon.supervisor import Backoff
from tdmon.record.sink import MessageSink

FAST_BACKOFF = Backoff(initial=0.1, maximum=0.5)
WELL_FILE = Path(__file__).resolve().parents[2] / "config" / "wells" / "aadnoy-example-7-1.toml"


def schema_validators(schemas: dict[str, Any]) -> dict[str, Any]:
    """A validator per topic: ``validators[topic].validate(message)`` is
    ``jsonschema.validate(message, schemas[topic])``, which checks the schema and builds its
    validator on every call (minutes over a whole recording); here each is done once."""
    validators: dict[str, Any] = {}
    for topic, schema in schemas.items():
        kind = jsonschema.validators.validator_for(schema)
        kind.check_schema(schema)
        validators[topic] = kind(schema)
    return validators


class CollectSink(MessageSink):
    """Keeps every message written, by topic (a stand-in for the recorder)."""

    def __init__(self) -> None:
        self.messages: dict[str, list[dict[str, Any]]] = defaultdict(list)
        self.order: list[str] = []
        self.closed = False

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        assert isinstance(log_time_ns, int)
        json.dumps(message, allow_nan=False)  # what a sink gets must be plain JSON
        self.messages[topic].append(message)
        self.order.append(topic)

    def close(self) -> None:
        self.closed = True

    def __getitem__(self, name: str) -> list[dict[str, Any]]:
        return self.messages[f"/tdmon/{name}"]


def _linear_curves(depths: NDArray[np.float64], mu: float) -> tuple[
        NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    weight = 300.0 * depths + 500e3  # [N]: 300 N/m of string plus the block
    return weight * (1 + mu), weight * (1 - mu), weight, 20.0 * depths * mu


def linear_model(mu: float = 0.25, band: tuple[float, ...] = (0.1, 0.2, 0.3)) -> GridLoadModel:
    """A stand-in model with simple closed-form curves (exact under linear interpolation)."""
    return GridLoadModel.from_function(_linear_curves, np.linspace(0, 5000, 51), mu, band)


def make_config(data: dict[str, Any], folder: Path | None = None) -> DaemonConfig:
    base = {"prefix": "rig/T1", "publish": {"status_interval": "0.2 s"},
            "channels": {"hookload": {"unit": "kN"}, "torque": {"unit": "kN*m"},
                         "bit_depth": {"unit": "m"}}}
    for key, value in data.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            base[key] = {**base[key], **value}
        else:
            base[key] = value
    return parse_daemon_config(base, (folder or Path.cwd()) / "test-daemon.toml")


async def wait_until(predicate: Callable[[], bool], timeout: float = 10.0,
                     what: str = "condition") -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        await asyncio.sleep(0.02)


@contextlib.asynccontextmanager
async def running(config: DaemonConfig, model: LoadModel | None = None,
                  sink: CollectSink | None = None, connected: tuple[str, ...] = (),
                  **kwargs: Any) -> AsyncIterator[tuple[Built, CollectSink]]:
    """Run a daemon in the background; stop it (and wait for its shutdown) on exit."""
    sink = sink or CollectSink()
    if model is None and config.well is None:
        model = linear_model()
    async with build_daemon(config, model=model, extra_sinks=[sink],
                            backoff=kwargs.pop("backoff", FAST_BACKOFF), **kwargs) as built:
        stop = asyncio.Event()
        task = asyncio.create_task(built.daemon.run(stop))
        try:
            await wait_until(lambda: all(built.daemon.connections.get(c) == "connected"
                                         for c in connected), 10, f"{connected} connected")
            yield built, sink
        finally:
            stop.set()
            await asyncio.wait_for(task, 30)


def payload(t: float, value: float, unit: str | None = None) -> bytes:
    body: dict[str, Any] = {"t": t, "value": value}
    if unit is not None:
        body["unit"] = unit
    return json.dumps(body).encode()
