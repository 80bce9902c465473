"""Units of at-least-once delivery and loss counting: when acknowledgements go, what the
daemon does with a recognised duplicate, the ``seq`` and sampling-gap rules, and the decoder
taking ``seq``."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable, Mapping
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest

from tdmon.daemon.daemon import AckWindow, Daemon, SourceSpec
from tdmon.daemon.loss import LossDetector
from tdmon.daemon.pipeline import Stats
from tdmon.errors import RecordError
from tdmon.ingest.decode import ChannelSpec, Decoder, parse_payload_seq
from tdmon.ingest.types import RawMessage, Sample
from tdmon.record.batch import Batch
from tdmon.record.sink import Recorder, RecorderStats


class FakeRecorder(Recorder):
    """Holds written messages in memory until flush() puts them 'in the file'; a flush asked
    for is done at once, as by the recorder in the daemon's process."""

    def __init__(self) -> None:
        self.buffer: list[Any] = []
        self.file: list[Any] = []
        self.written = self.durable = self.flushes = 0
        self.failed = False

    @property
    def error(self) -> RecordError | None:
        return RecordError("failed") if self.failed else None

    @property
    def path(self) -> Path | None:
        return None

    @property
    def stats(self) -> RecorderStats:
        return RecorderStats(written=self.written, flushes=self.flushes)

    def register_topic(self, topic: str, schema: Mapping[str, Any]) -> None:
        pass

    def retry(self) -> bool:
        return not self.failed

    def write_batch(self, batch: Batch) -> None:
        self.buffer += [message["payload"] for message in batch.messages()]
        self.written += len(batch)

    def flush(self) -> None:
        self.file += self.buffer
        self.buffer.clear()
        self.flushes += 1
        self.durable = self.written

    def durable_mark(self) -> int:
        return self.written

    def is_durable(self, mark: int) -> bool:
        return self.durable >= mark or self.failed

    def request_flush(self) -> None:
        self.flush()

    def close(self) -> None:
        self.flush()


class FarRecorder(FakeRecorder):
    """A recorder in another process: flushes asked for and done later (``settle``), never
    waited for."""

    def __init__(self) -> None:
        super().__init__()
        self.asked: list[int] = []

    def request_flush(self) -> None:
        self.asked.append(self.written)

    def settle(self) -> None:  # the other process flushed what it had been sent
        self.flush()


def _arrivals(recorder: FakeRecorder, window: AckWindow, acked: list[int]
              ) -> Callable[[int, float], None]:
    def arrive(i: int, now: float) -> None:
        recorder.write("/tdmon/raw", 0, {"payload": i})
        window.add([lambda: acked.append(i)], now=now)
    return arrive


def test_acks_wait_for_the_recorders_flush() -> None:
    recorder = FakeRecorder()
    window = AckWindow([recorder], batch=5, idle_s=0.05, idle_min=3, max_age_s=5.0)
    acked: list[int] = []
    arrive = _arrivals(recorder, window, acked)
    arrive(0, 0.0)
    arrive(1, 0.0)
    window.release(now=0.01, idle=0.01)
    assert acked == [] and len(window) == 2  # marked, not flushed yet
    arrive(99, 0.02)  # written after that look
    recorder.flush()  # the recorder's own schedule
    window.release(now=0.03, idle=0.0)
    assert acked == [0, 1]  # 99 was in the flush, but is marked only at the next look
    window.release(now=0.04, idle=0.0)
    assert acked == [0, 1]  # looks at most every check_s
    window.release(now=0.1, idle=0.0)
    assert acked == [0, 1, 99] and len(window) == 0 and window.forced_flushes == 0
    acked.remove(99)
    # idle with too few waiting: nothing; with idle_min waiting: a flush, and they go
    arrive(2, 1.0)
    arrive(3, 1.0)
    window.release(now=1.1, idle=1.0)
    assert acked == [0, 1]
    arrive(4, 1.1)
    window.release(now=1.2, idle=0.06)
    assert acked == [0, 1, 2, 3, 4] and window.forced_flushes == 1
    # a full batch goes at once; an old one goes once it has waited max_age_s
    for i in range(5, 10):
        arrive(i, 2.0)
    window.release(now=2.0, idle=0.0)
    assert acked[-5:] == [5, 6, 7, 8, 9]
    arrive(10, 3.0)
    window.release(now=7.9, idle=0.0)
    assert acked[-1] == 9
    window.release(now=8.0, idle=0.0)
    assert acked[-1] == 10 and recorder.file == [0, 1, 99, *range(2, 11)]


