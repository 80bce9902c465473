"""Compile every numba kernel into numba's on-disk cache, on a small synthetic well.

The kernels are ``cache=True``: the first call in any process compiles them (about 10 s for
all of them) and stores the machine code next to the source (``tdmon/model/__pycache__``, or
numba's user-wide cache folder when that is not writable, or ``NUMBA_CACHE_DIR``). Later
processes load it in a fraction of a second. Run by the set-up scripts (``tdmon model warmup``)
so that the first real command does not pay the compilation.

Every call below passes the same argument types as the model's own callers: numba keeps one
machine code per signature, and a call with another type (an int for a float, a strided array)
would compile again.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from tdmon.model import _kernels
from tdmon.model.broomstick import broomstick_from_model
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.survey import minimum_curvature
from tdmon.model.torque_drag import METHODS, WellModel
from tdmon.model.well import Fluid, HoleSection, Well

#: The compiled entry points (numba dispatchers) the model calls.
ENTRY_POINTS: tuple[Any, ...] = (
    _kernels._pack_well, _kernels.march_one, _kernels.march_cases, _kernels.march_profile,
    _kernels.sweep, _kernels.march_gradient, _kernels.all_finite_non_negative,
)


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
    """Call every kernel once (loading it from numba's cache, or compiling and storing it).

    Returns the time it took [s].
    """
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


def cache_folder() -> str:
    """Where numba keeps the kernels' machine code (for messages)."""
    cache = getattr(_kernels.march_one, "_cache", None)
    return str(getattr(cache, "cache_path", "numba's cache folder"))
