"""The synchronous heart of the daemon: raw message -> sinks -> decoder -> aligner -> steps.

Everything here runs on the event loop thread without awaiting, so a message is fully handled
(recorded, decoded, aligned, evaluated) before the next one is looked at, and the pipeline can
be driven by tests without any transport.

Plug-in points for other issues:

* a **sink** (:class:`tdmon.record.sink.Sink`: the MCAP recorder, Rerun, publishers) receives
  every message the daemon produces in :class:`~tdmon.record.batch.Batch` es of one topic
  (``/tdmon/<name>``): ``write_batch(batch)``, and ``close()`` once. A sink takes the topics
  in its ``topics`` (None: all); a message no sink takes is not even made, which matters for
  the per-message ``raw`` and ``sample`` dicts. Raw input and rejections reach every sink
  before any later step sees the sample; so do samples when messages come one at a time
  (``process``). The daemon hands queued messages over in bursts (``process_burst``): a
  burst's raw input is written before any of it is decoded, its samples after its last
  message's steps, each topic as one batch (docs/daemon.md, "Bursts").
* a **step** (rig state, monitor, back-calculation, alarms) sees each aligned frame in order:
  ``on_frame(frame, emit)`` and ``close(emit)``; ``emit(name, message)`` sends a result to all
  sinks and leaves it in ``frame.results[name]`` for the steps after it.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Protocol, runtime_checkable

from tdmon.daemon.clock import ClockGuard, ClockJump, JumpLog
from tdmon.daemon.loss import LossDetector
from tdmon.ingest.decode import Decoder
from tdmon.ingest.types import (
    RECORDED_PAYLOAD_BYTES,
    SAMPLE_ITEMS,
    RawMessage,
    Rejected,
    Sample,
    raw_items,
    rejected_message,
)
from tdmon.messages import alarm_message, status_message
from tdmon.record.batch import Batch
from tdmon.record.sink import Recorder, Sink
from tdmon.vocabulary import AlarmKind, RigState, Severity

__all__ = ["Emit", "Frame", "FrameSource", "Pipeline", "Sink", "Stats", "Step"]

log = logging.getLogger(__name__)

Emit = Callable[[str, dict[str, Any]], None]


@dataclass(slots=True)
class Frame:
    """The rig's channels aligned on one hook-load sample.

    ``values`` holds, per channel, the newest value at or before ``t`` that is not older than
    the stale timeout (SI units); ``ages`` how old each is [s]; ``stale`` the channels seen
    before but left out as too old. On the first frame after a silence of the hook load longer
    than the stale timeout, ``gap`` holds the channels that went stale in it (the hook load
    first) and when each did [s]; ``gap_reported`` says the daemon already raised its alarm
    while the silence lasted (live). Steps annotate ``state``/``steady`` and ``results``.
    """

    t: float
    log_time_ns: int
    values: dict[str, float]
    ages: dict[str, float]
    stale: tuple[str, ...] = ()
    gap: tuple[tuple[str, float], ...] = ()
    gap_reported: bool = False
    state: str = RigState.UNKNOWN
    steady: bool = False
    results: dict[str, dict[str, Any]] = field(default_factory=dict)


@runtime_checkable
class Step(Protocol):
    """One stage after alignment. Steps run in list order on every frame."""

    name: str

    def on_frame(self, frame: Frame, emit: Emit) -> None: ...

    def close(self, emit: Emit) -> None: ...


@dataclass(slots=True)
class Stats:
    """Counters reported in the status message; every loss or oddity has one."""

    messages_in: int = 0
    samples_in: int = 0
    rejected: int = 0
    dropped: int = 0
    duplicates: int = 0
    out_of_order: int = 0
    frames: int = 0
    step_errors: int = 0
    sink_errors: int = 0
    redelivered: int = 0
    """Messages the transport marked as sent again (MQTT DUP) that this run had not seen."""
    duplicate_deliveries: int = 0
    """Redelivered messages this run had already handed to the pipeline: not processed again."""
    seq_lost: int = 0
    """Messages missing from the publishers' ``seq`` counters."""
    sampling_gaps: int = 0
    """Silences much longer than a channel's usual sampling interval."""
    clock_jumps: int = 0
    last_sample_t: float | None = None
    rejected_reasons: dict[str, int] = field(default_factory=dict)

    def count_drop(self, n: int = 1) -> None:
        self.dropped += n