def test_acks_wait_for_a_recorder_in_another_process_without_waiting_on_it() -> None:
    recorder = FarRecorder()
    window = AckWindow([recorder], batch=5, idle_s=0.05, idle_min=3, max_age_s=5.0,
                       check_s=0.05)
    acked: list[int] = []
    arrive = _arrivals(recorder, window, acked)
    arrive(0, 0.0)
    arrive(1, 0.0)
    window.release(now=0.01, idle=0.0)  # a mark of the two; nothing asked, nothing acked
    assert acked == [] and recorder.asked == []
    arrive(2, 0.02)
    recorder.settle()  # its own schedule: all three are in the file now
    window.release(now=0.03, idle=0.0)
    assert acked == [0, 1]  # the third was written before the flush, but marked after it
    window.release(now=0.1, idle=0.0)  # marked now, and in the file already
    assert acked == [0, 1, 2] and len(window) == 0
    # a full batch: a flush is asked for, nothing is waited for, the acks go once it is done
    for i in range(3, 8):
        arrive(i, 1.0)
    window.release(now=1.0, idle=0.0)
    assert recorder.asked == [8] and acked == [0, 1, 2] and window.forced_flushes == 1
    window.release(now=1.01, idle=0.0)
    assert acked == [0, 1, 2]
    recorder.settle()
    window.release(now=1.02, idle=0.0)
    assert acked == list(range(8))
    # a failed recorder holds nothing back (its loss is alarmed and counted)
    arrive(8, 2.0)
    recorder.failed = True
    window.release(now=2.1, idle=0.0)
    assert acked == list(range(9))
    # shutdown: flushed and acknowledged at once
    recorder.failed = False
    arrive(9, 3.0)
    window.release(now=3.0, idle=0.0, force=True)
    assert acked == list(range(10)) and recorder.file[-1] == 9


def test_a_recorder_added_later_is_waited_for() -> None:
    # a fleet's rigs appear while the daemon runs: the window reads the growing list
    first, later = FarRecorder(), FarRecorder()
    recorders: list[Recorder] = [first]
    window = AckWindow(recorders, check_s=0.05)
    acked: list[int] = []
    _arrivals(first, window, acked)(0, 0.0)
    recorders.append(later)
    _arrivals(later, window, acked)(1, 0.0)
    window.release(now=0.1, idle=0.0)
    first.settle()
    window.release(now=0.2, idle=0.0)
    assert acked == []  # the later recorder has not flushed its message yet
    later.settle()
    window.release(now=0.3, idle=0.0)
    assert acked == [0, 1]


def test_without_a_recorder_acks_go_after_processing() -> None:
    acked: list[int] = []
    window = AckWindow([])
    window.add([lambda: acked.append(1)], now=0.0)
    assert acked == [1] and window.acknowledged == 1


class FakePipeline:
    def __init__(self, recorder: FakeRecorder) -> None:
        self.sinks = [recorder]
        self.recorders = [recorder]
        self.stats = Stats()
        self.processed: list[bytes] = []
        self.recorder = recorder

    def process(self, raw: RawMessage) -> None:
        self.processed.append(raw.payload)
        self.recorder.write("/tdmon/raw", 0, {"payload": raw.payload})

    def process_burst(self, raws: list[RawMessage]) -> None:
        for raw in raws:
            self.process(raw)

    def tick(self) -> None:
        pass

    def emit(self, name: str, message: dict[str, Any]) -> None:
        pass

    def status_message(self, connections: dict[str, str]) -> dict[str, Any]:
        return {}

    def emit_status(self, connections: dict[str, str]) -> None:
        pass

    def save_state(self) -> None:
        pass

    def flush(self) -> None:
        pass

    def close_sinks(self) -> None:
        for sink in self.sinks:
            sink.close()


