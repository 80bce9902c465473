"""Batch re-analysis on Dask distributed: many recordings through the daemon's pipeline.

Each recording is one task, :func:`replay_task`, run in a worker process: the same
:func:`tdmon.replay.driver.replay` as ``tdmon replay`` (recorder inline: the workers already
keep every core busy), with BLAS held to one thread and a :class:`FleetCollector` riding along
for the summary. A task never raises: a broken or missing file, an unusable configuration or a
bug come back as an outcome with its reason, and a worker that dies is reported the same way by
:func:`run_batch`, so one bad file never stops the rest. ``distributed`` and ``threadpoolctl``
are imported when a batch runs (``pip install 'tdmon[batch]'``).
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tdmon.errors import ConfigError, TdmonError
from tdmon.replay.batch_summary import (
    FleetCollector,
    HoleSectionSpan,
    RecordingOutcome,
    section_rows,
    summary_tables,
    write_html,
    write_tables,
)

if TYPE_CHECKING:
    import pandas as pd

    from tdmon.config.daemon import DaemonConfig

__all__ = ["WORKER_BLAS_THREADS", "BatchJob", "BatchResult", "RecordingOutcome", "blas_capped",
           "local_cluster", "output_names", "replay_task", "run_batch"]

#: BLAS threads per worker task. The replay's linear algebra is small matrices where extra
#: threads only contend with the other workers for the cores (the reason the CLI sets one
#: thread too, tdmon/cli/__init__.py); a cluster joined with --scheduler may not have set it.
WORKER_BLAS_THREADS = 1

Progress = Callable[[RecordingOutcome, int, int], None]


@dataclass(frozen=True)
class BatchJob:
    """One task: replay ``recording`` into ``out`` with the daemon file ``config`` (None: the
    one the replay's expectations name)."""

    recording: Path
    out: Path
    config: Path | None = None


@dataclass(frozen=True)
class BatchResult:
    """What a batch did: one outcome per recording (in the order given) and the files of the
    summary."""

    outcomes: tuple[RecordingOutcome, ...]
    out_dir: Path
    files: tuple[Path, ...] = field(default_factory=tuple)

    @property
    def failed(self) -> tuple[RecordingOutcome, ...]:
        return tuple(o for o in self.outcomes if not o.ok)

    def tables(self) -> dict[str, pd.DataFrame]:
        """The summary's DataFrames (tdmon.replay.batch_summary)."""
        return summary_tables(self.outcomes)


@contextmanager
def blas_capped(threads: int = WORKER_BLAS_THREADS) -> Iterator[Callable[[], int | None]]:
    """Hold every BLAS library of this process to ``threads`` threads while inside; yields a
    function returning the most threads any BLAS library has now (None: none loaded)."""
    from threadpoolctl import threadpool_info, threadpool_limits

    def most() -> int | None:
        counts = [pool["num_threads"] for pool in threadpool_info()
                  if pool.get("user_api") == "blas"]
        return max(counts) if counts else None

    # load the BLAS libraries before limiting them: numpy's, and scipy's own copy, which the
    # replay would otherwise load later (lazily) with its default thread count
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401

    with threadpool_limits(limits=threads, user_api="blas"):
        yield most


def _hole_sections(config: DaemonConfig) -> list[HoleSectionSpan]:
    from tdmon.config.well import load_well

    if config.well is None:
        return []
    well = load_well(config.resolve(config.well))
    return [HoleSectionSpan(name=s.name or f"{s.kind} {i + 1}", kind=s.kind, top=s.top,
                            bottom=s.bottom) for i, s in enumerate(well.hole)]


def _size(path: Path) -> int:
    """The file's size [bytes], 0 when it cannot be read (its task reports why)."""
    try:
        return path.stat().st_size
    except OSError:
        return 0


def replay_task(job: BatchJob) -> RecordingOutcome:
    """Replay one recording (in a worker) and summarise it; never raises."""
    import asyncio

    from tdmon.replay.driver import check_replay_file, replay
    from tdmon.replay.run import resolve_config

    worker = f"{socket.gethostname()}:{os.getpid()}"
    name = job.out.stem
    try:
        with blas_capped() as blas_threads:
            # the file first: a CSV or a missing file is named as such, before any config
            check_replay_file(job.recording)
            config = resolve_config(job.recording, job.config)
            collector = FleetCollector()
            result = asyncio.run(replay(job.recording, config, job.out,
                                        extra_sinks=[collector], separate_writer=False))
            threads = blas_threads()
        if result.interrupted:
            raise TdmonError(f"{job.recording}: replay interrupted by a signal")
        return RecordingOutcome(
            recording=str(job.recording), out=str(job.out), name=name, well=collector.well,
            messages_in=result.messages_in, samples=result.samples, rejected=result.rejected,
            wall_s=result.wall_s, worker=worker, blas_threads=threads,
            windows=collector.windows,
            sections=section_rows(collector.profile, _hole_sections(config)),
            state_seconds=dict(collector.states.state_time), alarms=dict(collector.alarms))
    except TdmonError as exc:
        return RecordingOutcome(recording=str(job.recording), out=None, error=str(exc),
                                name=name, worker=worker)
    except Exception as exc:  # a bug: reported with its type, the batch goes on
        return RecordingOutcome(recording=str(job.recording), out=None, name=name,
                                worker=worker, error=f"{type(exc).__name__}: {exc}")


def output_names(recordings: Sequence[Path]) -> list[str]:
    """A distinct output file name per recording: its own name, ``-2``, ``-3``... when two
    recordings of different folders share one."""
    seen: dict[str, int] = {}
    names = []
    for path in recordings:
        stem = path.stem
        seen[stem] = seen.get(stem, 0) + 1
        names.append(f"{stem}.mcap" if seen[stem] == 1 else f"{stem}-{seen[stem]}.mcap")
    return names


@contextmanager
def _client(scheduler: str | None, workers: int | None, jobs: int) -> Iterator[Any]:
    try:
        from distributed import Client
    except ImportError as exc:
        raise TdmonError("tdmon batch needs Dask distributed: pip install 'tdmon[batch]'") \
            from exc
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise ConfigError("--scheduler", "",
                              f"cannot reach the Dask scheduler {scheduler!r}: {exc}") from exc
        with client:
            yield client
        return
    count = workers if workers is not None else min(jobs, os.cpu_count() or 1)
    if count < 1:
        raise ConfigError("--workers", "", f"{count} workers: give at least 1")
    with local_cluster(count) as cluster, Client(cluster) as client:
        yield client


#: Environment variables the Dask nanny sets in its workers by default that the batch's own
#: cluster leaves out. ``MALLOC_TRIM_THRESHOLD_=65536`` fixes glibc's thresholds, so that every
#: numpy array above 128 KiB is mmapped and unmapped afresh: a replay then took up to 1.39 x the
#: CPU time it takes in a plain process (docs/replays.md, "Speed").
_WORKER_ENVIRON_DROPPED = ("MALLOC_TRIM_THRESHOLD_",)


@contextmanager
def local_cluster(workers: int) -> Iterator[Any]:
    """A Dask ``LocalCluster`` of ``workers`` processes for replays: one thread each (a replay
    holds the GIL), everything on 127.0.0.1 (the scheduler's HTTP server too: its default,
    ':8787', listens on every interface), and glibc's malloc left to tune itself."""
    import dask
    from distributed import LocalCluster

    # the nanny runs in this process and writes its variables into os.environ before it
    # spawns a worker (a worker inherits them): unset them in its configuration (None) and
    # keep them out of os.environ while the cluster lives, then put back what was there
    saved = {key: os.environ.pop(key) for key in _WORKER_ENVIRON_DROPPED if key in os.environ}
    unset = {f"distributed.nanny.pre-spawn-environ.{key}": None
             for key in _WORKER_ENVIRON_DROPPED}
    try:
        with (dask.config.set(unset),
              LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address="127.0.0.1:0") as cluster):
            yield cluster
    finally:
        for key in _WORKER_ENVIRON_DROPPED:
            os.environ.pop(key, None)
        os.environ.update(saved)


