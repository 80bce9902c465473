"""The command line starts without the heavy libraries: each check runs in a fresh interpreter
and reads its ``sys.modules`` (what is imported, not how long it takes). ``tdmon model loads``
runs the model's loops as plain Python: it does not load numba either (the daemon does, from
numba's cache)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
WELL = ROOT / "config" / "wells" / "aadnoy-example-7-1.toml"

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


def test_model_loads_runs_without_pandas_scipy_integrate_rerun_or_numba() -> None:
    code = ("import contextlib, io, tdmon.cli\n"
            "out = io.StringIO()\n"
            "with contextlib.redirect_stdout(out):\n"
            f"    assert tdmon.cli.main(['model', 'loads', '--well', {str(WELL)!r}]) == 0\n"
            "assert 'pick' in out.getvalue().lower()")
    loaded = _modules_after(code)
    assert "tdmon.model._kernels" in loaded  # the command did run the model's loops
    assert sorted(loaded & {"pandas", "pyarrow", "scipy.integrate", "rerun", "zenoh",
                            "matplotlib", "numba", "llvmlite"}) == []

