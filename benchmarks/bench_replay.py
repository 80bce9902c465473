"""Replay through the whole daemon pipeline against a bare MCAP read/decode/write; long sessions.

Two measurements, one process (project virtualenv):

1. **Rate ratio.** A simulated session (``--hours`` of rig time rounded up to whole phases,
   1 Hz, 8 channels: hook load, torque, bit depth, hole depth, block position, rpm, flow in,
   standpipe pressure; trips out and in with connections, so that rig states, windows,
   back-calculation and alarms all do their work) is replayed with
   ``tdmon.replay.driver.replay`` at full speed (decode, record raw input and samples, align,
   rig state, monitor, calibration, alarms, MCAP recorder in single-file mode; the recorder runs
   in a child process, as ``tdmon replay --recorder process`` does, and the same replay with
   the recorder in the replaying process, as ``tdmon replay`` does by default, is printed
   beside it, with CPU times: the child's counted for the first). Side by side,
   the *bare* path reads the same ``/tdmon/raw`` messages with the ``mcap`` package's
   ``StreamReader``, decodes each with ``json.loads`` (the recorded message and its payload)
   and writes it to an MCAP file with mcap's ``Writer`` (zstd chunks, as the recorder): pure
   Python, as issue 15 states the floor. Best of
   ``--repeat`` runs each, alternated; the ratio pipeline/bare is the figure (target >= 1.0
   for the replay in one process).
2. **Long session** (``--days``, default 7; 0 skips): the same programme generated for that
   long (7 days x 86400 s x 8 channels = 4.84 M messages) into a temporary file, replayed once
   at full speed; wall time (target < 5 min) and the process's resident memory sampled every
   ``--sample`` seconds from a thread (``/proc/<pid>/statm`` of this process plus its
   children, i.e. the recorder's process): first and last sample after the
   first 10 % of the run, and the peak. With ``--tracemalloc`` the Python heap is traced
   too (slows the run down by about 2x).
3. **The command's summary** (``--summary-memory``, issue 33): ``tdmon replay --json`` (which
   gathers its summary while replaying) on sessions of ``--summary-hours`` (default 1 and 24
   h), each against the library replay (``tdmon.replay``, no summary) of the same session, in
   turn, ``--repeat`` pairs; each in a process of its own, whose peak resident memory
   (``ru_maxrss`` of the waited-for child) and wall time are taken. Targets: the command's
   peak at the longest session at most 1.5x its peak at the shortest, and its wall time
   within 10 % of the library replay's. ``--sessions DIR`` keeps the simulated sessions
   (``session-<h>h.mcap``) and reuses them on the next run.

    .venv/bin/python benchmarks/bench_replay.py                 # ratio (3.3 h) and 7 days
    .venv/bin/python benchmarks/bench_replay.py --days 0 --hours 4 --repeat 3 --json out.json
    .venv/bin/python benchmarks/bench_replay.py --profile       # cProfile of one replay
    .venv/bin/python benchmarks/bench_replay.py --blas-threads 1  # single-threaded OpenBLAS
    .venv/bin/python benchmarks/bench_replay.py --summary-memory --repeat 1 --sessions /tmp/s

Not part of the test suite (a 7-day replay takes minutes).
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import gc
import json
import os
import pstats
import subprocess
import sys
import tempfile
import threading
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

REPO = Path(__file__).resolve().parents[1]
WELL = REPO / "replays" / "scenarios" / "wells" / "example-7-1-glydril.toml"
CONFIG = REPO / "config" / "daemon" / "replay-sim-trip-out.toml"
CHANNELS = ["hookload", "torque", "bit_depth", "hole_depth", "block_position", "rpm",
            "flow_in", "spp"]


def scenario_text(seconds: float) -> str:
    """A scenario of at least ``seconds`` of rig time: trips out to 1500 m and back to 4200 m
    with circulation and rotation between them (each pair about 6.5 h)."""
    head = f"""
