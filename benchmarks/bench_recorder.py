"""Benchmark of the MCAP flight recorder (and, for scale, the Rerun views).

Run: ``.venv/bin/python benchmarks/bench_recorder.py [--seconds 3600] [--repeat 3]``

Measures, on the synthetic stream of tdmon.record.synthetic (every topic, ~8 messages per
second of data, of which 3 raw + 3 sample per second of input):

1. the recorder alone: messages/s written, file bytes per message and per input sample, both
   with the flush of a replay at full speed (one flush per wall-clock second) and with the
   flush a live rig gives (one flush per second of *data*, i.e. a chunk of ~8 messages);
2. the recorder's cost inside a pipeline: a stand-in loop (JSON decode of each raw payload,
   latest-value alignment, a small numpy "model" evaluation per frame, building the output
   messages) timed without a sink and with the recorder as its sink (kept for comparison
   with earlier figures; item 4 is the real measure);
3. the Rerun views built from the same stream (messages/s), for scale;
4. the recorder's cost in the daemon itself: a recording (default the bundled simulated trip
   out with its daemon config) replayed flat out through ``build_daemon``'s pipeline (MCAP
   source, no publishing), with and without the folder recorder of ``[recorder]`` (in a child
   process and in the daemon's, ``--process``), runs alternated in one invocation; throughput
   ratio and bytes per input sample. Twice: with the
   config as given (calibration on) and with calibration off (rig state and monitor only, the
   cheapest pipeline, where the recorder weighs most).

Best of ``--repeat`` runs (item 4 also prints the median of each round's own share, with and
without the recorder a few seconds apart, and the recorder's cost in us per input sample); the
machine is shared, so expect noise of 10-20 %. OpenBLAS is held
to one thread unless OPENBLAS_NUM_THREADS says otherwise: its threads make the calibration's
small matrix products 5-16 x slower on a busy 2-core machine, which would drown the recorder.
"""

from __future__ import annotations

import os

# before numpy is imported (see the module docstring)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import asyncio
import json
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tdmon.config.daemon import (
    DaemonConfig,
    McapSourceConfig,
    PublishConfig,
    RecorderConfig,
    RerunConfig,
    SourcesConfig,
    load_daemon_config,
)
from tdmon.record.batch import Batch
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import RecordedMessage
from tdmon.record.sink import Sink as RecordSink
from tdmon.record.synthetic import synthetic_messages

ROOT = Path(__file__).resolve().parents[1]
#: the daemon replays this housekeeping-free (tdmon.replay.driver does the same at full speed)
_NO_TICKS = 10 * 365 * 86400.0

Sink = Callable[[str, int, dict[str, Any]], None]


def best_of(repeat: int, run: Callable[[], float]) -> float:
    return min(run() for _ in range(repeat))


def recorder_alone(stream: list[RecordedMessage], live_flush: bool) -> tuple[float, int]:
    """Seconds to write the stream, and the file size [bytes]."""
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        with McapRecorder(folder, recover=False) as recorder:
            last_second = stream[0].log_time_ns // 10**9
            for topic, log_time_ns, message in stream:
                if live_flush and log_time_ns // 10**9 != last_second:
                    # At a rig's pace the 1 s flush cuts a chunk per second of data.
                    recorder.flush()
                    last_second = log_time_ns // 10**9
                recorder.write(topic, log_time_ns, message)
        elapsed = time.perf_counter() - start
        size = sum(path.stat().st_size for path in recorder.stats.files)
    return elapsed, size


