"""Batch re-analysis on Dask: 12 replays on 2 worker processes against the same 12 in series.

Side by side in one run (project virtualenv):

* **serial**: this process replays each recording with ``tdmon.replay.batch.replay_task`` (the
  function the workers run: the daemon's pipeline with the recorder inline, the fleet
  collector, BLAS at one thread) one after the other, then builds and writes the summary;
* **batch**: ``tdmon.replay.batch.run_batch`` on a local Dask cluster of ``--workers``
  processes (127.0.0.1), started before the timing and warmed up with one replay per worker
  (imports and numba's cached kernels, which the serial process has loaded by then too).

The recordings are the bundled replays taken in turn until there are ``--count`` (12: the
nine bundled ones and three again), with the daemon files their expectations name, 0.5-2.5 s
each. Each side runs ``--repeat`` times, alternating; the best time of each gives the figure,
throughput ratio = serial time / batch time (target >= 1.7 on 2 workers); the ratio of each
run's pair and the machine's load average at its start are printed too (on a shared machine,
other work takes cores from the workers), with the machine's own ceiling measured just before
each run: the throughput of two CPU-bound Python processes against one (2.0 on two idle
cores). The cluster's start-up is printed apart, and one replay's CPU time in this process
against on a worker (the same where the workers' environment is right; Dask's default
MALLOC_TRIM_THRESHOLD_ made it up to 1.39 x: ``--dask-default-environ`` runs the whole
benchmark on such workers for comparison).

    .venv/bin/python benchmarks/bench_batch.py                    # 12 replays, 2 workers
    .venv/bin/python benchmarks/bench_batch.py --repeat 3 --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tdmon.replay.batch import BatchJob

REPO = Path(__file__).resolve().parents[1]
REPLAYS = sorted((REPO / "replays").glob("*.mcap"))


def _spin(iterations: int) -> None:
    total = 0
    for i in range(iterations):
        total += i * i


def ceiling(iterations: int = 4_000_000) -> float:
    """The machine's own parallel ceiling now: throughput of two CPU-bound processes against
    one (2.0 on two idle cores; other work on the machine takes it down)."""
    import multiprocessing

    context = multiprocessing.get_context("spawn")

    def timed(count: int) -> float:
        processes = [context.Process(target=_spin, args=(iterations,)) for _ in range(count)]
        started = time.perf_counter()
        for process in processes:
            process.start()
        for process in processes:
            process.join()
        return time.perf_counter() - started

    one, two = timed(1), timed(2)
    return 2 * one / two


def serial(recordings: list[Path], out: Path) -> float:
    from tdmon.replay.batch import BatchJob, output_names, replay_task
    from tdmon.replay.batch_summary import summary_tables, write_html, write_tables

    started = time.perf_counter()
    outcomes = [replay_task(BatchJob(path, out / "recordings" / name))
                for path, name in zip(recordings, output_names(recordings), strict=True)]
    tables = summary_tables(outcomes)
    write_tables(tables, out / "summary")
    write_html(tables, out / "summary.html")
    elapsed = time.perf_counter() - started
    failed = [o for o in outcomes if not o.ok]
    if failed:
        sys.exit(f"serial replay failed: {failed[0].error}")
    return elapsed


def batch(recordings: list[Path], out: Path, scheduler: str) -> tuple[float, float]:
    """Wall time of the batch, and the replay time (the driver's own clock) summed on its
    busiest worker: the rest is what Dask, the tasks' set-up and the summary cost."""
    from tdmon.replay.batch import run_batch

    started = time.perf_counter()
    result = run_batch(recordings, out, scheduler=scheduler)
    elapsed = time.perf_counter() - started
    if result.failed:
        sys.exit(f"batch replay failed: {result.failed[0].error}")
    per_worker: dict[str, float] = {}
    for outcome in result.outcomes:
        per_worker[outcome.worker] = per_worker.get(outcome.worker, 0.0) + outcome.wall_s
    return elapsed, max(per_worker.values())


def replay_cpu(job: BatchJob) -> float:
    """CPU time [s] of this thread for one replay: where it runs (this process or a worker)
    must not change it, whatever else the machine does."""
    from tdmon.replay.batch import replay_task

    started = time.thread_time()
    replay_task(job)
    return time.thread_time() - started


@contextmanager
def dask_default_cluster(workers: int) -> Iterator[Any]:
    """Dask's LocalCluster as configured by default (the nanny's MALLOC_TRIM_THRESHOLD_ kept),
    for --dask-default-environ."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      host="127.0.0.1", dashboard_address="127.0.0.1:0") as cluster:
        yield cluster


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--count", type=int, default=12,
                        help="recordings per side: the bundled replays in turn (default 12)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", type=Path, help="write the figures as JSON")
    parser.add_argument("--dask-default-environ", action="store_true",
                        help="workers with Dask's default environment (MALLOC_TRIM_THRESHOLD_="
                             "65536), as before tdmon's local_cluster left it out")
    args = parser.parse_args()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the CLI does, before numpy

    from distributed import Client

    from tdmon.replay.batch import BatchJob, local_cluster, replay_task

    recordings = [REPLAYS[i % len(REPLAYS)] for i in range(args.count)]
    with tempfile.TemporaryDirectory(prefix="tdmon-bench-batch-") as tmp:
        root = Path(tmp)
        replay_task(BatchJob(REPLAYS[0], root / "warm.mcap"))  # imports and kernels, here
        started = time.perf_counter()
        make_cluster = dask_default_cluster if args.dask_default_environ else local_cluster
        with make_cluster(args.workers) as cluster, Client(cluster) as client:
            startup = time.perf_counter() - started
            workers = list(client.scheduler_info()["workers"])
            warm = [client.submit(replay_task, BatchJob(REPLAYS[0], root / f"warm-{i}.mcap"),
                                  workers=[address], pure=False)
                    for i, address in enumerate(workers)]
            client.gather(warm)
            cpu_here, cpu_worker = [], []
            longest = REPO / "replays" / "model-error-density.mcap"
            for i in range(3):  # one replay's CPU time here and on a worker, interleaved
                cpu_here.append(replay_cpu(BatchJob(longest, root / f"cpu-here-{i}.mcap")))
                cpu_worker.append(client.submit(
                    replay_cpu, BatchJob(longest, root / f"cpu-worker-{i}.mcap"),
                    workers=[workers[0]], pure=False).result())
            print(f"{longest.name}: CPU time, best of 3: {min(cpu_here):.3f} s in this process, "
                  f"{min(cpu_worker):.3f} s on a worker (x{min(cpu_worker) / min(cpu_here):.2f})",
                  flush=True)
            serial_times, batch_times, loads, ceilings, busiest = [], [], [], [], []
            for run in range(args.repeat):
                loads.append(round(os.getloadavg()[0], 1))
                ceilings.append(round(ceiling(), 2))
                serial_times.append(serial(recordings, root / f"serial-{run}"))
                elapsed, replaying = batch(recordings, root / f"batch-{run}",
                                           cluster.scheduler_address)
                batch_times.append(elapsed)
                busiest.append(replaying)
                print(f"run {run + 1}: serial {serial_times[-1]:.2f} s, batch "
                      f"{batch_times[-1]:.2f} s, ratio {serial_times[-1] / batch_times[-1]:.2f} "
                      f"(load average {loads[-1]}, machine ceiling {ceilings[-1]}; busiest worker "
                      f"replaying {busiest[-1]:.2f} s of the batch's {elapsed:.2f} s)", flush=True)
    best_serial, best_batch = min(serial_times), min(batch_times)
    figures = {
        "recordings": len(recordings), "workers": args.workers,
        "serial_s": round(best_serial, 3), "batch_s": round(best_batch, 3),
        "throughput_ratio": round(best_serial / best_batch, 2),
        "cluster_startup_s": round(startup, 2),
        "dask_default_environ": args.dask_default_environ,
        "replay_cpu_here_s": round(min(cpu_here), 3),
        "replay_cpu_worker_s": round(min(cpu_worker), 3),
        "serial_runs_s": [round(t, 2) for t in serial_times],
        "batch_runs_s": [round(t, 2) for t in batch_times],
        "paired_ratios": [round(a / b, 2) for a, b in zip(serial_times, batch_times,
                                                         strict=True)],
        "load_average_per_run": loads,
        "machine_ceiling_per_run": ceilings,
        "busiest_worker_replay_s": [round(t, 2) for t in busiest],
    }
    print(f"{len(recordings)} replays: serial {best_serial:.2f} s, {args.workers} workers "
          f"{best_batch:.2f} s -> throughput x{best_serial / best_batch:.2f} (best of "
          f"{args.repeat}); local cluster start-up {startup:.1f} s; 1-min load average at "
          f"the runs' starts {loads}; the machine's ceiling (2 CPU-bound processes against "
          f"1, before each run) {ceilings}")
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))


if __name__ == "__main__":
    main()
