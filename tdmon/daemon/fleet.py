"""One daemon, many rigs: one pipeline per rig behind one transport session.

A fleet daemon file (``[[rigs]]`` and/or ``[fleet]``, docs/daemon.md "Many rigs") names a root
``prefix``; the sources subscribe once to everything under it and :class:`FleetPipeline` routes
each message by its topic to the rig it belongs to. Each rig is a plain single-rig
:class:`~tdmon.daemon.pipeline.Pipeline` built from ``config.for_rig(...)`` (the same decoder,
aligner and steps as ``tdmon run`` with one rig), writing to its own recorder (its own folder:
each rig's recording replays on its own) and publishing on ``<rig prefix>/tdmon/<name>``.

Shared between rigs: the sources (one Zenoh session and subscription, or one MQTT
connection), the publishers' sessions, the compiled kernels (per process anyway) and what is
read from a well file: rigs with the same well file and ``[monitor]`` settings share the
``Well`` and the precomputed load grid (:class:`WellCache`).

:class:`FleetPipeline` offers what :class:`~tdmon.daemon.daemon.Daemon` needs of a pipeline
(``process``, ``tick``, ``flush``, ``emit_status``, ``close_sinks``, ``sinks``, ``stats``), so
supervision, backpressure, acknowledgements and shutdown are the single-rig daemon's own.
"""

from __future__ import annotations

import contextlib
import gc
import logging
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tdmon.config.daemon import DaemonConfig, RigConfig
from tdmon.config.well_file import WellFile, read_well_file
from tdmon.daemon.build import Built, assemble_pipeline, rig_steps
from tdmon.daemon.daemon import Daemon
from tdmon.daemon.pipeline import Pipeline, Sink, Stats
from tdmon.daemon.sinks import _publish_mqtt, _publish_zenoh
from tdmon.daemon.sources import SOURCES
from tdmon.daemon.steps.monitor import LoadModel
from tdmon.daemon.supervisor import Backoff
from tdmon.daemon.wiring import Wiring, wire
from tdmon.errors import TdmonError
from tdmon.ingest.types import RawMessage

log = logging.getLogger(__name__)

#: Routed topics remembered (a topic is looked up once); past this the memory starts afresh,
#: so that a flood of stray topics cannot grow it without bound.
MAX_ROUTES = 100_000

#: The per-rig counters summed into the fleet's when it stops (``tdmon run``'s last line).
SUMMED = ("messages_in", "samples_in", "rejected", "dropped", "duplicates", "out_of_order",
          "frames", "step_errors", "sink_errors", "seq_lost", "sampling_gaps", "clock_jumps")


def rig_folder_name(prefix: str) -> str:
    """The recording folder (and file name prefix) of rig ``prefix``: "rig/F4" -> "rig_F4"."""
    return prefix.replace("/", "_")


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


class _RoundStats:
    """``flushes`` of :class:`FleetRecorders`: rounds in which every recorder flushed."""

    def __init__(self, owner: FleetRecorders) -> None:
        self._owner = owner

    @property
    def flushes(self) -> int:
        return self._owner.rounds()


class FleetRecorders:
    """The rigs' recorders as one, for the daemon's acknowledgement window.

    A message is acknowledged once its rig's recorder has flushed it; which rig a waiting
    acknowledgement belongs to is not kept, so a flush counts only when every rig's recorder
    has flushed since the previous one (a round). Rigs found later join the next round.
    """

    def __init__(self) -> None:
        self.recorders: list[Any] = []
        self._seen: list[int] = []
        self._rounds = 0
        self._stats = _RoundStats(self)

    @property
    def stats(self) -> _RoundStats:
        return self._stats

    def add(self, recorder: Any) -> None:
        self.recorders.append(recorder)
        self._seen.append(int(recorder.stats.flushes))

    def rounds(self) -> int:
        now = [int(recorder.stats.flushes) for recorder in self.recorders]
        if now and all(count > seen for count, seen in zip(now, self._seen, strict=True)):
            self._rounds += 1
            self._seen = now
        return self._rounds

    def flush(self) -> None:
        for recorder in self.recorders:
            recorder.flush()

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        """Never written to: each rig writes to its own recorder."""

    def close(self) -> None:
        """Each rig closes its own recorder."""