[scenario]
name = "bench-long"
well = "{WELL}"
seed = 5
start = "2024-05-01T00:00:00Z"
prefix = "sim/trip-out"
bit_depth = "4200 m"
hole_depth = "4223.5 m"
block_position = "2 m"

[sampling]
interval = "1 s"
channels = {json.dumps(CHANNELS)}

[noise]
relative = 0.003

[noise.channels.bit_depth]
relative = 0.0
absolute = "0.005 m"

[noise.channels.block_position]
relative = 0.0
absolute = "0.005 m"
"""
    cycle = """
[[phase]]
kind = "circulate"
duration = "10 min"
flow = "2000 L/min"

[[phase]]
kind = "trip_out"
to = "1500 m"
speed = "0.5 m/s"
slips_time = "60 s"

[[phase]]
kind = "static"
duration = "10 min"

[[phase]]
kind = "trip_in"
to = "4200 m"
speed = "0.5 m/s"
slips_time = "60 s"

[[phase]]
kind = "rotate"
duration = "10 min"
rpm = "100 rpm"
flow = "2000 L/min"
"""
    pair = 2 * (2700 / 0.5 + 2700 / 28 * 60) + 30 * 60  # [s] of one cycle, roughly
    cycles = max(1, int(seconds / pair) + 1)
    return head + cycle * cycles


def make_session(path: Path, seconds: float) -> tuple[int, float]:
    """Simulate ``seconds`` of rig time into ``path`` (truncated to that length); returns
    (input messages, seconds it took)."""
    from tdmon.replay.scenario import load_scenario_model
    from tdmon.replay.simulate import simulate_to_mcap

    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        scenario_file = Path(folder) / "bench.toml"
        scenario_file.write_text(scenario_text(seconds))
        scenario = load_scenario_model(scenario_file)
        scenario = _truncated(scenario, seconds)
        _, count = simulate_to_mcap(scenario, path, progress=sys.stderr.isatty())
    return count, time.perf_counter() - started


def _truncated(scenario: Any, seconds: float) -> Any:
    # whole cycles overshoot the wanted length; phases past it are dropped
    import dataclasses

    phases = list(scenario.phases)
    total, kept = 0.0, []
    for phase in phases:
        kept.append(phase)
        total += _phase_seconds(phase)
        if total >= seconds:
            break
    if dataclasses.is_dataclass(scenario):
        return dataclasses.replace(scenario, phases=tuple(kept))
    return scenario


def _phase_seconds(phase: Any) -> float:
    duration = getattr(phase, "duration", None)
    if duration:
        return float(duration)
    return 2700 / 0.5 + 2700 / 28 * 60


def bare_copy(src: Path, dst: Path) -> int:
    """Read every input message, decode its payload, write it to MCAP: the floor.

    Pure Python as the issue states it: the ``mcap`` package's ``StreamReader`` itself (not
    tdmon's ``iter_raw``: the floor must not get faster with the replay's own code), the
    ``json`` module for the recorded message and its payload, and ``mcap``'s ``Writer``. Under
    the same garbage-collector setting as a full-speed replay (``replay`` raises the
    young-generation threshold for the run; ~4 % faster here too)."""
    from tdmon.replay.driver import FULL_SPEED_GC_YOUNG

    previous = gc.get_threshold()
    gc.set_threshold(FULL_SPEED_GC_YOUNG, *previous[1:])
    try:
        return _bare_copy(src, dst)
    finally:
        gc.set_threshold(*previous)


def _bare_copy(src: Path, dst: Path) -> int:
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader

    count = 0
    topics: dict[int, str] = {}
    with src.open("rb") as stream, dst.open("wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD, chunk_size=4 * 1024 * 1024)
        writer.start()
        schema = writer.register_schema("raw", "jsonschema", b"{}")
        channel = writer.register_channel("/tdmon/raw", "json", schema)
        for record in StreamReader(stream).records:
            if isinstance(record, Channel):
                topics[record.id] = record.topic
            if not isinstance(record, Message) or topics.get(record.channel_id) != "/tdmon/raw":
                continue
            raw = json.loads(record.data)
            payload = json.loads(raw["payload"])
            body = json.dumps({"topic": raw["topic"], "receive_time": raw["receive_time"],
                               "payload": payload}, separators=(",", ":")).encode()
            writer.add_message(channel, record.log_time, body, record.log_time,
                               sequence=count)
            count += 1
        writer.finish()
    return count


def pipeline_replay(src: Path, dst: Path, separate_writer: bool = True) -> int:
    from tdmon.config.daemon import load_daemon_config
    from tdmon.replay.driver import replay

    config = load_daemon_config(CONFIG)
    result = asyncio.run(replay(src, config, dst, separate_writer=separate_writer))
    return result.messages_in


def best_of(repeat: int, run: Callable[[], int]) -> tuple[float, int]:
    best, count = float("inf"), 0
    for _ in range(repeat):
        started = time.perf_counter()
        count = run()
        best = min(best, time.perf_counter() - started)
    return best, count


def _children() -> list[str]:
    """Process ids of this process's children (e.g. the recorder's process), from /proc."""
    me = str(os.getpid())
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                # "pid (comm) state ppid ...": comm may hold spaces, so split after its ")"
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if fields[1] == me:
            found.append(entry)
    return found


class MemorySampler:
    """Resident set size [bytes] of this process and its children (and the traced Python
    heap of this one) every ``interval`` s."""

    def __init__(self, interval: float, trace: bool) -> None:
        self.interval = interval
        self.trace = trace
        self.samples: list[tuple[float, int, int]] = []  # (t, rss, traced)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._page = os.sysconf("SC_PAGE_SIZE")

    def _rss(self) -> int:
        total = 0
        for pid in [str(os.getpid()), *_children()]:
            try:
                with open(f"/proc/{pid}/statm") as f:
                    total += int(f.read().split()[1]) * self._page
            except OSError:
                pass  # a child that just ended
        return total

    def _run(self) -> None:
        start = time.perf_counter()
        while not self._stop.wait(self.interval):
            traced = tracemalloc.get_traced_memory()[0] if self.trace else 0
            self.samples.append((time.perf_counter() - start, self._rss(), traced))

    def __enter__(self) -> MemorySampler:
        if self.trace:
            tracemalloc.start()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        if self.trace:
            tracemalloc.stop()


def ratio(hours: float, repeat: int, folder: Path) -> dict[str, Any]:
    src = folder / "session.mcap"
    _, made = make_session(src, hours * 3600)
    # alternated, one of each per round: a change of the machine's load hits all three alike.
    # CPU time of this process beside the wall time: on a shared machine it is the steadier
    # figure (not for the child-process recorder, whose child it does not count)
    bare_s = pipe_s = inline_s = bare_cpu = inline_cpu = pipe_cpu = float("inf")
    for _ in range(repeat):
        cpu = time.process_time()
        run_s, n_bare = best_of(1, lambda: bare_copy(src, folder / "bare.mcap"))
        bare_cpu = min(bare_cpu, time.process_time() - cpu)
        bare_s = min(bare_s, run_s)
        # the child-process recorder's CPU time too: its process has ended (and been waited
        # for) when the replay returns, so os.times() counts it among the children
        cpu = time.process_time() + _children_cpu()
        run_s, n_pipe = best_of(
            1, lambda: pipeline_replay(src, folder / "pipe.mcap", separate_writer=True))
        _wait_for_recorder_exit()
        pipe_cpu = min(pipe_cpu, time.process_time() + _children_cpu() - cpu)
        pipe_s = min(pipe_s, run_s)
        cpu = time.process_time()
        run_s, n_inline = best_of(
            1, lambda: pipeline_replay(src, folder / "inline.mcap", separate_writer=False))
        inline_cpu = min(inline_cpu, time.process_time() - cpu)
        inline_s = min(inline_s, run_s)
    assert n_bare == n_pipe == n_inline, (n_bare, n_pipe, n_inline)
    # whole trips: the session is longer than asked for (a trip out alone is ~3 h)
    return {"hours": round(n_pipe / len(CHANNELS) / 3600, 2), "messages": n_pipe,
            "simulate_s": round(made, 1),
            "bare_s": round(bare_s, 3), "bare_rate": round(n_bare / bare_s),
            "pipeline_s": round(pipe_s, 3), "pipeline_rate": round(n_pipe / pipe_s),
            "ratio": round(bare_s / pipe_s, 3),
            "inline_s": round(inline_s, 3), "inline_rate": round(n_inline / inline_s),
            "inline_ratio": round(bare_s / inline_s, 3),
            "bare_cpu_s": round(bare_cpu, 3), "inline_cpu_s": round(inline_cpu, 3),
            "pipeline_cpu_s": round(pipe_cpu, 3),
            "inline_cpu_ratio": round(bare_cpu / inline_cpu, 3),
            "input_bytes": src.stat().st_size}


def _wait_for_recorder_exit() -> None:
    """The recorder's close returns once its file is finished and leaves the wait for the
    child's exit to a thread: its CPU time counts only once that wait is over."""
    for thread in threading.enumerate():
        if thread.name == "tdmon-recorder-reap":
            thread.join()