async def test_daemon_skips_a_recognised_duplicate_and_acks_everything_once_recorded() -> None:
    recorder = FakeRecorder()
    pipeline = FakePipeline(recorder)
    acked: list[bytes] = []
    recorded_when_acked: list[bool] = []

    def ack_for(payload: bytes) -> Any:
        def ack() -> None:
            acked.append(payload)
            recorded_when_acked.append(payload in recorder.file)
        return ack

    messages = [
        RawMessage("mqtt", "rig/a", b"1", 0.0, ack_for(b"1")),
        RawMessage("mqtt", "rig/a", b"2", 0.0, ack_for(b"2")),
        RawMessage("mqtt", "rig/a", b"1", 0.0, ack_for(b"1"), True, True),  # recognised
        RawMessage("mqtt", "rig/a", b"3", 0.0, ack_for(b"3"), True, False),  # after a crash
    ]

    @asynccontextmanager
    async def source() -> AsyncIterator[AsyncIterator[RawMessage]]:
        async def gen() -> AsyncIterator[RawMessage]:
            for message in messages:
                yield message
        yield gen()

    daemon = Daemon(pipeline, [SourceSpec("mqtt", source, finite=True)],  # type: ignore[arg-type]
                    stop_when_sources_done=True, status_interval=10.0)
    await asyncio.wait_for(daemon.run(), 10)
    assert pipeline.processed == [b"1", b"2", b"3"]
    assert pipeline.stats.duplicate_deliveries == 1 and pipeline.stats.redelivered == 1
    assert sorted(acked) == [b"1", b"1", b"2", b"3"]
    assert all(recorded_when_acked)  # never acknowledged before it was in the file


def _sample(topic: str, t: float, seq: int | None = None) -> Sample:
    return Sample(topic.rsplit("/", 1)[-1], t, 1.0, "mqtt", topic, "N", t, seq)


def test_seq_gaps_are_counted_restarts_and_repeats_are_not() -> None:
    loss = LossDetector()
    alarms = []
    for index, seq in enumerate([1, 2, 3, 7, 8, 8, 6, 9, 1, 2, 4]):
        alarms += loss.observe(_sample("rig/a/torque", float(index), seq))
    # 3 -> 7: 4, 5, 6 held open; 8 again: ignored; 6 late, within the hold: not lost;
    # 9 -> 1: a restart, so 4 and 5 are judged lost now; 2 -> 4: 3 held open
    seq_alarms = [a for a in alarms if "never arrived" in a["message"]]
    assert [a["value"] for a in seq_alarms] == [2]
    assert seq_alarms[0]["message"] == "2 message(s) on rig/a/torque never arrived (seq 3 -> 7)"
    assert loss.seq_late == 1
    # the end of the input judges what is still held open
    seq_alarms += loss.finish()
    assert [a["value"] for a in seq_alarms] == [2, 1]
    assert loss.seq_lost == 3 and loss.seq_gaps == 2
    assert all(a["kind"] == "data_loss" and a["severity"] == "warning" for a in seq_alarms)
    # per topic: another topic's counter is its own
    assert loss.observe(_sample("rig/a/hookload", 100.0, 50)) == []


def test_newer_messages_before_the_backlog_are_not_a_loss() -> None:
    """Fault 4 of issue 32: after a broker restart mosquitto delivered a topic's newer messages
    (here 601-900) before its backlog (1-600), 0.5 s of rig time apart each."""
    loss = LossDetector()
    alarms = []
    order = [*range(601, 901), *range(1, 601)]
    for index, seq in enumerate(order):
        alarms += loss.observe(_sample("rig/a/hookload", 1000.0 + seq * 0.5 + index * 1e-3, seq))
    alarms += loss.finish()
    assert alarms == [] and loss.seq_lost == 0
    assert loss.seq_late == 0  # 1-600 came before any number after them: nothing was missing


def test_a_backlog_after_newer_messages_fills_the_held_jump() -> None:
    loss = LossDetector()
    alarms = []
    order = [*range(1, 101), *range(201, 261), *range(101, 201), *range(261, 400)]
    for index, seq in enumerate(order):
        alarms += loss.observe(_sample("rig/a/hookload", 1000.0 + index * 0.05, seq))
    alarms += loss.finish()
    assert alarms == [] and loss.seq_lost == 0 and loss.seq_late == 100