def run_batch(
    recordings: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    *,
    config: str | os.PathLike[str] | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: Progress | None = None,
) -> BatchResult:
    """Replay every recording on a Dask cluster and write the fleet summary.

    Parameters
    ----------
    recordings : the replays (MCAP files); paths as the workers see them
    out_dir : folder for ``recordings/<name>.mcap`` (the flight recordings), the summary
        tables (``summary/<table>.parquet``, CSV without pyarrow) and ``summary.html``
    config : daemon file for every recording; None: each replay's expectations name one
    scheduler : address of a running Dask scheduler (``tcp://host:8786``); None: a local
        cluster of ``workers`` processes on this machine, closed at the end
    workers : worker processes of the local cluster (default: one per core, at most one per
        recording)
    progress : called after each recording with its outcome, the number done and the total

    Returns
    -------
    BatchResult
        Failed recordings carry their reason (``outcome.error``); nothing is raised for them.

    Raises
    ------
    TdmonError
        Dask is not installed, the scheduler cannot be reached, ``workers`` < 1, no recordings.
    """
    paths = [Path(p).absolute() for p in recordings]
    if not paths:
        raise ConfigError("RECORDINGS", "", "no recordings given")
    folder = Path(out_dir)
    (folder / "recordings").mkdir(parents=True, exist_ok=True)
    daemon_file = None if config is None else Path(config).absolute()
    jobs = [BatchJob(recording=path, out=(folder / "recordings" / name).absolute(),
                     config=daemon_file)
            for path, name in zip(paths, output_names(paths), strict=True)]
    outcomes: dict[int, RecordingOutcome] = {}
    with _client(scheduler, workers, len(jobs)) as client:
        from distributed import as_completed

        # longest first (file size stands for replay time): the last task to start is a short
        # one, so the workers finish together instead of one waiting on a long tail
        order = sorted(range(len(jobs)), key=lambda i: -_size(jobs[i].recording))
        futures = client.map(replay_task, [jobs[i] for i in order], pure=False)
        index = {future.key: i for future, i in zip(futures, order, strict=True)}
        for future in as_completed(futures):
            i = index[future.key]
            try:
                outcome = future.result()
            except Exception as exc:  # the worker died (KilledWorker) or the task was lost
                outcome = RecordingOutcome(recording=str(jobs[i].recording), out=None,
                                           name=jobs[i].out.stem,
                                           error=f"{type(exc).__name__}: {exc}")
            outcomes[i] = outcome
            if progress is not None:
                progress(outcome, len(outcomes), len(jobs))
    ordered = tuple(outcomes[i] for i in range(len(jobs)))
    tables = summary_tables(ordered)
    files = [*write_tables(tables, folder / "summary"), write_html(tables, folder /
                                                                   "summary.html")]
    return BatchResult(outcomes=ordered, out_dir=folder, files=tuple(files))
