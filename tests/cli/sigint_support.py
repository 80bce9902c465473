"""Waiting until a child process handles SIGINT, read from Linux's /proc/PID/status, so that a
test sends SIGINT when the process can take it rather than after a guessed delay (a SIGINT sent
while a process still ignores it, during the interpreter's own start, is lost for good)."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path


def handles_sigint(pid: int) -> bool:
    """Whether process ``pid`` has a handler of its own for SIGINT (its ``SigCgt`` mask)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) & (1 << (signal.SIGINT - 1)))
    raise AssertionError(f"/proc/{pid}/status has no SigCgt line")


def wait_until_sigint_handled(process: subprocess.Popen[bytes], timeout: float = 60.0) -> None:
    """Return once ``process`` handles SIGINT; fail if it exits first or ``timeout`` passes
    (generous: a loaded machine starts Python slowly)."""
    deadline = time.monotonic() + timeout
    while not handles_sigint(process.pid):
        assert process.poll() is None, f"exited with {process.returncode} before arming SIGINT"
        assert time.monotonic() < deadline, f"SIGINT not handled after {timeout} s"
        time.sleep(0.005)
