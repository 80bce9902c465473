"""SIGINT is handled from the entry point's first line, even for a process started with SIGINT
ignored (what a shell without job control does to a background job): ``tdmon/cli/__init__.py``
arms it before its other imports, and ``python -m tdmon`` and the console script reach it
first. A SIGINT from then on ends the command with code 130 and one line, whatever stage it
lands in."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from sigint_support import wait_until_sigint_handled

ROOT = Path(__file__).resolve().parents[2]
CONSOLE_SCRIPT = Path(sys.executable).with_name("tdmon")  # installed by `pip install -e .`

# Records, the first time each module is imported, whether SIGINT is still ignored; then runs
# the entry point given as ENTRY (its exit, e.g. from --version, is caught).
PROBE = """
import json, signal, sys
seen = {}
class Watch:
    def find_spec(self, name, path=None, target=None):
        if name in ("argparse", "tdmon.blas", "tdmon.errors", "tdmon.cli.model") \\
                and name not in seen:
            seen[name] = signal.getsignal(signal.SIGINT) is not signal.SIG_IGN
        return None
sys.meta_path.insert(0, Watch())
sys.argv = ["tdmon", "--version"]
try:
    ENTRY
except SystemExit:
    pass
print(json.dumps(seen))
"""

ENTRIES = {
    "tdmon.cli": "import tdmon.cli; tdmon.cli.main(['--version'])",
    "python -m tdmon": "import runpy; runpy.run_module('tdmon', run_name='__main__')",
    "console script": f"import runpy; runpy.run_path({str(CONSOLE_SCRIPT)!r}, "
                      "run_name='__main__')",
}


def _ignoring_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@pytest.mark.parametrize("entry", list(ENTRIES))
def test_sigint_is_armed_before_the_entry_points_own_imports(entry: str) -> None:
    assert CONSOLE_SCRIPT.exists(), "the console script comes with `pip install -e .`"
    done = subprocess.run(
        [sys.executable, "-c", PROBE.replace("ENTRY", ENTRIES[entry])], capture_output=True,
        text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=ROOT,
        preexec_fn=_ignoring_sigint, check=True)
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    # every import after tdmon.cli's first lines already sees SIGINT handled
    assert seen == {"argparse": True, "tdmon.blas": True, "tdmon.errors": True,
                    "tdmon.cli.model": True}, done.stdout


@pytest.mark.parametrize("entry", ["python -m tdmon", "console script"])
def test_sigint_during_start_ends_the_command_with_130(
        entry: str, tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    csv = tmp_path / "rig.csv"
    csv.write_text("TIME,HKLD\n" + "".join(f"{1.7e9 + i:.1f},{i}\n" for i in range(50)))
    command = [sys.executable, "-m", "tdmon"] if entry == "python -m tdmon" else [
        str(CONSOLE_SCRIPT)]
    err = tmp_path / "err.txt"
    with err.open("w") as handle:
        process = subprocess.Popen(
            [*command, "publish", str(csv), "--zenoh-listen",
             f"tcp/127.0.0.1:{free_tcp_port()}", "--columns", "hookload=HKLD:kN",
             "--time-column", "TIME", "--speed", "1"],
            stdout=subprocess.DEVNULL, stderr=handle, env={**os.environ, "PYTHONPATH": str(ROOT)},
            preexec_fn=_ignoring_sigint)
    try:
        wait_until_sigint_handled(process)
        process.send_signal(signal.SIGINT)
        code = process.wait(60)  # generous: a loaded machine
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(10)
    log = err.read_text()
    # death by SIGINT itself (-2) is what a SIGINT during the interpreter's shutdown gives
    assert code in (130, -signal.SIGINT), log
    assert "Traceback" not in log
    assert "tdmon: interrupted" in log or "publish stopped by SIGINT" in log, log