class StandIn:
    """A stand-in for the daemon's per-message work (not the daemon: see module docstring)."""

    def __init__(self) -> None:
        self.latest: dict[str, float] = {}
        # A 1000-element string on a J well: enough numpy per frame to resemble a soft-string
        # evaluation of the band (five friction factors), which the daemon does per frame.
        self.md = np.linspace(0.0, 3000.0, 1000)
        inclination = np.radians(np.clip((self.md - 500.0) / 10.0, 0.0, 60.0))
        self.axial = 250.0 * np.gradient(self.md) * np.cos(inclination)
        self.normal = 250.0 * np.gradient(self.md) * np.sin(inclination)

    def run(self, stream: list[RecordedMessage], sink: Sink | None) -> float:
        start = time.perf_counter()
        for topic, log_time_ns, message in stream:
            if topic != "/tdmon/raw":
                continue
            if sink is not None:
                sink("/tdmon/raw", log_time_ns, message)
            decoded = json.loads(message["payload"])
            channel = message["topic"].rsplit("/", 1)[-1]
            value = float(decoded["value"])
            self.latest[channel] = value
            sample = {"channel": channel, "t": decoded["t"], "value": value,
                      "unit": decoded["unit"], "source": "mqtt", "topic": message["topic"]}
            if sink is not None:
                sink("/tdmon/sample", log_time_ns, sample)
            if channel == "bit_depth":
                self._frame(decoded["t"], log_time_ns, value, sink)
        return time.perf_counter() - start

    def _frame(self, t: float, log_time_ns: int, bit_depth: float, sink: Sink | None) -> None:
        inside = self.md <= bit_depth
        axial, normal = self.axial[inside][::-1], self.normal[inside][::-1]
        band = [300e3 + float(np.cumsum(axial + mu * normal)[-1]) for mu in (0.1, 0.2, 0.3, 0.4)]
        buoyed = float(np.cumsum(axial)[-1])
        measured = self.latest.get("hookload", float("nan"))
        model = {
            "t": t, "bit_depth_m": bit_depth,
            "hookload_N": {"pick_up": band[1], "slack_off": 2 * buoyed - band[1],
                           "rotating": 300e3 + buoyed},
            "torque_Nm": {"rotating": 6e3 + bit_depth},
            "band": {"mu": [0.1, 0.2, 0.3, 0.4], "pick_up_N": band, "slack_off_N": band},
            "measured": {"hookload_N": measured, "torque_Nm": self.latest.get("torque")},
            "residual": {"hookload_N": measured - band[1], "torque_Nm": 0.0},
        }
        state = {"t": t, "state": "pick_up", "steady": True, "bit_depth_m": bit_depth}
        if sink is not None:
            sink("/tdmon/state", log_time_ns, state)
            sink("/tdmon/model", log_time_ns, model)


def pipeline_cost(stream: list[RecordedMessage], repeat: int) -> tuple[float, float, int]:
    """Seconds of the stand-in without a sink, with the recorder, and inputs processed."""
    inputs = sum(1 for m in stream if m.topic == "/tdmon/raw")
    bare = best_of(repeat, lambda: StandIn().run(stream, None))

    def with_recorder() -> float:
        with tempfile.TemporaryDirectory() as folder:
            recorder = McapRecorder(folder, recover=False)
            try:
                return StandIn().run(stream, recorder.write)
            finally:
                recorder.close()

    recorded = best_of(repeat, with_recorder)
    return bare, recorded, inputs


def rerun_views(stream: list[RecordedMessage]) -> float:
    from tdmon.record.rerun_views import build_rrd

    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        build_rrd(stream, Path(folder) / "views.rrd")
        return time.perf_counter() - start


class NullSink(RecordSink):
    """Takes every message, makes it and does nothing else: the raw/sample messages are
    otherwise not made when no sink wants them, so this separates that cost from the
    recorder's own."""

    def write_batch(self, batch: Batch) -> None:
        batch.messages()


class BareWriter(RecordSink):
    """The floor of recording in the daemon's process: each message encoded with orjson and
    handed to foxglove-sdk's MCAP writer (zstd level 1 in 1 MiB chunks, as the recorder), and
    nothing else: no queue, counters, check for NaN, flushes, rotation or failure handling."""

    def __init__(self, path: Path) -> None:
        import orjson
        from foxglove import Context, open_mcap
        from foxglove.mcap import MCAPCompression, MCAPWriteOptions

        self._dumps = orjson.dumps
        self._context = Context()
        self._writer = open_mcap(path, context=self._context, writer_options=MCAPWriteOptions(
            compression=MCAPCompression.Zstd, compression_level=1, compression_threads=0,
            chunk_size=1024 * 1024))
        self._logs: dict[str, Any] = {}

    def _log(self, topic: str) -> Any:
        log = self._logs.get(topic)
        if log is None:
            from foxglove import Channel, Schema

            schema = Schema(name=topic, encoding="jsonschema", data=b"{}")
            log = self._logs[topic] = Channel(topic, schema=schema, message_encoding="json",
                                              context=self._context).base.log
        return log

    def write_batch(self, batch: Batch) -> None:
        log = self._log(batch.topic)
        for data, log_time_ns in zip(map(self._dumps, batch.messages()), batch.log_times_ns,
                                     strict=True):
            log(data, log_time_ns)

    def close(self) -> None:
        self._writer.close()


