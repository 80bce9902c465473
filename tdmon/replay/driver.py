"""The replay driver: a recording through the daemon's own pipeline, into one flight recording.

There is no replay-specific processing: the driver takes the daemon configuration, swaps its
sources for one :class:`~tdmon.ingest.mcap_source.McapSource` on the replay, turns off
publishing and the folder recorder, and hands :func:`tdmon.daemon.build.build_daemon` three
extra sinks: the MCAP recorder in single-file mode (``--out``), Rerun (``--rrd``) and a
counting sink for the summary. The daemon stops by itself when the source is exhausted and
flushes the aligner and the steps, exactly as a live daemon does on SIGTERM.

Determinism: at ``speed=None`` (as fast as possible) the daemon's wall-clock housekeeping is
switched off for the run. In a live daemon (and in a paced replay) a hook-load frame that waits
longer than ``align.max_wait`` of wall time for its other channels is emitted by that
housekeeping tick; at full speed wall time says nothing about the data, and a tick landing
between two messages would make the frames, hence the estimates, depend on the machine's load.
Without it a frame is completed by the data alone (its channels, or the next hook load), so the
same file always gives the same estimates. The final status message is still written.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import math
import signal
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tdmon.config.daemon import (
    DaemonConfig,
    McapSourceConfig,
    PublishConfig,
    RecorderConfig,
    RerunConfig,
    SourcesConfig,
)
from tdmon.daemon.build import build_daemon
from tdmon.daemon.pipeline import Pipeline
from tdmon.daemon.runner import stop_on_signals
from tdmon.errors import IngestError, RecordError
from tdmon.record.batch import Batch
from tdmon.record.sink import MessageSink, Recorder, Sink
from tdmon.vocabulary import EstimateKind

__all__ = ["FULL_SPEED_GC_YOUNG", "ReplayResult", "SummarySink", "check_replay_file",
           "describe_start", "raw_message_count", "replay", "replay_config",
           "summarize_recording"]

#: Housekeeping period used at full speed [s]: long enough never to fire during a replay.
_NO_TICKS = 10 * 365 * 86400.0

#: Allocations between young-generation garbage collections at full speed (CPython's default
#: is 700). A replay allocates and frees a few dicts per message; at the default the collector
#: ran ~100 000 times per 3.3 h session and took 0.3-0.5 s of a ~3 s replay
#: (benchmarks/bench_replay.py). Restored when the replay ends.
FULL_SPEED_GC_YOUNG = 10_000


@contextlib.contextmanager
def _young_collections_every(allocations: int | None) -> Iterator[None]:
    if allocations is None:
        yield
        return
    previous = gc.get_threshold()
    gc.set_threshold(max(allocations, previous[0]), *previous[1:])
    try:
        yield
    finally:
        gc.set_threshold(*previous)


@dataclass
class ReplayResult:
    """What one replay did; ``summary()`` is the JSON the CLI prints."""

    input: Path
    out: Path
    rrd: Path | None
    messages_in: int = 0
    samples: int = 0
    rejected: int = 0
    dropped: int = 0
    frames: int = 0
    step_errors: int = 0
    sink_errors: int = 0
    windows: int = 0
    windows_rejected: int = 0
    estimates: dict[str, int] = field(default_factory=dict)
    alarms: dict[str, int] = field(default_factory=dict)
    state_shares: dict[str, float] = field(default_factory=dict)
    non_finite: int = 0
    wall_s: float = 0.0
    interrupted: bool = False
    """Stopped by SIGINT/SIGTERM before the end of the replay (the recording is finished and
    holds what was read up to then)."""

    @property
    def rate(self) -> float:
        """Input messages per second of wall time."""
        return self.messages_in / self.wall_s if self.wall_s > 0 else 0.0

    def summary(self) -> dict[str, Any]:
        return {
            "input": str(self.input), "out": str(self.out),
            "rrd": None if self.rrd is None else str(self.rrd),
            "messages_in": self.messages_in, "samples": self.samples,
            "rejected": self.rejected, "dropped": self.dropped, "frames": self.frames,
            "step_errors": self.step_errors, "sink_errors": self.sink_errors,
            "windows": self.windows, "windows_rejected": self.windows_rejected,
            "estimates": dict(sorted(self.estimates.items())),
            "alarms": dict(sorted(self.alarms.items())),
            "state_shares": dict(sorted(self.state_shares.items())),
            "non_finite": self.non_finite, "interrupted": self.interrupted,
            "wall_s": round(self.wall_s, 3), "rate_msg_per_s": round(self.rate, 1),
        }


class SummarySink(MessageSink):
    """Counts results for the summary: estimates and alarms per kind, rig-state time shares.

    Non-finite numbers are not looked for here: the recorder finds them anyway while encoding
    (``nonfinite_replaced``), and a second walk through every model message cost a tenth of
    the replay's time.
    """

    #: only results: raw input and samples are counted by the pipeline's own stats
    topics = frozenset({"/tdmon/state", "/tdmon/estimate", "/tdmon/alarm"})

    def __init__(self) -> None:
        self.estimates: Counter[str] = Counter()
        self.alarms: Counter[str] = Counter()
        self.state_time: dict[str, float] = {}
        self._state: tuple[str, float] | None = None

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        if topic == "/tdmon/state":
            # a state message is sent on a change and at least every second: time shares
            # come from the rig-time intervals between them
            t, state = float(message.get("t", math.nan)), str(message.get("state"))
            if self._state is not None and math.isfinite(t) and t > self._state[1]:
                previous = self._state[0]
                self.state_time[previous] = self.state_time.get(previous, 0.0) + t - self._state[1]
            if math.isfinite(t):
                self._state = (state, t)
        elif topic == "/tdmon/estimate":
            self.estimates[str(message.get("kind"))] += 1
        elif topic == "/tdmon/alarm":
            self.alarms[str(message.get("kind"))] += 1

    def shares(self) -> dict[str, float]:
        total = sum(self.state_time.values())
        if total <= 0:
            return {}
        return {state: round(seconds / total, 4) for state, seconds in self.state_time.items()}


class _ProgressSink(Sink):
    """Advances a progress callback every ``every`` input messages (counts batches: no
    message is made for it)."""

    topics = frozenset({"/tdmon/raw"})

    def __init__(self, advance: Callable[[int], None], every: int = 1000) -> None:
        self.advance = advance
        self.every = every
        self.count = 0

    def write_batch(self, batch: Batch) -> None:
        before, self.count = self.count, self.count + len(batch)
        passed = self.count // self.every - before // self.every
        if passed:
            self.advance(passed * self.every)

    def close(self) -> None:
        rest = self.count % self.every
        if rest:
            self.advance(rest)
            self.count -= rest  # closed twice (daemon, then driver): counted once


def describe_start(head: bytes) -> str:
    """What the first bytes of a file that is not MCAP look like, for the error line: the text
    (up to 24 characters, ``'time,hookload,...'``) when they are text, else their hex."""
    sample = head[:24]
    try:
        text = sample.decode("utf-8")
    except UnicodeDecodeError:
        text = ""
    if text and all(char.isprintable() or char in "\t\r\n" for char in text):
        shown = text.split("\n")[0].rstrip("\r")
        return repr(shown + ("..." if len(head) > len(shown) else ""))
    return "bytes " + sample[:8].hex(" ")


def _looks_like_csv(head: bytes) -> bool:
    first = head.split(b"\n", 1)[0]
    return any(separator in first for separator in (b",", b";", b"\t"))


def check_replay_file(path: str | Path) -> None:
    """Refuse, with one line naming the file, what cannot be replayed (before anything runs).

    Raises
    ------
    IngestError
        Missing file, a folder, an empty file, a file that is not MCAP (the line says what it
        starts with and, for text with separators, to import the CSV first), or an unfinished
        MCAP file (no footer: to be recovered first). Replaying any of these used to leave the
        daemon retrying the source for ever.
    """
    from tdmon.record.reader import MAGIC, describe_os_error, has_footer

    source = Path(path)
    try:
        with source.open("rb") as stream:
            head = stream.read(256)
            if not head:
                raise IngestError(f"{source}: empty file (0 bytes), not an MCAP file")
            if not head.startswith(MAGIC):
                hint = ("; for CSV use `tdmon import csv` (or `tdmon import volve`) first"
                        if _looks_like_csv(head) else
                        "; a replay is an MCAP file (tdmon simulate, tdmon import, or a "
                        "flight recording)")
                raise IngestError(f"{source}: not an MCAP file (starts with "
                                  f"{describe_start(head)}){hint}")
            finished = has_footer(stream)
    except FileNotFoundError as exc:
        raise IngestError(f"{source}: replay not found (no such file)") from exc
    except OSError as exc:
        raise IngestError(describe_os_error(source, exc)) from exc
    if not finished:
        raise IngestError(f"{source}: unfinished MCAP file (no footer: its writer was killed or "
                          f"the copy is cut short); run `tdmon recover {source}` first")


def raw_message_count(path: str | Path) -> int | None:
    """Input messages in a replay (from its summary; None when it has none)."""
    from tdmon.record.reader import topic_counts

    try:
        counts = topic_counts(path)
    except RecordError:
        return None
    if "/tdmon/raw" in counts:
        return counts["/tdmon/raw"]
    return sum(n for topic, n in counts.items() if not topic.startswith(("/tdmon/", "/truth/",
                                                                            "/reference/")))


def replay_config(config: DaemonConfig, path: Path, speed: float | None) -> DaemonConfig:
    """``config`` with the replay as its only source; no publishing, no folder recorder, no
    Rerun from the file (the driver adds its own single-file recorder and .rrd sink)."""
    mcap = McapSourceConfig(path=path.resolve(), speed="max" if speed is None else speed)
    return config.model_copy(update={
        "sources": SourcesConfig(mcap=mcap),
        "publish": PublishConfig(mqtt=False, zenoh=False, names=list(config.publish.names),
                                 status_interval=config.publish.status_interval),
        "recorder": RecorderConfig(enabled=False),
        "rerun": RerunConfig(mode="off"),
    })


async def replay(
    path: str | Path,
    config: DaemonConfig,
    out: str | Path,
    *,
    rrd: str | Path | None = None,
    speed: float | None = None,
    progress: Callable[[int], None] | None = None,
    extra_sinks: Sequence[Sink] = (),
    separate_writer: bool = False,
) -> ReplayResult:
    """Run ``path`` through the daemon built from ``config``; record everything to ``out``.

    Parameters
    ----------
    path : the replay (MCAP with ``/tdmon/raw`` input messages, or rig topics)
    config : the daemon configuration (prefix, channel map, well, calibration)
    out : the flight recording to write (replaced if it exists)
    rrd : a Rerun .rrd file to write as well
    speed : real time x ``speed``; None: as fast as the pipeline goes (deterministic)
    progress : called with the number of input messages handled since the last call
    extra_sinks : more sinks (tests)
    separate_writer : record from a child process
        (:class:`~tdmon.record.writer_process.RecorderProcess`: encoding and writing on a
        second core; at most ~5 % faster on a long session when a core is idle, ~25 % more
        CPU in all, and slower on a short replay, which pays the child's start-up); False (the
        default): in this process (:class:`McapRecorder`; figures in docs/benchmarks.md)

    Raises
    ------
    IngestError, RecordError, ConfigError
        The replay cannot be read (see :func:`check_replay_file`: checked before any output is
        created), an output cannot be written, the configuration is unusable.
    """
    from tdmon.record.mcap_recorder import McapRecorder
    from tdmon.record.writer_process import RecorderProcess

    source = Path(path)
    check_replay_file(source)
    out_path = Path(out)
    rrd_path = None if rrd is None else Path(rrd)
    if out_path.resolve() == source.resolve():
        raise RecordError(f"{out_path}: the output would replace the replay being read")
    run_config = replay_config(config, source, speed)
    pipeline: Pipeline | None = None

    def on_alarm(message: dict[str, Any]) -> None:
        if pipeline is not None:
            pipeline.emit("alarm", message)

    summary = SummarySink()
    sinks: list[Sink] = []
    recorder_type = RecorderProcess if separate_writer else McapRecorder
    recorder: Recorder = recorder_type(path=out_path, overwrite=True, on_alarm=on_alarm,
                                       flush_interval_s=5.0)
    sinks.append(recorder)
    try:
        if rrd_path is not None:
            from tdmon.record.rerun_views import RerunViews

            sinks.append(RerunViews(rrd_path))
        sinks.append(summary)
        if progress is not None:
            sinks.append(_ProgressSink(progress))
        sinks.extend(extra_sinks)
        started = time.perf_counter()
        stop, signals = asyncio.Event(), list[signal.Signals]()
        with (_young_collections_every(FULL_SPEED_GC_YOUNG if speed is None else None),
              stop_on_signals(stop, signals.append)):
            async with build_daemon(run_config, extra_sinks=sinks,
                                    stop_when_sources_done=True) as built:
                pipeline = built.pipeline
                # log times and the status in rig time: the recording spans the session
                pipeline.follow_input_time()
                if speed is None:
                    built.daemon.tick_interval = _NO_TICKS
                await built.daemon.run(stop)
        wall = time.perf_counter() - started
    finally:
        # idempotent: the daemon closed them unless building failed half-way
        for sink in sinks:
            sink.close()
    stats = built.stats
    result = ReplayResult(
        input=source, out=out_path, rrd=rrd_path, messages_in=stats.messages_in,
        samples=stats.samples_in, rejected=stats.rejected,
        # recorded nothing of it: as lost as a dropped publication
        dropped=stats.dropped + recorder.stats.lost,
        frames=stats.frames, step_errors=stats.step_errors, sink_errors=stats.sink_errors,
        estimates=dict(summary.estimates), alarms=dict(summary.alarms),
        state_shares=summary.shares(), wall_s=wall,
        non_finite=recorder.stats.nonfinite_replaced, interrupted=bool(signals),
    )
    result.windows = summary.estimates.get(EstimateKind.WINDOW, 0)
    for step in built.steps:
        rejected = getattr(step, "rejected", None)
        if isinstance(rejected, Counter):
            result.windows_rejected += sum(rejected.values())
    return result


def summarize_recording(path: str | Path) -> dict[str, Any]:
    """The replay summary's counts for any flight recording (e.g. a live daemon's): input
    messages, samples, rejections, estimates and alarms per kind, rig-state shares, and the
    engineer's numbers of :func:`tdmon.record.digest.digest` (docs/recording.md)."""
    from tdmon.record.digest import summarize
    from tdmon.record.reader import read_messages

    summary = SummarySink()
    counts: Counter[str] = Counter()
    for item in read_messages(path, allow_unfinished=True):
        counts[item.topic] += 1
        if item.topic in summary.topics:
            summary.write(item.topic, item.log_time_ns, item.message)
    return {
        "recording": str(path), "messages_in": counts["/tdmon/raw"],
        "samples": counts["/tdmon/sample"], "rejected": counts["/tdmon/rejected"],
        "windows": summary.estimates.get(EstimateKind.WINDOW, 0),
        "estimates": dict(sorted(summary.estimates.items())),
        "alarms": dict(sorted(summary.alarms.items())),
        "state_shares": dict(sorted(summary.shares().items())),
        # the engineer's numbers, as in tdmon replay --json
        **summarize([path], allow_unfinished=True),
    }