def test_what_the_hold_does_not_bring_is_lost_and_alarmed_at_its_end() -> None:
    loss = LossDetector(hold=30.0)
    t = 0.0
    for seq in [*range(1, 11), *range(21, 31)]:  # 11-20 never come
        t += 1.0
        assert loss.observe(_sample("rig/a/hookload", t, seq)) == []
    for seq in [15, 16]:  # two come late, within the hold
        t += 1.0
        assert loss.observe(_sample("rig/a/torque", t, seq)) == []
        assert loss.observe(_sample("rig/a/hookload", t, seq)) == []
    # the jump was seen at t = 11 s: rig time 41 s ends the hold (another topic's sample too)
    assert loss.observe(_sample("rig/a/torque", 40.9, 17)) == []
    alarms = loss.observe(_sample("rig/a/torque", 41.0, 18))
    assert [(a["t"], a["value"]) for a in alarms] == [(41.0, 8)]
    assert alarms[0]["message"] == ("8 message(s) on rig/a/hookload never arrived "
                                    "(seq 10 -> 21)")
    assert loss.seq_lost == 8 and loss.seq_late == 2
    # a number that comes after its jump was judged is not counted again
    late = loss.observe(_sample("rig/a/hookload", 42.0, 11))
    assert not [a for a in late if "never arrived" in a["message"]] and loss.seq_lost == 8
    assert loss.finish() == []


def test_a_sampling_gap_is_one_alarm_per_gap() -> None:
    loss = LossDetector()
    t = 0.0
    alarms = []
    for _ in range(40):
        t += 0.1
        alarms += loss.observe(_sample("rig/a/hookload", t))
    assert alarms == []
    t += 5.0  # 50 intervals missing
    alarms += loss.observe(_sample("rig/a/hookload", t))
    for _ in range(5):
        t += 0.1
        alarms += loss.observe(_sample("rig/a/hookload", t))
    t += 1.5  # 15 x the interval but shorter than 2 s: not a gap
    alarms += loss.observe(_sample("rig/a/hookload", t))
    assert len(alarms) == 1 and loss.sampling_gaps == 1
    assert alarms[0]["value"] == 49  # about 5.0 / 0.1 - 1 samples
    assert "no hookload samples for 5.0 s" in alarms[0]["message"]


@pytest.mark.parametrize("jump", [3600.0, -3600.0])
def test_a_held_seq_jump_keeps_its_hold_over_a_clock_jump(jump: float) -> None:
    loss = LossDetector(hold=30.0)
    for t, seq in [(1.0, 1), (2.0, 5)]:  # 2-4 held open until t = 32 s
        loss.observe(_sample("rig/a/torque", t, seq))
    loss.reanchor()
    assert loss.observe(_sample("rig/a/torque", 3.0 + jump, 6)) == []
    assert loss.observe(_sample("rig/a/torque", 31.9 + jump, 7)) == []
    alarms = loss.observe(_sample("rig/a/torque", 33.0 + jump, 8))
    assert [a["value"] for a in alarms] == [3] and loss.seq_lost == 3


@pytest.mark.parametrize("jump", [3600.0, -3600.0])
def test_a_clock_jump_is_neither_a_gap_nor_a_blind_spot(jump: float) -> None:
    loss = LossDetector()
    t = 0.0
    for _ in range(40):
        t += 0.5
        assert loss.observe(_sample("rig/a/hookload", t)) == []
    loss.reanchor()  # the pipeline calls this when the rig clock jumps
    t += jump
    assert loss.observe(_sample("rig/a/hookload", t)) == []  # not 3600 s of missing samples
    for _ in range(5):
        t += 0.5
        loss.observe(_sample("rig/a/hookload", t))
    t += 10.0  # a real gap on the new clock is still seen (after a jump back too)
    alarms = loss.observe(_sample("rig/a/hookload", t))
    assert [a["value"] for a in alarms] == [19] and loss.sampling_gaps == 1


def test_decoder_takes_seq_and_never_rejects_for_it() -> None:
    assert parse_payload_seq(b'{"t": 1.7e9, "value": 1, "seq": 12}') == (1.7e9, 1.0, None, 12)
    for bad in (b'"x"', b"-1", b"1.5", b"true", b"null"):
        parsed = parse_payload_seq(b'{"t": 1.7e9, "value": 1, "seq": %s}' % bad)
        assert parsed == (1.7e9, 1.0, None, None)
    decoder = Decoder("rig", [ChannelSpec("hookload", "hookload", "kN")])
    sample = decoder.decode(RawMessage("mqtt", "rig/hookload",
                                       b'{"t": 1.7e9, "value": 2, "seq": 3}', 0.0))
    assert isinstance(sample, Sample) and sample.seq == 3 and sample.value == 2000.0
