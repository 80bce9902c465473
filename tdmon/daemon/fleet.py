"""One daemon, many rigs: one pipeline per rig behind one transport session.

A fleet daemon file (``[[rigs]]`` and/or ``[fleet]``, docs/daemon.md "Many rigs") names a root
``prefix``; the sources subscribe once to everything under it and :class:`FleetPipeline` routes
each message by its topic to the rig it belongs to. Each rig is a plain single-rig
:class:`~tdmon.daemon.pipeline.Pipeline` built from ``config.for_rig(...)`` (the same decoder,
aligner and steps as ``tdmon run`` with one rig), with its sinks wired from the single-rig
tables (:data:`~tdmon.daemon.sinks.SINKS`, :data:`~tdmon.daemon.sinks.PUBLISHERS`): its own
recorder (its own folder: each rig's recording replays on its own), publishing on
``<rig prefix>/tdmon/<name>``.

Shared between rigs: the sources (one Zenoh session and subscription, or one MQTT
connection), the publishers' sessions, the compiled kernels (per process anyway) and what is
read from a well file: rigs with the same well file and ``[monitor]`` settings share the
``Well`` and the precomputed load grid (:class:`WellCache`).

:class:`FleetPipeline` offers what :class:`~tdmon.daemon.daemon.Daemon` needs of a pipeline
(``process``, ``tick``, ``flush``, ``emit_status``, ``close_sinks``, ``recorders``,
``stats``), so supervision, backpressure, acknowledgements and shutdown are the single-rig
daemon's own.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import math
import re
import time
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tdmon.config.daemon import DaemonConfig, RigConfig
from tdmon.config.rig_names import DEFAULT_NAME_PATTERN, name_refusal, printable
from tdmon.config.well_file import WellFile, read_well_file
from tdmon.daemon.build import Built, assemble_pipeline, rig_steps
from tdmon.daemon.daemon import Daemon
from tdmon.daemon.pipeline import Pipeline, Sink, Stats
from tdmon.daemon.sinks import PUBLISHERS, SINKS
from tdmon.daemon.sources import SOURCES
from tdmon.daemon.steps.monitor import LoadModel
from tdmon.daemon.supervisor import Backoff
from tdmon.daemon.wiring import Wiring, wire
from tdmon.errors import TdmonError
from tdmon.ingest.decode import parse_payload
from tdmon.ingest.loss_state import LOSS_STATE_FILE
from tdmon.ingest.types import RawMessage
from tdmon.record.sink import Recorder

log = logging.getLogger(__name__)

#: Routed topics remembered (a topic is looked up once); past this the memory starts afresh,
#: so that a flood of stray topics cannot grow it without bound.
MAX_ROUTES = 100_000
#: Topics longer than this are looked up every time, never remembered [characters].
MAX_REMEMBERED_TOPIC = 256
#: Names of rigs that could not be built (no well file), remembered so that each is logged
#: once; past this the memory starts afresh (each name is at most 64 characters).
MAX_UNBUILDABLE = 10_000
#: At most one log line per this many seconds about refused rig names [s].
REFUSAL_LOG_INTERVAL = 60.0
#: How often silent rigs are looked for [s].
IDLE_CHECK_INTERVAL = 1.0

#: The per-rig counters summed into the fleet's when it stops (``tdmon run``'s last line).
SUMMED = ("messages_in", "samples_in", "rejected", "dropped", "duplicates", "out_of_order",
          "frames", "step_errors", "sink_errors", "seq_lost", "sampling_gaps", "clock_jumps")


def rig_folder_name(prefix: str) -> str:
    """The recording folder (and file name prefix) of rig ``prefix``: "rig/F4" -> "rig_F4"."""
    return prefix.replace("/", "_")


def keep_loss_state(pipeline: Pipeline, config: DaemonConfig, live: bool) -> None:
    """As for one rig (``build_daemon``): a rig with a recorder on a live source keeps its loss
    state beside its own recordings, so its counting goes on across the daemon's restarts and
    its own retirement (``config``: the rig's, ``DaemonConfig.for_rig``)."""
    if config.recorder.enabled and live:
        pipeline.loss.keep_state(config.resolve(config.recorder.output)
                                 / rig_folder_name(config.prefix) / LOSS_STATE_FILE)


class WellCache:
    """Well files and load grids read once per process, shared by the rigs that use them.

    The ``Well`` is keyed by the resolved path, the load grid by the path and the
    ``[monitor]`` settings it was computed with (both are read-only once built).
    """

    def __init__(self) -> None:
        self._files: dict[Path, WellFile] = {}
        self._models: dict[tuple[Path, str], LoadModel] = {}

    def well_file(self, config: DaemonConfig) -> WellFile | None:
        if config.well is None:
            return None
        path = config.resolve(config.well).resolve()
        cached = self._files.get(path)
        if cached is None:
            cached = read_well_file(config)
            assert cached is not None
            self._files[path] = cached
        return cached

    def model(self, config: DaemonConfig, well_file: WellFile | None) -> LoadModel | None:
        if well_file is None:
            return None
        key = (well_file.path.resolve(), config.monitor.model_dump_json())
        cached = self._models.get(key)
        if cached is None:
            from tdmon.daemon.wellmodel import grid_model_for_well

            cached = grid_model_for_well(config, well_file.well)
            self._models[key] = cached
        return cached

    @property
    def wells_read(self) -> int:
        return len(self._files)


@dataclass
class Rig:
    """One rig of the fleet: its prefix, configuration and pipeline; ``owned`` are the sinks
    only this rig writes to (closed when a silent rig is retired)."""

    prefix: str
    config: DaemonConfig
    pipeline: Pipeline
    owned: Sequence[Sink] = ()
    last_message: float = field(default_factory=time.monotonic)


class FleetPipeline:
    """Route each message to its rig's pipeline; rigs listed in the file exist from the start,
    rigs found under ``[fleet]`` appear with their first valid message.

    ``make_rig(prefix, rig)`` builds a rig's pipeline (``rig``: its ``[[rigs]]`` entry, None
    for a rig found by topic); it returns None when the rig cannot run (no well file for the
    calibration), whose messages are then counted in ``unrouted``.

    What anyone who can publish could otherwise exhaust is bounded (docs/fleet.md, "Rig
    names"): a found rig's name must meet the rule of :mod:`tdmon.config.rig_names`, its first
    message must be a sample on a channel topic, at most ``max_rigs`` exist at once, and a
    found rig silent for ``idle_rig_timeout`` is retired and its slot freed. Refused names
    are counted in ``refusals`` (by reason), never kept.
    """

    def __init__(self, config: DaemonConfig,
                 make_rig: Callable[[str, RigConfig | None], Rig | None],
                 stats: Stats | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.root = config.prefix
        self.listed = {rig.prefix: rig for rig in config.rigs}
        fleet = config.fleet
        self.discover = fleet is not None and fleet.discover
        self.max_rigs = fleet.max_rigs if fleet is not None else len(self.listed)
        self.name_pattern = re.compile(DEFAULT_NAME_PATTERN if fleet is None
                                       else fleet.name_pattern)
        self.idle_timeout = math.inf if fleet is None else fleet.idle_rig_timeout
        self.channel_topics = frozenset(spec.topic for spec in config.channel_specs())
        self.make_rig = make_rig
        self.clock = clock
        #: every rig's flight recorders, for the daemon's acknowledgements (grows with rigs)
        self.recorders: list[Recorder] = []
        self.stats = stats or Stats()
        self.rigs: dict[str, Rig] = {}
        self._rig_of: dict[Pipeline, Rig] = {}
        #: names of rigs that could not be built (bounded: MAX_UNBUILDABLE)
        self.refused: set[str] = set()
        #: refused rig names and first messages, by reason (counted, never kept)
        self.refusals: dict[str, int] = {}
        #: found rigs retired after a silence
        self.retired = 0
        self.unrouted = 0
        self._routes: dict[str, Pipeline | None] = {}
        self._retired_counts = Stats()
        self._last_refusal_log = -math.inf
        self._next_idle_check = clock() + IDLE_CHECK_INTERVAL
        self._closed = False
        try:
            for prefix, rig in self.listed.items():
                self._add(prefix, rig, found=False)
        except BaseException:
            self.close_sinks()  # the rigs built so far: the daemon will not
            raise

    def _add(self, prefix: str, rig: RigConfig | None, found: bool = True) -> Pipeline | None:
        """Build rig ``prefix``. A rig listed in the file that cannot be built stops the
        daemon at start; one found by topic is refused with one log line, the others go on."""
        if prefix in self.refused:
            return None
        try:
            built = self.make_rig(prefix, rig)
        except (TdmonError, OSError, ValueError) as exc:
            # a found rig's folder or file that cannot be made refuses that rig, not the daemon
            if not found:
                raise
            log.error("rig %s ignored: %s", prefix, printable(str(exc), 200))
            built = None
        if built is None:
            if len(self.refused) >= MAX_UNBUILDABLE:
                self.refused.clear()
            self.refused.add(prefix)
            return None
        self.rigs[prefix] = built
        self._rig_of[built.pipeline] = built
        self.recorders.extend(built.pipeline.recorders)
        # What a rig keeps for its life (well model, filters, recorder) goes to the permanent
        # generation: a full collection then scans only what came after. Without it, building
        # rigs grows the tracked heap until full collections take 0.15-0.25 s each (measured
        # with 50 rigs), a stall every rig's messages wait through.
        gc.freeze()
        log.info("rig %s: monitoring (%d rig%s)", prefix, len(self.rigs),
                 "" if len(self.rigs) == 1 else "s")
        return built.pipeline

    def _route(self, topic: str, payload: bytes | None = None) -> Pipeline | None:
        """The pipeline of the rig ``topic`` belongs to; None for results (``tdmon/``), for
        topics of no rig, and for a rig not found yet whose first message ``payload`` is not
        a valid sample."""
        return self._resolve(topic, payload)[0]

    def _resolve(self, topic: str, payload: bytes | None) -> tuple[Pipeline | None, bool]:
        """``_route``'s answer and whether it holds for the topic's next messages too."""
        root = self.root
        if not topic.startswith(root + "/"):
            return None, True
        prefix = max((p for p in self.listed if topic.startswith(p + "/")), key=len,
                     default=None)
        if prefix is None:
            if not self.discover:
                return None, True
            name, _, rest = topic[len(root) + 1:].partition("/")
            if not rest or name == "tdmon":
                return None, True
            refusal = name_refusal(name, self.name_pattern)
            if refusal is not None:
                self._refuse(refusal, name)
                return None, True
            prefix = f"{root}/{name}"
        rest = topic[len(prefix) + 1:]
        if rest.startswith("tdmon/"):
            return None, True  # results of this or another daemon: not input
        rig = self.rigs.get(prefix)
        if rig is not None:
            return rig.pipeline, True
        if len(self.rigs) >= self.max_rigs:
            # remembered until a slot is freed (the memory of routes is cleared then)
            self._refuse(f"[fleet] max_rigs = {self.max_rigs} reached", prefix)
            return None, True
        if prefix not in self.listed and not self._valid_first(rest, payload):
            # not remembered: the rig's next message may be a valid one
            self._refuse("first message not a sample on a channel topic", prefix)
            return None, False
        return self._add(prefix, None), True

    def _valid_first(self, channel_topic: str, payload: bytes | None) -> bool:
        """Whether a message on ``<rig>/<channel_topic>`` may found a rig: a channel topic
        of the file and a payload that reads as a sample."""
        return (channel_topic in self.channel_topics and payload is not None
                and not isinstance(parse_payload(payload), str))

    def _refuse(self, reason: str, name: str) -> None:
        """Count a refused rig name or first message; one log line a minute at most, the name
        escaped and cut short."""
        refusals = self.refusals
        refusals[reason] = refusals.get(reason, 0) + 1
        now = self.clock()
        if now - self._last_refusal_log >= REFUSAL_LOG_INTERVAL:
            self._last_refusal_log = now
            log.warning("rig %s ignored: %s (refused so far: %s)", printable(name), reason,
                        ", ".join(f"{count} {why}" for why, count in refusals.items()))

    def _pipeline_of(self, topic: str, payload: bytes | None = None) -> Pipeline | None:
        """The rig pipeline of an input topic, remembered (None: counted as unrouted unless
        it is a result)."""
        routes = self._routes
        if topic in routes:
            pipeline = routes[topic]
        else:
            pipeline, remember = self._resolve(topic, payload)
            if remember and len(topic) <= MAX_REMEMBERED_TOPIC:
                if len(routes) >= MAX_ROUTES:
                    routes.clear()
                routes[topic] = pipeline
        if pipeline is None and "/tdmon/" not in topic:
            self.unrouted += 1
        return pipeline

    def process(self, raw: RawMessage) -> Any:
        pipeline = self._pipeline_of(raw.topic, raw.payload)
        if pipeline is None:
            return None
        self._heard(pipeline)
        return pipeline.process(raw)

    def process_burst(self, raws: Sequence[RawMessage]) -> None:
        """``process`` for each message, each rig's share in one burst of its pipeline (the
        rigs are independent: each keeps its own messages' order)."""
        shares: dict[Pipeline, list[RawMessage]] = {}
        pipeline_of = self._pipeline_of
        for raw in raws:
            pipeline = pipeline_of(raw.topic, raw.payload)
            if pipeline is not None:
                shares.setdefault(pipeline, []).append(raw)
        for pipeline, messages in shares.items():
            self._heard(pipeline)
            pipeline.process_burst(messages)

    def _heard(self, pipeline: Pipeline) -> None:
        """Note that the rig of ``pipeline`` is not silent (found rigs only: listed ones are
        never retired)."""
        if self.discover:
            self._rig_of[pipeline].last_message = self.clock()

    def tick(self) -> None:
        for rig in self.rigs.values():
            rig.pipeline.tick()
        now = self.clock()
        if now >= self._next_idle_check:
            self._next_idle_check = now + IDLE_CHECK_INTERVAL
            self.retire_silent(now)

    def retire_silent(self, now: float) -> list[str]:
        """Retire the found rigs silent for ``idle_rig_timeout``: each flushes, its own sinks
        close (its recording is finished), its counters are kept for the fleet's totals and
        its slot is free for a rig that sends again. The prefixes retired."""
        silent = [prefix for prefix, rig in self.rigs.items()
                  if prefix not in self.listed and now - rig.last_message >= self.idle_timeout]
        for prefix in silent:
            rig = self.rigs.pop(prefix)
            del self._rig_of[rig.pipeline]
            rig.pipeline.flush()
            # its loss state, as a stopping daemon's: a rig that sends again goes on from it
            rig.pipeline.save_state()
            for recorder in rig.pipeline.recorders:
                # durable now: acknowledgements waiting on this recorder's marks can go
                recorder.flush()
            for sink in rig.owned:
                try:
                    sink.close()
                except Exception:
                    rig.pipeline.stats.sink_errors += 1
                    log.exception("rig %s: sink %r failed while closing", prefix, sink)
            for recorder in rig.pipeline.recorders:
                if recorder in self.recorders:
                    self.recorders.remove(recorder)
            for name in SUMMED:
                setattr(self._retired_counts, name, getattr(self._retired_counts, name)
                        + getattr(rig.pipeline.stats, name))
            self.retired += 1
            log.info("rig %s: retired after %.0f s without a message (%d rig%s left)", prefix,
                     now - rig.last_message, len(self.rigs), "" if len(self.rigs) == 1 else "s")
        if silent:
            self._routes.clear()  # topics of the retired rigs, and those refused for room
            # what the retired rigs held was frozen with them (see _add): let it be collected
            gc.unfreeze()
            gc.collect()
            gc.freeze()
        return silent

    def save_state(self) -> None:
        """Each rig's :meth:`Pipeline.save_state`: its loss state, beside its recordings."""
        for rig in self.rigs.values():
            rig.pipeline.save_state()

    def emit_status(self, connections: dict[str, str]) -> None:
        """Each rig's ``status`` on its own prefix (the connections are the fleet's)."""
        for rig in self.rigs.values():
            rig.pipeline.emit_status(connections)

    def emit(self, name: str, message: dict[str, Any]) -> None:
        """A message of the whole fleet (e.g. a recorder's alarm): to every rig."""
        for rig in self.rigs.values():
            rig.pipeline.emit(name, message)

    def flush(self) -> None:
        """End of input: every rig flushes; the fleet's counters become the rigs' sums."""
        if self._closed:
            return
        self._closed = True
        for rig in self.rigs.values():
            rig.pipeline.flush()
        self._sum_counts()

    def _sum_counts(self) -> None:
        stats = self.stats
        own_dropped = stats.dropped
        for name in SUMMED:
            setattr(stats, name, getattr(self._retired_counts, name) + sum(
                getattr(rig.pipeline.stats, name) for rig in self.rigs.values()))
        stats.dropped += own_dropped
        stats.messages_in += self.unrouted

    def close_sinks(self) -> None:
        for rig in self.rigs.values():
            rig.pipeline.close_sinks()


@contextlib.asynccontextmanager
async def build_fleet(config: DaemonConfig, *, backoff: Backoff | None = None,
                      stop_when_sources_done: bool | None = None,
                      extra_rig_sinks: Callable[[str], list[Sink]] | None = None,
                      extra_sinks: Sequence[Sink] = (),
                      ) -> AsyncIterator[Built]:
    """Create the daemon of a fleet file (``config.is_fleet``); sessions close on exit.

    ``extra_rig_sinks(prefix)`` adds sinks to each rig (tests); ``extra_sinks`` receive every
    rig's messages (as for ``build_daemon``, e.g. the command line's status line; each rig
    closes them, so their ``close`` must bear being called again). ``Built.pipeline`` is the
    :class:`FleetPipeline`; its ``rigs`` hold each rig's own pipeline.
    """
    stats = Stats()
    wiring = Wiring(config, stats)
    cache = WellCache()
    fleet: FleetPipeline | None = None
    try:
        wire(SOURCES, wiring)
        # What the rigs' publishers share (Zenoh sessions, the MQTT connection the daemon
        # supervises) is opened now, before any rig exists: the publishers' rows are wired once
        # for the fleet's own prefix, and those sinks closed unused.
        shared = wiring.for_rig(config)
        wire(PUBLISHERS, shared)
        for sink in shared.owned:
            sink.close()
        wells = (None if config.fleet is None or config.fleet.wells is None
                 else config.resolve(config.fleet.wells))
        live = any(not source.finite for source in wiring.sources)

        def make_rig(prefix: str, rig: RigConfig | None) -> Rig | None:
            well = None
            if rig is None and wells is not None:
                candidate = wells / f"{prefix.rsplit('/', 1)[-1]}.toml"
                well = candidate if candidate.is_file() else None
            rig_config = config.for_rig(prefix, rig, well)
            if rig_config.calibration.enabled and rig_config.well is None:
                log.error("rig %s ignored: the calibration needs a well file, and there is no "
                          "%s/%s.toml nor a 'well' in %s", prefix, wells,
                          prefix.rsplit('/', 1)[-1], config.source_file)
                return None
            well_file = cache.well_file(rig_config)
            model = cache.model(rig_config, well_file)
            rig_wiring = wiring.for_rig(rig_config)
            try:
                # the sinks of a single rig, the same tables in the same order
                wire(SINKS, rig_wiring)
                if extra_rig_sinks is not None:
                    rig_wiring.sinks.extend(extra_rig_sinks(prefix))
                rig_wiring.sinks.extend(extra_sinks)
                wire(PUBLISHERS, rig_wiring)
                steps = rig_steps(rig_config, well_file, model)
            except BaseException:
                for sink in rig_wiring.owned:
                    sink.close()
                raise
            well_obj = None if well_file is None else well_file.well
            pipeline = assemble_pipeline(rig_config, well_obj, steps, rig_wiring.sinks,
                                         rig_wiring.stats)
            rig_wiring.pipeline = pipeline
            keep_loss_state(pipeline, rig_config, live)
            return Rig(prefix, rig_config, pipeline, owned=list(rig_wiring.owned))

        fleet = FleetPipeline(config, make_rig, stats)
        # a source's health alarms (e.g. MQTT messages dropped) go to every rig
        wiring.pipeline = fleet  # type: ignore[assignment]
        sources = wiring.sources
        if stop_when_sources_done is None:
            stop_when_sources_done = bool(sources) and all(s.finite for s in sources)
        daemon = Daemon(
            fleet, sources, wiring.connected,  # type: ignore[arg-type]
            queue_size=config.queues.ingest,
            status_interval=config.publish.status_interval,
            backoff=backoff,
            stop_when_sources_done=stop_when_sources_done,
        )
        yield Built(daemon, fleet, fleet.stats)  # type: ignore[arg-type]
    finally:
        if fleet is None:
            await wiring.release(close_sinks=True)
        else:
            await wiring.release(close_sinks=False)