@dataclass
class _RigPublisher:
    """A rig's results on its own prefix through the fleet's one MQTT publisher."""

    shared: Any  # tdmon.ingest.mqtt.MqttPublisher
    prefix: str
    topics: frozenset[str] = field(init=False)

    def __post_init__(self) -> None:
        self.topics = self.shared.topics

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        self.shared.enqueue(f"{self.prefix}/tdmon/{topic.rsplit('/', 1)[-1]}", message)

    def close(self) -> None:
        """The shared publisher is the daemon's to close."""


@dataclass
class Rig:
    """One rig of the fleet: its prefix, configuration and pipeline."""

    prefix: str
    config: DaemonConfig
    pipeline: Pipeline


class FleetPipeline:
    """Route each message to its rig's pipeline; rigs listed in the file exist from the start,
    rigs found under ``[fleet]`` appear with their first message.

    ``make_rig(prefix, rig)`` builds a rig's pipeline (``rig``: its ``[[rigs]]`` entry, None
    for a rig found by topic); it returns None when the rig cannot run (no well file for the
    calibration), whose messages are then counted in ``unrouted``.
    """

    def __init__(self, config: DaemonConfig,
                 make_rig: Callable[[str, RigConfig | None], Rig | None],
                 recorders: FleetRecorders | None = None) -> None:
        self.root = config.prefix
        self.listed = {rig.prefix: rig for rig in config.rigs}
        self.discover = config.fleet is not None and config.fleet.discover
        self.max_rigs = config.fleet.max_rigs if config.fleet is not None else len(self.listed)
        self.make_rig = make_rig
        self.recorders = recorders
        self.stats = Stats()
        self.rigs: dict[str, Rig] = {}
        self.refused: set[str] = set()
        self.unrouted = 0
        self._routes: dict[str, Pipeline | None] = {}
        self._closed = False
        try:
            for prefix, rig in self.listed.items():
                self._add(prefix, rig, found=False)
        except BaseException:
            self.close_sinks()  # the rigs built so far: the daemon will not
            raise

    @property
    def sinks(self) -> list[Sink]:
        """What the acknowledgement window waits for: the rigs' recorders as one."""
        return [self.recorders] if self.recorders is not None else []

    def _add(self, prefix: str, rig: RigConfig | None, found: bool = True) -> Pipeline | None:
        """Build rig ``prefix``. A rig listed in the file that cannot be built stops the
        daemon at start; one found by topic is refused with one log line, the others go on."""
        if prefix in self.refused:
            return None
        try:
            built = self.make_rig(prefix, rig)
        except TdmonError as exc:
            if not found:
                raise
            log.error("rig %s ignored: %s", prefix, exc)
            built = None
        if built is None:
            self.refused.add(prefix)
            return None
        self.rigs[prefix] = built
        # What a rig keeps for its life (well model, filters, recorder) goes to the permanent
        # generation: a full collection then scans only what came after. Without it, building
        # rigs grows the tracked heap until full collections take 0.15-0.25 s each (measured
        # with 50 rigs), a stall every rig's messages wait through.
        gc.freeze()
        log.info("rig %s: monitoring (%d rig%s)", prefix, len(self.rigs),
                 "" if len(self.rigs) == 1 else "s")
        return built.pipeline

    def _route(self, topic: str) -> Pipeline | None:
        """The pipeline of the rig ``topic`` belongs to; None for results (``tdmon/``) and
        for topics of no rig."""
        root = self.root
        if not topic.startswith(root + "/"):
            return None
        prefix = max((p for p in self.listed if topic.startswith(p + "/")), key=len,
                     default=None)
        if prefix is None:
            if not self.discover:
                return None
            name, _, rest = topic[len(root) + 1:].partition("/")
            if not rest or name == "tdmon":
                return None
            prefix = f"{root}/{name}"
        if topic[len(prefix) + 1:].startswith("tdmon/"):
            return None  # results of this or another daemon: not input
        rig = self.rigs.get(prefix)
        if rig is not None:
            return rig.pipeline
        if len(self.rigs) >= self.max_rigs:
            if prefix not in self.refused:
                self.refused.add(prefix)
                log.warning("rig %s ignored: [fleet] max_rigs = %d reached", prefix,
                            self.max_rigs)
            return None
        return self._add(prefix, None)

    def _pipeline_of(self, topic: str) -> Pipeline | None:
        """The rig pipeline of an input topic, remembered (None: counted as unrouted unless
        it is a result)."""
        routes = self._routes
        if topic in routes:
            pipeline = routes[topic]
        else:
            if len(routes) >= MAX_ROUTES:
                routes.clear()
            pipeline = routes[topic] = self._route(topic)
        if pipeline is None and "/tdmon/" not in topic:
            self.unrouted += 1
        return pipeline

    def process(self, raw: RawMessage) -> Any:
        pipeline = self._pipeline_of(raw.topic)
        return None if pipeline is None else pipeline.process(raw)

    def process_burst(self, raws: Sequence[RawMessage]) -> None:
        """``process`` for each message, each rig's share in one burst of its pipeline (the
        rigs are independent: each keeps its own messages' order)."""
        shares: dict[Pipeline, list[RawMessage]] = {}
        pipeline_of = self._pipeline_of
        for raw in raws:
            pipeline = pipeline_of(raw.topic)
            if pipeline is not None:
                shares.setdefault(pipeline, []).append(raw)
        for pipeline, messages in shares.items():
            pipeline.process_burst(messages)

    def tick(self) -> None:
        for rig in self.rigs.values():
            rig.pipeline.tick()

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
            setattr(stats, name, sum(getattr(rig.pipeline.stats, name)
                                     for rig in self.rigs.values()))
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
    from tdmon.ingest.mqtt import MqttPublisher
    from tdmon.ingest.zenoh_io import ZenohPublisher

    stats = Stats()
    wiring = Wiring(config, stats)
    cache = WellCache()
    names = list(config.publish.names)
    recorders = FleetRecorders() if config.recorder.enabled else None
    fleet: FleetPipeline | None = None
    try:
        await wire(SOURCES, wiring)
        zenoh_section = _publish_zenoh(config)
        zenoh_session = (None if zenoh_section is None
                         else await wiring.zenoh_session(zenoh_section))
        mqtt_section = _publish_mqtt(config)
        mqtt_shared: MqttPublisher | None = None
        if mqtt_section is not None:
            mqtt_shared = MqttPublisher(mqtt_section, config.prefix, names,
                                        qos=config.publish.qos,
                                        queue_size=config.queues.publish,
                                        on_drop=stats.count_drop, base=wiring.base)
            wiring.connected.append(mqtt_shared)
        wells = (None if config.fleet is None or config.fleet.wells is None
                 else config.resolve(config.fleet.wells))

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
            sinks: list[Sink] = []
            pipeline_box: list[Pipeline] = []
            if recorders is not None:
                from tdmon.record.mcap_recorder import McapRecorder

                section = rig_config.recorder
                recorder = McapRecorder(
                    rig_config.resolve(section.output) / rig_folder_name(prefix),
                    prefix=rig_folder_name(prefix),
                    rotate_s=section.rotation,
                    flush_interval_s=section.flush_interval,
                    on_alarm=lambda message: pipeline_box[0].emit("alarm", message)
                    if pipeline_box else None,
                )
                recorders.add(recorder)
                sinks.append(recorder)
            if extra_rig_sinks is not None:
                sinks.extend(extra_rig_sinks(prefix))
            sinks.extend(extra_sinks)
            if zenoh_session is not None:
                sinks.append(ZenohPublisher(zenoh_session, prefix, names))
            if mqtt_shared is not None:
                sinks.append(_RigPublisher(mqtt_shared, prefix))
            steps = rig_steps(rig_config, well_file, model)
            well_obj = None if well_file is None else well_file.well
            pipeline = assemble_pipeline(rig_config, well_obj, steps, sinks, Stats())
            pipeline_box.append(pipeline)
            return Rig(prefix, rig_config, pipeline)

        fleet = FleetPipeline(config, make_rig, recorders)
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