def _children_cpu() -> float:
    """CPU time [s] of this process's ended and waited-for children."""
    times = os.times()
    return times.children_user + times.children_system


def long_session(days: float, sample: float, trace: bool, folder: Path) -> dict[str, Any]:
    src = folder / "long.mcap"
    _, made = make_session(src, days * 86400)
    with MemorySampler(sample, trace) as sampler:
        started = time.perf_counter()
        count = pipeline_replay(src, folder / "long-out.mcap")
        wall = time.perf_counter() - started
    samples = sampler.samples
    settled = [s for s in samples if s[0] >= 0.1 * wall] or samples
    mib = 1024 * 1024
    return {
        "days": days, "messages": count, "simulate_s": round(made, 1),
        "replay_s": round(wall, 1), "rate": round(count / wall),
        "input_bytes": src.stat().st_size,
        "output_bytes": (folder / "long-out.mcap").stat().st_size,
        "rss_first_MiB": round(settled[0][1] / mib, 1) if settled else None,
        "rss_last_MiB": round(settled[-1][1] / mib, 1) if settled else None,
        "rss_peak_MiB": round(max(s[1] for s in samples) / mib, 1) if samples else None,
        "traced_first_MiB": round(settled[0][2] / mib, 1) if trace and settled else None,
        "traced_last_MiB": round(settled[-1][2] / mib, 1) if trace and settled else None,
        "samples": len(samples),
    }


