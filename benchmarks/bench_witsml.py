"""Benchmark of ``tdmon import witsml`` on a large time log: speed and memory.

Run: ``.venv/bin/python benchmarks/bench_witsml.py [--mb 50] [--json out.json]``

Synthesises a WITSML 1.4.1.1 time log of about ``--mb`` MB in a temporary folder by repeating the
rows of the bundled Volve F-4 log (``data/volve-f4/witsml/GwdTime-2016-10-03-to-05.xml``, 7106
rows of 31 curves at 15 s) with their times shifted past the previous copy, then imports it with
:func:`tdmon.replay.witsml_import.import_witsml` in this process (the path the command takes),
while a thread samples the resident memory (``VmRSS`` of /proc/self/status) and how far the
parser has read the input (the file offset in /proc/self/fdinfo). Prints the wall time, MB/s,
rows/s, the RSS before the import, at 10 % of the input, at the end, and the peak (``VmHWM``):
flat memory means the end is within a few MB of the 10 % figure whatever the file's size.
Project virtualenv; Linux only (reads /proc). Figures in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import threading
import time
from datetime import UTC, datetime
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
VOLVE_LOG = REPO / "data" / "volve-f4" / "witsml" / "GwdTime-2016-10-03-to-05.xml"


def _status(field: str) -> float:
    """A /proc/self/status field in MB (VmRSS, VmHWM)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError(f"no {field} in /proc/self/status")


def _offset(path: Path) -> int | None:
    """Where this process has read ``path`` to (None when it is not open)."""
    target = str(path.resolve())
    for fd in os.listdir("/proc/self/fd"):
        try:
            if os.readlink(f"/proc/self/fd/{fd}") == target:
                for line in Path(f"/proc/self/fdinfo/{fd}").read_text().splitlines():
                    if line.startswith("pos:"):
                        return int(line.split()[1])
        except OSError:
            continue
    return None


def synthesise(target: Path, megabytes: float) -> int:
    """Write a log of about ``megabytes`` MB from the Volve rows; returns the number of rows."""
    text = VOLVE_LOG.read_text(encoding="utf-8")
    start = text.index("<data>")
    end = text.rindex("</data>") + len("</data>")
    head, body, tail = text[:start], text[start:end], text[end:]
    rows = [row.removeprefix("<data>") for row in body.split("</data>") if row]
    stamps = [datetime.fromisoformat(row.split(",", 1)[0]).timestamp() for row in rows]
    period = stamps[-1] - stamps[0] + 15.0
    copies = max(1, round(megabytes * 1e6 / len(body.encode())))
    with target.open("w", encoding="utf-8") as out:
        out.write(head)
        for copy in range(copies):
            shift = copy * period
            for stamp, row in zip(stamps, rows, strict=True):
                when = datetime.fromtimestamp(stamp + shift, UTC)
                out.write(f"<data>{when.strftime('%Y-%m-%dT%H:%M:%S.000Z')},"
                          f"{row.split(',', 1)[1]}</data>")
        out.write(tail)
    return copies * len(rows)


def run(megabytes: float) -> dict[str, float | int | str]:
    from tdmon.replay.witsml_import import import_witsml

    with tempfile.TemporaryDirectory() as folder:
        log = Path(folder) / "big-log.xml"
        rows = synthesise(log, megabytes)
        size = log.stat().st_size
        rss_before = _status("VmRSS")
        samples: list[tuple[float, float]] = []  # (fraction read, RSS [MB])
        done = threading.Event()

        def sample() -> None:
            while not done.wait(0.05):
                position = _offset(log)
                if position is not None:
                    samples.append((position / size, _status("VmRSS")))

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        began = time.perf_counter()
        result = import_witsml([log], Path(folder) / "out.mcap", prefix="rig/bench")
        seconds = time.perf_counter() - began
        done.set()
        sampler.join()
        rss_end = _status("VmRSS")
        at_10 = next((rss for fraction, rss in samples if fraction >= 0.10), float("nan"))
        out_mb = (Path(folder) / "out.mcap").stat().st_size / 1e6
    return {
        "command": "import_witsml([log], out, prefix='rig/bench') (= tdmon import witsml)",
        "input_MB": round(size / 1e6, 1), "rows": rows, "rows_written": result.rows,
        "messages": result.messages, "output_MB": round(out_mb, 1),
        "seconds": round(seconds, 2), "MB_per_s": round(size / 1e6 / seconds, 2),
        "rows_per_s": round(rows / seconds), "rss_before_MB": round(rss_before, 1),
        "rss_at_10pct_MB": round(at_10, 1), "rss_end_MB": round(rss_end, 1),
        "peak_rss_MB": round(_status("VmHWM"), 1), "samples": len(samples),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mb", type=float, default=50.0, help="size of the synthetic log [MB]")
    parser.add_argument("--json", type=Path, help="write the figures as JSON")
    args = parser.parse_args()
    figures = run(args.mb)
    for key, value in figures.items():
        print(f"{key:>16}: {value}")
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
