"""`tdmon model warmup` prepares what the model's callers use: the real calls add no numba
signature after it (each new one would be compiled in the first real command), and a new
process finds every entry point in numba's cache and compiles none."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tdmon.calib.backcalc import back_calculate
from tdmon.cli import main
from tdmon.model import kernels, warmup
from tdmon.model.broomstick import broomstick_from_model
from tdmon.model.fluid_terms import FluidTerms
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Well

ROOT = Path(__file__).resolve().parents[2]


def _signatures() -> list[list[object]]:
    module = kernels.load("numba").module
    return [list(getattr(module, name).signatures) for name in kernels.ENTRY_POINTS]


def test_the_model_calls_only_signatures_the_warmup_compiled(three_d: Well) -> None:
    warmup.compile_kernels()
    compiled = _signatures()
    assert all(compiled)  # each entry point has machine code
    model = WellModel(three_d, engine="numba")  # a well file's shapes: sections' friction
    for method in ("soft-string", "aadnoy"):
        model.evaluate("pick_up", 3000.0, None, method=method)
        model.evaluate("rotating", 3000, 0.3, method=method, psi=0.2)
        model.evaluate("on_bottom", 3000.0, model.friction(0.2), method=method, wob=9e4,
                       bit_torque=3e3)
        model.evaluate_cases("slack_off", 3000.0, np.full((3, model.n_elements), 0.2),
                             method=method)
        model.evaluate_gradient("rotating", 3000.0, 0.25, quantity_index=1, method=method)
        model.loads(3000.0, None, method=method)
        broomstick_from_model(model, np.arange(500.0, 3001.0, 500.0), [0.1, 0.2],
                              method=method)
        measured = model.evaluate("pick_up", 2500.0, 0.22, method=method)[0]
        back_calculate(model, "pick_up", 2500.0, measured, 1e3, method=method)
        # with fluid terms: the same argument types as without
        fluid = FluidTerms(axial=np.full(model.n_elements, 10.0), bit_force=-2e3,
                           inside_density=np.full(model.n_elements, 1500.0))
        model.evaluate("pick_up", 3000.0, 0.2, method=method, fluid=fluid)
        model.evaluate_cases("slack_off", 3000.0, np.full((3, model.n_elements), 0.2),
                             method=method, fluid=fluid)
        model.evaluate_gradient("pick_up", 3000.0, 0.25, method=method, fluid=fluid)
        model.loads(3000.0, None, method=method, fluid=fluid)
        broomstick_from_model(model, [1000.0, 3000.0], [0.1, 0.2], method=method,
                              fluid=lambda depth, operation, terms=fluid: terms)
    assert _signatures() == compiled
    assert [len(signatures) for signatures in compiled] == [1] * len(kernels.ENTRY_POINTS)


def test_after_the_warmup_a_new_process_compiles_nothing(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["model", "warmup"]) == 0
    (line,) = capsys.readouterr().out.strip().splitlines()
    assert line.startswith("model kernels: ") and "numba cache: " in line
    done = warmup.warm_up()  # again, in this process: each entry point counted once
    assert done.compiled + done.loaded == len(kernels.ENTRY_POINTS)
    assert sorted(Path(done.cache_folder).glob("_kernels.march_one-*.nbi"))
    script = ("import json\n"
              "from tdmon.model import kernels, warmup\n"
              "warmup.compile_kernels()\n"
              "module = kernels.load('numba').module\n"
              "stats = [getattr(module, name).stats for name in kernels.ENTRY_POINTS]\n"
              "print(json.dumps([[sum(s.cache_hits.values()), sum(s.cache_misses.values())]"
              " for s in stats]))\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop(kernels.ENVIRONMENT, None)
    new = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env=env, cwd=ROOT, timeout=600, check=True)
    hits_and_misses = json.loads(new.stdout.strip().splitlines()[-1])
    assert hits_and_misses == [[1, 0]] * len(kernels.ENTRY_POINTS)  # loaded, none compiled


def test_without_a_cache_folder_numba_can_write_the_error_says_what_to_do() -> None:
    """numba's locators find no folder (here: only the one for zipped sources is allowed):
    loading the numba kernels is a ModelError naming the remedies, not numba's RuntimeError."""
    script = ("from tdmon.errors import ModelError\n"
              "from tdmon.model import kernels\n"
              "try:\n"
              "    kernels.load('numba')\n"
              "except ModelError as error:\n"
              "    print(error)\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_CACHE_LOCATOR_CLASSES": "ZipCacheLocator"}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=120, check=True)
    message = done.stdout.strip()
    assert "no locator available" in message
    assert "NUMBA_CACHE_DIR" in message and "TDMON_KERNELS=python" in message