def _timed_process(command: list[str]) -> tuple[float, float]:
    """Run ``command``; its wall time [s] and peak resident memory [MiB] (``ru_maxrss`` of the
    child, from ``wait4``: its own, not this process's)."""
    started = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - started
    process.returncode = os.waitstatus_to_exitcode(status)
    error = process.stderr.read().decode() if process.stderr is not None else ""
    if process.returncode != 0:
        raise RuntimeError(f"{command} failed ({process.returncode}): {error[-2000:]}")
    return wall, usage.ru_maxrss / 1024  # ru_maxrss is in KiB on Linux


def summary_memory(hours: list[float], repeat: int, sessions: Path) -> dict[str, Any]:
    """``tdmon replay --json`` against the library replay, per session length (docstring, 3)."""
    sessions.mkdir(parents=True, exist_ok=True)
    library = ("import sys, tdmon; tdmon.replay(sys.argv[1], sys.argv[2], config=sys.argv[3])")
    rows = []
    for length in hours:
        src = sessions / f"session-{length:g}h.mcap"
        if not src.exists():
            # the programme comes in whole phases (~3.3 h at the least): cut to the length
            whole = sessions / f"session-{length:g}h-whole.mcap"
            if not whole.exists():
                make_session(whole, length * 3600)
            cut_session(whole, src, length * 3600)
        out = sessions / f"out-{length:g}h.mcap"
        command = [sys.executable, "-m", "tdmon", "replay", str(src), "--config", str(CONFIG),
                   "--out", str(out), "--no-progress", "--json"]
        call = [sys.executable, "-c", library, str(src), str(out), str(CONFIG)]
        cli_s, cli_mib, lib_s, lib_mib = [], [], [], []
        for _ in range(repeat):  # in turn: a change of the machine's load hits both alike
            wall, peak = _timed_process(command)
            cli_s.append(wall)
            cli_mib.append(peak)
            wall, peak = _timed_process(call)
            lib_s.append(wall)
            lib_mib.append(peak)
        rows.append({"hours": length, "messages": _raw_count(src),
                     "cli_s": [round(x, 2) for x in cli_s],
                     "library_s": [round(x, 2) for x in lib_s],
                     "cli_over_library": [round(a / b, 3) for a, b in zip(cli_s, lib_s,
                                                                          strict=True)],
                     "cli_peak_MiB": round(max(cli_mib), 1),
                     "library_peak_MiB": round(max(lib_mib), 1)})
    return {"sessions": rows,
            "peak_ratio": round(rows[-1]["cli_peak_MiB"] / rows[0]["cli_peak_MiB"], 3)}