class FrameSource(Protocol):
    """What the pipeline needs from an aligner (see :class:`tdmon.daemon.aligner.Aligner`)."""

    duplicates: int
    out_of_order: int

    def push(self, sample: Sample, now: float) -> list[Frame]: ...

    def expire(self, now: float) -> list[Frame]: ...

    def flush(self) -> list[Frame]: ...

    def take_jumps(self) -> Sequence[ClockJump]:
        """The rig clock's jumps back seen since the last call."""
        ...

    def silence(self, now: float) -> tuple[tuple[str, float], ...]:
        """The channels that went stale in a silence of the whole stream, once per silence."""
        ...


@dataclass(slots=True)
class _HeldSamples:
    """The samples of a burst, whose ``sample`` messages go to the sinks at its end."""

    log_times: list[int]
    samples: list[Sample]


class Pipeline:
    """Decode, record, align and run the steps for each raw message."""

    def __init__(
        self,
        decoder: Decoder,
        aligner: FrameSource,
        steps: Sequence[Step] = (),
        sinks: Sequence[Sink] = (),
        stats: Stats | None = None,
        monotonic: Callable[[], float] = time.monotonic,
        clock: ClockGuard | None = None,
    ) -> None:
        self.decoder = decoder
        self.aligner = aligner
        # the rig clock against the receive time (docs/daemon.md, "Clock faults"); None: no
        # future check, as for a pipeline built by hand
        self.clock = clock
        self._jump_log = JumpLog()
        self.steps = list(steps)
        self.sinks = list(sinks)
        #: the sinks that are flight recorders (the daemon acknowledges input by their marks)
        self.recorders = [sink for sink in self.sinks if isinstance(sink, Recorder)]
        self.stats = stats or Stats()
        self._monotonic = monotonic
        self._closed = False
        self._routes: dict[str, list[Sink]] = {}
        # what the steps emit, by name: (topic, its sinks); cleared with _routes
        self._named_routes: dict[str, tuple[str, list[Sink]]] = {}
        # Payloads the decoder may accept are recorded whole (so they replay); longer ones,
        # which it rejects, as a bounded prefix with their size and hash.
        self._recorded_payload_bytes = max(RECORDED_PAYLOAD_BYTES, decoder.max_payload_bytes)
        self._raw_items = raw_items(self._recorded_payload_bytes)
        self.loss = LossDetector()
        # the log time [ns] of messages that belong to no input (status, what the steps emit
        # at the end, recorder alarms): the wall clock live, the latest input's time in a
        # replay (follow_input_time)
        self._now_ns: Callable[[], int] = time.time_ns
        self._input_ns = 0

    def follow_input_time(self) -> None:
        """Stamp messages that belong to no input with the time of the latest input message
        (its receive time as recorded) instead of the wall clock, and give the status that
        time: a replay's or an import's recording then spans the rig's time, not the seconds
        the run took (docs/recording.md). Before the first input: the wall clock."""
        self._now_ns = self._latest_input_ns

    def _latest_input_ns(self) -> int:
        return self._input_ns or time.time_ns()

    def now_ns(self) -> int:
        """The pipeline's clock [ns since the Unix epoch] (see :meth:`follow_input_time`)."""
        return self._now_ns()

    def add_sink(self, sink: Sink) -> None:
        self.sinks.append(sink)
        if isinstance(sink, Recorder):
            self.recorders.append(sink)
        self._routes.clear()
        self._named_routes.clear()

    def _sinks_for(self, topic: str) -> list[Sink]:
        route = self._routes.get(topic)
        if route is None:
            route = self._routes[topic] = [
                sink for sink in self.sinks if sink.topics is None or topic in sink.topics]
        return route

    def process(self, raw: RawMessage) -> Sample | Rejected:
        """Handle one message completely; returns what the decoder made of it."""
        routes = self._routes
        sinks = routes.get("/tdmon/raw")
        if sinks is None:
            sinks = self._sinks_for("/tdmon/raw")
        log_ns = int(raw.receive_time * 1e9)
        if sinks:
            # the input's time first: an alarm the write raises (a recorder's) carries it
            self._input_ns = log_ns
            self._write_batch(sinks, Batch("/tdmon/raw", (log_ns,), (raw,), self._raw_items))
        return self._process(raw, log_ns, None)

    def process_burst(self, raws: Sequence[RawMessage]) -> None:
        """Handle several messages completely, in order, as ``process`` does one by one, with
        their ``raw`` and ``sample`` messages handed to the sinks together: every raw input
        before the first is decoded, the samples after the last one's steps (one batch per
        topic; docs/daemon.md, "Bursts")."""
        if not raws:
            return
        sinks = self._sinks_for("/tdmon/raw")
        log_times = [int(raw.receive_time * 1e9) for raw in raws]
        if sinks:
            self._input_ns = log_times[0]
            self._write_batch(sinks, Batch("/tdmon/raw", log_times, raws, self._raw_items))
        held = _HeldSamples([], [])
        process = self._process
        try:
            for raw, log_ns in zip(raws, log_times, strict=True):
                process(raw, log_ns, held)
        finally:
            if held.samples:
                self._write_batch(self._sinks_for("/tdmon/sample"), Batch(
                    "/tdmon/sample", held.log_times, held.samples, SAMPLE_ITEMS))

    def _process(self, raw: RawMessage, log_ns: int, held: _HeldSamples | None
                 ) -> Sample | Rejected:
        """Everything after recording the raw input (``log_ns``: its log time); a sample
        message goes to ``held`` when given (a burst), else to the sinks at once."""
        # once per input message (a replay's whole cost is in here): routes, counters and the
        # loss detector's figures are read once, not through helper calls
        stats = self.stats
        stats.messages_in += 1
        self._input_ns = log_ns
        routes = self._routes
        decoded = self.decoder.decode(raw)
        if isinstance(decoded, Rejected):
            return self._reject(decoded, log_ns)
        jump: ClockJump | None = None
        if self.clock is not None:
            verdict = self.clock.check(decoded)
            if isinstance(verdict, str):
                return self._reject(Rejected(verdict, raw.payload, raw.source, raw.topic,
                                             raw.receive_time), log_ns)
            jump = verdict
        stats.samples_in += 1
        stats.last_sample_t = decoded.t
        sinks = routes.get("/tdmon/sample")
        if sinks is None:
            sinks = self._sinks_for("/tdmon/sample")
        if sinks:
            if held is None:
                self._write_batch(sinks, Batch("/tdmon/sample", (log_ns,), (decoded,),
                                               SAMPLE_ITEMS))
            else:
                held.log_times.append(log_ns)
                held.samples.append(decoded)
        self._align(decoded, jump, log_ns)
        return decoded

    def _align(self, decoded: Sample, jump: ClockJump | None, log_ns: int) -> None:
        """A recorded sample through the loss detector and the aligner, and the frames it
        completes through the steps."""
        stats, loss = self.stats, self.loss
        if jump is not None:
            loss.reanchor()
        for alarm in loss.observe(decoded):
            self._write("/tdmon/alarm", log_ns, alarm)
        stats.seq_lost = loss.seq_lost
        stats.sampling_gaps = loss.sampling_gaps
        if jump is not None:
            self._clock_jump(jump, log_ns)
        aligner = self.aligner
        frames = aligner.push(decoded, self._monotonic())
        stats.duplicates = aligner.duplicates
        stats.out_of_order = aligner.out_of_order
        for jump in aligner.take_jumps():
            if self.clock is not None:
                self.clock.reanchor(jump.offset)
            loss.reanchor()
            self._clock_jump(jump, log_ns)
        for frame in frames:
            self._run_steps(frame)

    def _reject(self, rejected: Rejected, log_ns: int) -> Rejected:
        stats = self.stats
        stats.rejected += 1
        # group by the reason's first words so a flood of distinct values stays small
        key = rejected.reason.split(":")[0].split("(")[0].strip()[:60]
        if key in stats.rejected_reasons or len(stats.rejected_reasons) < 64:
            stats.rejected_reasons[key] = stats.rejected_reasons.get(key, 0) + 1
        self._write("/tdmon/rejected", log_ns,
                    rejected_message(rejected, self._recorded_payload_bytes))
        return rejected

    def _clock_jump(self, jump: ClockJump, log_ns: int) -> None:
        """One alarm per clock jump and a rate-limited log line: never a silent stall."""
        self.stats.clock_jumps += 1
        if (line := self._jump_log.line(jump)) is not None:
            log.warning("%s", line)
        self._write("/tdmon/alarm", log_ns, alarm_message(
            jump.t, AlarmKind.CLOCK_JUMP, Severity.WARNING, jump.message, value=jump.seconds))

    def tick(self) -> None:
        """Emit a frame that has waited long enough for its other channels; raise the stale
        alarm of a silence of the whole stream while it lasts."""
        now = self._monotonic()
        for frame in self.aligner.expire(now):
            self._run_steps(frame)
        gone = self.aligner.silence(now)
        if gone:
            from tdmon.calib.alarms import stale_gap_alarm

            self._write("/tdmon/alarm", time.time_ns(), stale_gap_alarm(gone).to_message())

    def flush(self) -> None:
        """End of input: emit what the aligner holds and let each step finish (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for frame in self.aligner.flush():
            self._run_steps(frame)
        log_ns = self._now_ns()
        for alarm in self.loss.finish():  # seq jumps still held open: judged now
            self._write("/tdmon/alarm", log_ns, alarm)
        self.stats.seq_lost = self.loss.seq_lost
        for step in self.steps:
            try:
                step.close(self._emitter(log_ns, None))
            except Exception:
                self.stats.step_errors += 1
                log.exception("step %s failed while closing", step.name)

    def close_sinks(self) -> None:
        for sink in self.sinks:
            try:
                sink.close()
            except Exception:
                self.stats.sink_errors += 1
                log.exception("sink %r failed while closing", sink)

    def emit(self, name: str, message: dict[str, Any], log_time_ns: int | None = None) -> None:
        """Send a message that belongs to no frame (e.g. status) to every sink."""
        self._write(f"/tdmon/{name}", self._now_ns() if log_time_ns is None else log_time_ns,
                    message)

    def emit_status(self, connections: dict[str, str]) -> None:
        """Send the ``status`` message (a fleet's pipeline sends one per rig), and save what
        must survive a restart (:meth:`save_state`)."""
        self.emit("status", self.status_message(connections))
        self.save_state()

    def save_state(self) -> None:
        """Save what a restarted daemon goes on from: the loss detector's state, when it keeps
        one (the daemon calls it before acknowledging messages too)."""
        self.loss.save()

    def status_message(self, connections: dict[str, str], now: float | None = None
                       ) -> dict[str, Any]:
        """The periodic ``status`` message (docs/architecture.md)."""
        now = self._now_ns() / 1e9 if now is None else now
        stats = self.stats
        lag = 0.0 if stats.last_sample_t is None else max(0.0, now - stats.last_sample_t)
        return status_message(now, stats.samples_in, stats.rejected, stats.dropped, lag,
                              connections, messages_in=stats.messages_in,
                              duplicates=stats.duplicates, out_of_order=stats.out_of_order,
                              frames=stats.frames, redelivered=stats.redelivered,
                              duplicate_deliveries=stats.duplicate_deliveries,
                              seq_lost=stats.seq_lost, sampling_gaps=stats.sampling_gaps)

    def _sync_aligner_counts(self) -> None:
        self.stats.duplicates = self.aligner.duplicates
        self.stats.out_of_order = self.aligner.out_of_order

    def _run_steps(self, frame: Frame) -> None:
        self.stats.frames += 1
        emit = self._emitter(frame.log_time_ns, frame)
        for step in self.steps:
            try:
                step.on_frame(frame, emit)
            except Exception:
                # one bad frame must not stop monitoring; it is counted and logged loudly
                self.stats.step_errors += 1
                log.exception("step %s failed on frame t=%s", step.name, frame.t)

    def _emitter(self, log_time_ns: int, frame: Frame | None) -> Emit:
        return partial(self._emit_result, log_time_ns, frame)

    def _emit_result(self, log_time_ns: int, frame: Frame | None, name: str,
                     message: dict[str, Any]) -> None:
        """A step's ``emit``: the message to the frame's ``results`` (when there is a frame)
        and to the sinks of ``/tdmon/<name>``."""
        if frame is not None:
            frame.results[name] = message
        # twice per frame (state, model): the topic and its sinks from one lookup by name,
        # not an f-string and a route lookup per message (with the partial in place of a
        # closure per frame: 1.17 -> 0.85 us a frame of two messages, two sinks)
        route = self._named_routes.get(name)
        if route is None:
            topic = f"/tdmon/{name}"
            route = self._named_routes[name] = (topic, self._sinks_for(topic))
        self._write_to(route[1], route[0], log_time_ns, message)

    def _write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        self._write_to(self._sinks_for(topic), topic, log_time_ns, message)

    def _write_to(self, sinks: Sequence[Sink], topic: str, log_time_ns: int,
                  message: dict[str, Any]) -> None:
        if sinks:
            self._write_batch(sinks, Batch(topic, (log_time_ns,), (message,)))

    def _write_batch(self, sinks: Sequence[Sink], batch: Batch) -> None:
        """Hand ``batch`` to each of ``sinks``; one that raises is logged and counted."""
        for sink in sinks:
            try:
                sink.write_batch(batch)
            except Exception:
                self.stats.sink_errors += 1
                log.exception("sink %r failed writing %d message(s) on %s", sink, len(batch),
                              batch.topic)
