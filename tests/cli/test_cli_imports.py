"""The command line starts without the heavy libraries: each check runs in a fresh interpreter
and reads its ``sys.modules`` (what is imported, not how long it takes), or, for the daemon,
the shared libraries its process maps. With the model's kernels built ahead of time (the
set-up's ``tdmon model warmup``), neither a model command nor the daemon loads numba."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tdmon.model import aot, kernels

ROOT = Path(__file__).resolve().parents[2]
WELL = ROOT / "config" / "wells" / "aadnoy-example-7-1.toml"
IDLE_WELL = ROOT / "replays" / "scenarios" / "wells" / "example-7-1-glydril.toml"

#: Imported by no command's start; each one costs 0.2-0.5 s or tens of MB (docs/benchmarks.md).
HEAVY = ("pandas", "pyarrow", "scipy.integrate", "rerun", "numba", "zenoh", "matplotlib")


def _modules_after(code: str) -> set[str]:
    """Module names in ``sys.modules`` after running ``code`` in a new interpreter."""
    script = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=120, check=True)
    return set(json.loads(done.stdout.strip().splitlines()[-1]))


def test_the_parser_imports_no_heavy_library_nor_numpy() -> None:
    loaded = _modules_after("import tdmon.cli\ntdmon.cli.build_parser()")
    assert "argparse" in loaded  # the probe sees what the parser imported
    assert sorted(loaded & {*HEAVY, "numpy", "scipy", "pint"}) == []


def test_help_imports_no_heavy_library() -> None:
    code = ("import contextlib, io, tdmon.cli\n"
            "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
            "    tdmon.cli.main(['model', 'loads', '--help'])")
    assert sorted(_modules_after(code) & {*HEAVY, "numpy"}) == []


@pytest.fixture(scope="module")
def ahead_of_time() -> str:
    """The kernels built ahead of time, as the set-up builds them; their module's name."""
    aot.ensure_built()
    return kernels.module_name()


def test_model_loads_runs_without_pandas_scipy_integrate_rerun_or_numba(
        ahead_of_time: str) -> None:
    code = ("import contextlib, io, tdmon.cli\n"
            "out = io.StringIO()\n"
            "with contextlib.redirect_stdout(out):\n"
            f"    assert tdmon.cli.main(['model', 'loads', '--well', {str(WELL)!r}]) == 0\n"
            "assert 'pick' in out.getvalue().lower()")
    loaded = _modules_after(code)
    assert ahead_of_time in loaded  # the command did run the model, on those kernels
    assert sorted(loaded & {"pandas", "pyarrow", "scipy.integrate", "rerun", "zenoh",
                            "matplotlib", "numba", "llvmlite", "tdmon.model._kernels"}) == []


def test_an_idle_daemon_maps_neither_numba_nor_llvm(
        ahead_of_time: str, tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    """`tdmon run` with the monitor and the calibration on (a `WellModel` built), nothing
    publishing: the ahead-of-time kernels are mapped, numba's and LLVM's libraries are not."""
    port = free_tcp_port()
    config = tmp_path / "idle.toml"
    config.write_text(
        f'prefix = "test/idle"\nwell = "{IDLE_WELL}"\n'
        f'[sources.zenoh]\nmode = "peer"\nlisten = ["tcp/127.0.0.1:{port}"]\nconnect = []\n'
        f'scouting = false\n[recorder]\nenabled = true\noutput = "{tmp_path / "rec"}"\n'
        f'[monitor]\nmu = 0.25\nband_mu = [0.1, 0.3]\ngrid_step = "50 m"\n'
        f'[calibration]\nenabled = true\n')
    log = tmp_path / "daemon.log"
    with log.open("w") as err:
        daemon = subprocess.Popen([sys.executable, "-m", "tdmon", "run", "--config", str(config)],
                                  env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=ROOT,
                                  stdout=subprocess.DEVNULL, stderr=err)
        try:
            deadline = time.monotonic() + 60
            while "daemon running" not in log.read_text():
                assert daemon.poll() is None, log.read_text()
                assert time.monotonic() < deadline, log.read_text()
                time.sleep(0.1)
            maps = Path(f"/proc/{daemon.pid}/maps").read_text()
        finally:
            daemon.send_signal(signal.SIGINT)
            try:
                daemon.wait(30)
            except subprocess.TimeoutExpired:
                daemon.kill()
                daemon.wait()
    libraries = {line.split()[-1] for line in maps.splitlines() if line.endswith(".so")
                 or ".so." in line}
    assert any(ahead_of_time in library for library in libraries)
    assert sorted(lib for lib in libraries if "numba" in lib or "llvmlite" in lib) == []