def cut_session(src: Path, dst: Path, seconds: float) -> int:
    """Copy the input messages of ``src``'s first ``seconds`` of log time to ``dst`` (with
    their channels and schemas, zstd chunks); returns how many."""
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    schemas: dict[int, Schema] = {}
    channels: dict[int, int] = {}  # source channel id -> written channel id
    count, end = 0, None
    with src.open("rb") as stream, dst.open("wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD, chunk_size=4 * 1024 * 1024)
        writer.start()
        for record in StreamReader(stream).records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel) and not record.topic.startswith("/truth"):
                schema = schemas.get(record.schema_id)
                schema_id = 0 if schema is None else writer.register_schema(
                    schema.name, schema.encoding, schema.data)
                channels[record.id] = writer.register_channel(
                    record.topic, record.message_encoding, schema_id, dict(record.metadata))
            elif isinstance(record, Message) and record.channel_id in channels:
                end = record.log_time + int(seconds * 1e9) if end is None else end
                if record.log_time >= end:
                    break
                writer.add_message(channels[record.channel_id], record.log_time, record.data,
                                   record.publish_time, sequence=record.sequence)
                count += 1
        writer.finish()
    return count


def _raw_count(path: Path) -> int | None:
    from tdmon.replay.driver import raw_message_count

    return raw_message_count(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--hours", type=float, default=1.0,
                        help="session for the ratio [h], rounded up to whole phases")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--days", type=float, default=7.0, help="long session [days]; 0: skip")
    parser.add_argument("--sample", type=float, default=5.0, help="memory sampling [s]")
    parser.add_argument("--tracemalloc", action="store_true")
    parser.add_argument("--profile", action="store_true", help="cProfile one replay (ratio file)")
    parser.add_argument("--blas-threads", type=int, default=None,
                        help="OPENBLAS_NUM_THREADS for this run (default: OpenBLAS's own)")
    parser.add_argument("--json", type=Path, help="write the figures here")
    parser.add_argument("--tmp", type=Path, help="folder for the generated files")
    parser.add_argument("--summary-memory", action="store_true",
                        help="only measurement 3: the command's peak memory and wall time "
                             "against the library replay")
    parser.add_argument("--summary-hours", default="1,24",
                        help="session lengths for --summary-memory [h], comma-separated")
    parser.add_argument("--sessions", type=Path,
                        help="--summary-memory: keep the sessions here (reused when present)")
    args = parser.parse_args(argv)
    if args.blas_threads is not None:
        # must precede numpy's import (tdmon is imported lazily below): OpenBLAS's threads
        # make the friction profile's 141 x 141 covariance products ~16x slower on a busy
        # 2-core machine
        if "numpy" in sys.modules:
            parser.error("--blas-threads: numpy is already imported")
        os.environ["OPENBLAS_NUM_THREADS"] = str(args.blas_threads)

    results: dict[str, Any] = {"blas_threads": args.blas_threads}
    with tempfile.TemporaryDirectory(dir=args.tmp) as tmp:
        folder = Path(tmp)
        if args.summary_memory:
            hours = [float(h) for h in args.summary_hours.split(",")]
            results["summary"] = r = summary_memory(hours, args.repeat, args.sessions or folder)
            print("| rig time | messages | tdmon replay --json [s] | library replay [s] | "
                  "ratio | peak RSS, command [MiB] | peak RSS, library [MiB] |\n"
                  "|---|---|---|---|---|---|---|")
            for row in r["sessions"]:
                print(f"| {row['hours']:g} h | {row['messages']} | "
                      f"{', '.join(map(str, row['cli_s']))} | "
                      f"{', '.join(map(str, row['library_s']))} | "
                      f"{', '.join(map(str, row['cli_over_library']))} | "
                      f"{row['cli_peak_MiB']} | {row['library_peak_MiB']} |")
            print(f"peak at {hours[-1]:g} h / peak at {hours[0]:g} h: {r['peak_ratio']}")
            if args.json:
                args.json.write_text(json.dumps(results, indent=2))
            return 0
        if args.profile:
            src = folder / "session.mcap"
            make_session(src, args.hours * 3600)
            profile = cProfile.Profile()
            # in-process recorder: a child process's work would be invisible to cProfile
            profile.runcall(pipeline_replay, src, folder / "pipe.mcap", False)
            pstats.Stats(profile).sort_stats("tottime").print_stats(25)
            return 0
        results["ratio"] = ratio(args.hours, args.repeat, folder)
        r = results["ratio"]
        print(f"| rig time | messages | bare read+decode+write | pipeline, recorder in a child "
              f"process (--recorder process) | ratio | pipeline, recorder in-process (the default) "
              f"| ratio |\n"
              f"|---|---|---|---|---|---|---|\n"
              f"| {r['hours']:g} h | {r['messages']} | {r['bare_s']} s ({r['bare_rate']} msg/s) "
              f"| {r['pipeline_s']} s ({r['pipeline_rate']} msg/s) | {r['ratio']} "
              f"| {r['inline_s']} s ({r['inline_rate']} msg/s) | {r['inline_ratio']} |\n"
              f"CPU time: bare {r['bare_cpu_s']} s, in-process replay {r['inline_cpu_s']} s, "
              f"ratio {r['inline_cpu_ratio']}; replay with the child-process recorder "
              f"{r['pipeline_cpu_s']} s (both processes)", flush=True)
        if args.days > 0:
            results["long"] = long_session(args.days, args.sample, args.tracemalloc, folder)
            r = results["long"]
            print(f"\n{r['days']:g} days: {r['messages']} messages replayed in {r['replay_s']} s "
                  f"({r['rate']} msg/s; simulated in {r['simulate_s']} s); RSS "
                  f"{r['rss_first_MiB']} MiB after 10 % -> {r['rss_last_MiB']} MiB at the end "
                  f"(peak {r['rss_peak_MiB']} MiB)"
                  + (f"; traced heap {r['traced_first_MiB']} -> {r['traced_last_MiB']} MiB"
                     if args.tracemalloc else ""))
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
