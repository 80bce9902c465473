"""Prepare the model's kernels at set-up, so that no later command compiles them.

`warm_up` (``tdmon model warmup``, run by the set-up scripts) builds the kernels ahead of time
(`tdmon.model.aot`, about 15 s) unless the build of the current source is already there, then
runs every entry point once on a small synthetic well through the kernels `tdmon.model.kernels`
loads. Without a C compiler, or when the build fails, or with ``TDMON_KERNELS=jit``, those are
numba's JIT kernels (``cache=True``): the run compiles them (about 10 s) and numba stores the
machine code next to the source (``tdmon/model/__pycache__``, or numba's user-wide cache folder
when that is not writable, or ``NUMBA_CACHE_DIR``), where later processes load it.

Every call below passes the same argument types as the model's own callers: numba keeps one
machine code per signature (a call with another type would compile again), and the
ahead-of-time module has exactly one per entry point.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from tdmon.errors import ModelError
from tdmon.model import aot, kernels
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.survey import minimum_curvature
from tdmon.model.well import Fluid, HoleSection, Well


@dataclass(frozen=True)
class Warmup:
    """What `warm_up` did: the ``kernels`` now loaded, the ahead-of-time build's time [s]
    (None when none was run), the time of one call of every entry point [s], and why the JIT
    is used when it is (``note``, one line, empty otherwise)."""

    kernels: kernels.Kernels
    build_seconds: float | None
    call_seconds: float
    note: str


def _small_well() -> Well:
    """Vertical, build and hold with two components, cased and open hole: every branch."""
    survey = minimum_curvature([0.0, 300.0, 600.0, 1000.0], [0.0, 0.0, 40.0, 40.0],
                               [0.0, 0.0, 30.0, 45.0])
    string = DrillString((
        StringComponent("BHA", 100.0, outer_diameter=0.165, inner_diameter=0.07,
                        buoyed_weight=1500.0),
        StringComponent("drill pipe", 900.0, outer_diameter=0.127, inner_diameter=0.108,
                        buoyed_weight=250.0),
    ))
    return Well(survey=survey, string=string,
                sections=(HoleSection(0.0, 400.0, 0.22, "cased", friction=0.2),
                          HoleSection(400.0, 1000.0, 0.2159, "open", friction=0.3)),
                fluid=Fluid(density=1200.0), element_length=30.0, name="warm-up")


def compile_kernels() -> float:
    """Call every entry point once through the loaded kernels (on the JIT: loading each from
    numba's cache, or compiling and storing it). Returns the time it took [s]."""
    from tdmon.model.broomstick import broomstick_from_model
    from tdmon.model.torque_drag import METHODS, WellModel

    start = time.perf_counter()
    model = WellModel(_small_well())
    depth = 900.0
    for method in METHODS:
        model.evaluate("pick_up", depth, 0.25, method=method)
        model.evaluate_cases("rotating", depth, np.full((2, model.n_elements), 0.25),
                             method=method)
        model.evaluate_gradient("slack_off", depth, 0.25, method=method)
        model.loads(depth, 0.25, method=method)
        broomstick_from_model(model, [600.0, depth], [0.2, 0.3], method=method)
    return time.perf_counter() - start


def warm_up() -> Warmup:
    """Build the kernels ahead of time if needed (and possible), then run each once.

    A failed build is not an error but a note (the JIT serves), unless ``TDMON_KERNELS=aot``
    asks for the ahead-of-time kernels.
    """
    mode = kernels.mode()
    build_seconds = None
    note = ""
    if mode == "jit":
        note = f"{kernels.ENVIRONMENT}=jit"
    else:
        try:
            build_seconds = aot.ensure_built()
        except Exception as error:  # compilers and numba fail in many ways: each means the JIT
            first_line = (str(error).strip().splitlines() or [""])[0]
            reason = f"{type(error).__name__}: {first_line}"
            if not aot.compiler_available():
                reason = "no C compiler found"
            if mode == "aot":
                raise ModelError(f"{kernels.ENVIRONMENT}=aot but the ahead-of-time build "
                                 f"failed ({reason})") from error
            note = f"no ahead-of-time build ({reason})"
    kernels.forget()
    loaded = kernels.load()
    return Warmup(loaded, build_seconds, compile_kernels(), note)


def cache_folder() -> str:
    """Where numba keeps the JIT kernels' machine code (for messages)."""
    from tdmon.model import _kernels

    cache = getattr(_kernels.march_one, "_cache", None)
    return str(getattr(cache, "cache_path", "numba's cache folder"))