def daemon_replay(recording: Path, config: DaemonConfig, folder: Path | None,
                  null_sink: bool = False, bare_writer: Path | None = None,
                  process: str = "inline") -> tuple[float, float, int, int]:
    """Replay ``recording`` flat out through the daemon built from ``config``; with a recorder
    in ``folder`` (None: no recorder; ``process``: its ``[recorder] process``, ``inline`` or
    ``child``), a do-nothing sink (``null_sink``) or a `BareWriter` to ``bare_writer``.
    Returns wall seconds, CPU seconds of this process (all its threads: the recorder's
    flusher too; not the child's), input samples, recorded bytes."""
    from tdmon.daemon.build import build_daemon
    from tdmon.daemon.runner import collections_for_a_stream

    run_config = config.model_copy(update={
        "sources": SourcesConfig(mcap=McapSourceConfig(path=recording, speed="max")),
        "publish": PublishConfig(),
        "recorder": RecorderConfig(enabled=folder is not None,
                                   output=folder or Path("unused"),
                                   flush_interval=config.recorder.flush_interval,
                                   process=process),
        "rerun": RerunConfig(),
    })

    async def run() -> tuple[float, float, int]:
        extra: list[Any] = [NullSink()] if null_sink else []
        if bare_writer is not None:
            extra.append(BareWriter(bare_writer))
        async with build_daemon(run_config, stop_when_sources_done=True,
                                extra_sinks=extra) as built:
            built.daemon.tick_interval = _NO_TICKS  # no wall-clock frames: same work each run
            start = time.perf_counter()  # the model's start-up sweep is not the recorder's
            cpu = time.process_time()
            # the garbage collector as `tdmon run` sets it while the daemon runs
            with collections_for_a_stream():
                await built.daemon.run(asyncio.Event())
            return (time.perf_counter() - start, time.process_time() - cpu,
                    built.stats.samples_in)

    elapsed, cpu, samples = asyncio.run(run())
    size = 0 if folder is None else sum(p.stat().st_size for p in folder.glob("*.mcap"))
    return elapsed, cpu, samples, size


