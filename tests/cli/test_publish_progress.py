"""``tdmon publish`` started from a script: Ctrl-C (SIGINT) stops it promptly at any stage,
even with SIGINT ignored as a shell does for background jobs, and it reports its progress
(sent of total, rate, time left) as plain lines."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from sigint_support import wait_until_sigint_handled

from tdmon.cli.run import _duration, _ProgressLines

TDMON = [sys.executable, "-m", "tdmon"]


def _csv(folder: Path, rows: int = 600) -> Path:
    path = folder / "rig.csv"
    path.write_text("TIME,HKLD\n" + "".join(f"{1.7e9 + i * 0.1:.3f},{i}\n" for i in range(rows)))
    return path


def _start(csv: Path, port: int, err: Path) -> subprocess.Popen[bytes]:
    with err.open("w") as handle:
        return subprocess.Popen(
            [*TDMON, "publish", str(csv), "--zenoh-listen", f"tcp/127.0.0.1:{port}",
             "--columns", "hookload=HKLD:kN", "--time-column", "TIME", "--speed", "1",
             "--status-every", "0.5"],
            stdout=subprocess.DEVNULL, stderr=handle,
            # what a shell without job control does to a background job
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))


def _stop(process: subprocess.Popen[bytes]) -> int:
    """SIGINT, then the exit code; death by SIGINT itself (-2, which a shell reports as 130,
    as for exit code 130) counts as 130: a SIGINT during the interpreter's own start-up or
    shutdown ends it that way."""
    process.send_signal(signal.SIGINT)
    try:
        code = process.wait(60)  # generous: a loaded CI machine
        return 130 if code == -signal.SIGINT else code
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(10)


def test_sigint_while_starting_and_while_publishing(tmp_path: Path,
                                                   free_tcp_port: Callable[[], int]) -> None:
    csv = _csv(tmp_path)
    # as soon as the entry point handles SIGINT (its first line, while the command's modules
    # are imported), and later in the start (the CSV counted, the Zenoh peer awaited): the
    # outcome is the same whenever the SIGINT lands, so the pause is not a timing condition
    for pause in (0.0, 2.0):
        err = tmp_path / f"early-{pause}.err"
        process = _start(csv, free_tcp_port(), err)
        wait_until_sigint_handled(process)
        time.sleep(pause)
        assert _stop(process) == 130, err.read_text()
        assert "Traceback" not in err.read_text()
    # while publishing: the progress lines come, then SIGINT ends it with a summary
    err = tmp_path / "publishing.err"
    process = _start(csv, free_tcp_port(), err)
    deadline = time.monotonic() + 60
    while "messages (" not in err.read_text():
        assert time.monotonic() < deadline and process.poll() is None, err.read_text()
        time.sleep(0.1)
    assert _stop(process) == 130
    log = err.read_text()
    assert "Traceback" not in log
    progress = [x for x in log.splitlines() if "messages (" in x]
    sent, total, share = re.fullmatch(
        r"tdmon: publish: (\d+) of (\d+) messages \(([\d.]+) %\), \d+ msg/s, about .+ left",
        progress[0]).groups()  # type: ignore[union-attr]
    assert int(total) == 600 and 0 < int(sent) < 600
    assert float(share) == round(100 * int(sent) / 600, 1)
    stopped = next(x for x in log.splitlines() if "stopped by SIGINT" in x)
    assert " of 600 messages delivered" in stopped


def test_progress_line_numbers() -> None:
    lines = _ProgressLines(total=11169, every=10.0)
    # 1200 messages in 10 s: 120/s, 9969 left: 83 s
    assert lines.line(1200, 10.0) == ("1200 of 11169 messages (10.7 %), 120 msg/s, "
                                      "about 1 min 23 s left")
    assert _ProgressLines(total=None, every=1.0).line(50, 2.0) == "50 messages, 25 msg/s"
    assert [_duration(s) for s in (4.4, 65, 7620)] == ["4 s", "1 min 05 s", "2 h 07 min"]
