"""Fill numba's on-disk cache with the model's kernels at set-up, so no later command compiles.

`warm_up` (``tdmon model warmup``, run by the set-up scripts) runs every entry point of the
numba kernels (`tdmon.model.kernels`) once on a small synthetic well, with the same argument
types as the model's own callers: numba keeps one machine code per signature, and a call with
another type would compile again in the first real command (`tests/model/test_warmup.py` checks
that the real calls add none). Each one numba compiles (about a minute for all, on a busy
machine) it stores in its cache: ``tdmon/model/__pycache__`` next to the source, or, when that
folder is not writable (a package installed by another user or read-only), numba's user-wide
cache folder for the user running the warm-up (``NUMBA_CACHE_DIR`` overrides both). So run it
as the user that runs the daemon, or point ``NUMBA_CACHE_DIR`` at a folder both share; run it
again after changing `tdmon/model/_kernels.py` or upgrading numba (the cache is keyed by the
source file and numba's version, and a stale entry is compiled again on first use).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from tdmon.model import kernels
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.survey import minimum_curvature
from tdmon.model.well import Fluid, HoleSection, Well


@dataclass(frozen=True)
class Warmup:
    """What `warm_up` did: how many entry points numba ``compiled`` (and stored) and how many
    it ``loaded`` from its cache, the ``seconds`` it took, and numba's ``cache_folder``."""

    compiled: int
    loaded: int
    seconds: float
    cache_folder: str


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


def compile_kernels(engine: str = "numba") -> float:
    """Call every entry point once through ``engine``'s kernels (numba's: loading each from
    its cache, or compiling and storing it). Returns the time it took [s]."""
    from tdmon.model.broomstick import broomstick_from_model
    from tdmon.model.torque_drag import METHODS, WellModel

    start = time.perf_counter()
    model = WellModel(_small_well(), engine=engine)
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
    """Compile the numba kernels of every entry point into numba's cache, or load them from
    it when they are there already (a ModelError when numba cannot be imported)."""
    seconds = compile_kernels("numba")
    module = kernels.load("numba").module
    compiled = loaded = 0
    folder = ""
    for name in kernels.ENTRY_POINTS:
        stats: Any = getattr(module, name).stats  # numba's counters of this dispatcher
        compiled += sum(stats.cache_misses.values()) > 0
        loaded += sum(stats.cache_hits.values()) > 0
        folder = str(stats.cache_path)
    return Warmup(compiled, loaded, seconds, folder)