def daemon_cost(recording: Path, config: DaemonConfig, repeat: int, label: str,
                places: tuple[str, ...] = ("child", "inline")) -> dict[str, Any]:
    """Best of ``repeat`` alternated runs without and with the recorder (in each of
    ``places``: ``[recorder] process``); prints a line per place.

    Wall time is the figure; CPU time of the process (best of the runs too) is printed beside
    it because on a shared machine it is the steadier of the two (for the child recorder it
    leaves out the child's, which runs on the other core)."""
    bare: list[tuple[float, float]] = []
    null: list[tuple[float, float]] = []
    recorded: dict[str, list[tuple[float, float]]] = {place: [] for place in places}
    floor: list[tuple[float, float]] = []
    samples = size = 0
    daemon_replay(recording, config, None)  # a first run pays the imports and caches: not timed
    for _ in range(repeat):
        elapsed, cpu, samples, _ = daemon_replay(recording, config, None)
        bare.append((elapsed, cpu))
        elapsed, cpu, samples, _ = daemon_replay(recording, config, None, null_sink=True)
        null.append((elapsed, cpu))
        for place in places:
            with tempfile.TemporaryDirectory() as folder:
                elapsed, cpu, samples, size = daemon_replay(recording, config, Path(folder),
                                                            process=place)
            recorded[place].append((elapsed, cpu))
        with tempfile.TemporaryDirectory() as folder:
            elapsed, cpu, samples, _ = daemon_replay(recording, config, None,
                                                     bare_writer=Path(folder) / "bare.mcap")
        floor.append((elapsed, cpu))

    def rate(runs: list[tuple[float, float]], which: int) -> float:
        return samples / min(run[which] for run in runs)

    fast, with_messages = rate(bare, 0), rate(null, 0)
    bare_writer = rate(floor, 0)
    floor_cost = 1.0 - bare_writer / fast
    print(f"daemon replay, {label} ({samples} samples): {fast:,.0f} samples/s without the "
          f"recorder, {with_messages:,.0f} with a do-nothing sink taking every message; "
          f"a bare orjson + foxglove writer in the daemon's process (the floor of recording "
          f"there): {bare_writer:,.0f} samples/s, {floor_cost * 100:.1f} %, "
          f"{(1.0 / bare_writer - 1.0 / fast) * 1e6:.1f} us per input sample; "
          f"{size / samples:.1f} B per input sample, all topics")
    figures: dict[str, Any] = {
        "samples": samples, "bare_samples_per_s": fast,
        "null_sink_samples_per_s": with_messages, "bare_writer_samples_per_s": bare_writer,
        "bare_writer_cost": floor_cost, "bytes_per_sample": size / samples}
    for place, runs in recorded.items():
        slow = rate(runs, 0)
        cost = 1.0 - slow / fast
        cpu_cost = 1.0 - rate(runs, 1) / rate(bare, 1)
        # the same in absolute terms: what each input sample costs more with the recorder
        per_sample_us = (1.0 / slow - 1.0 / fast) * 1e6
        # each round's own share (its run with the recorder against its run without, a few
        # seconds apart): their median is less at the mercy of one lucky run than the best-of
        paired = statistics.median(1.0 - off[0] / on[0] for off, on in zip(bare, runs,
                                                                            strict=True))
        print(f"  recorder {place:6s}: {slow:,.0f} samples/s; it costs {cost * 100:.1f} % of "
              f"the throughput (CPU time of the daemon's process: {cpu_cost * 100:.1f} %; "
              f"median of the rounds' own {paired * 100:.1f} %; target <= 15 %), "
              f"{per_sample_us:.1f} us per input sample")
        figures[place] = {"recorded_samples_per_s": slow, "cost": cost, "cpu_cost": cpu_cost,
                          "paired_cost_median": paired, "recorder_us_per_sample": per_sample_us}
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=int, default=3600, help="seconds of synthetic data")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-rerun", action="store_true")
    parser.add_argument("--recording", type=Path,
                        default=ROOT / "replays" / "trip-out-tight-spot.mcap",
                        help="recording replayed through the daemon (item 4)")
    parser.add_argument("--config", type=Path,
                        default=ROOT / "config" / "daemon" / "replay-sim-trip-out.toml",
                        help="daemon config for it (its source, publishing, recorder and "
                             "Rerun settings are replaced)")
    parser.add_argument("--daemon-only", action="store_true", help="only item 4")
    parser.add_argument("--process", choices=("both", "child", "inline"), default="both",
                        help="item 4: the recorder in a child process ([recorder] process = "
                             "'child', what 'auto' picks on two cores or more), in the "
                             "daemon's own ('inline'), or both in the same rounds")
    parser.add_argument("--json", type=Path, help="write the daemon figures here")
    args = parser.parse_args()

    config = load_daemon_config(args.config)
    places = ("child", "inline") if args.process == "both" else (args.process,)
    figures = {"calibration_on": daemon_cost(args.recording.resolve(), config, args.repeat,
                                             "calibration as configured", places)}
    if config.calibration.enabled:
        monitor_only = config.model_copy(update={
            "calibration": config.calibration.model_copy(update={"enabled": False})})
        figures["monitor_only"] = daemon_cost(args.recording.resolve(), monitor_only,
                                              args.repeat, "rig state and monitor only", places)
    if args.json is not None:
        args.json.write_text(json.dumps(figures, indent=2) + "\n")
    if args.daemon_only:
        return

    stream = list(synthetic_messages(duration_s=args.seconds))
    messages = len(stream)
    samples = sum(1 for m in stream if m.topic == "/tdmon/sample")
    print(f"stream: {messages} messages ({samples} input samples), {args.seconds} s of data")

    modes = (("replay-pace flush (1 s wall)", False), ("rig-pace flush (1 s data)", True))
    for label, live in modes:
        runs = [recorder_alone(stream, live) for _ in range(args.repeat)]
        elapsed = min(r[0] for r in runs)
        size = runs[0][1]
        print(f"recorder alone, {label}: {messages / elapsed:,.0f} msg/s, "
              f"{size / messages:.1f} B/message, {size / samples:.1f} B/input sample "
              f"(all topics), {size / args.seconds / 1e3:.2f} kB per second of data")

    bare, recorded, inputs = pipeline_cost(stream, args.repeat)
    print(f"stand-in pipeline (NOT the daemon): {inputs / bare:,.0f} inputs/s bare, "
          f"{inputs / recorded:,.0f} inputs/s with the recorder; recorder cost "
          f"{(recorded - bare) / bare * 100:.0f} % of the stand-in's time, "
          f"{(recorded - bare) / inputs * 1e6:.1f} us per input")

    if not args.no_rerun:
        elapsed = rerun_views(stream)
        print(f"Rerun views (.rrd): {messages / elapsed:,.0f} msg/s")


if __name__ == "__main__":
    main()
