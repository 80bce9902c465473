"""How the model's element loops run: compiled by numba, or as plain Python.

The loops live once, in `tdmon.model._kernels`, as plain Python that imports no numba. `load`
hands them out in one of two engines with the same entry points and the same numbers bit for
bit (`tests/model/test_kernels.py` compares every `WellModel` call):

``"numba"`` (the default)
    every function of `_kernels` compiled by ``numba.njit(cache=True)``. numba keeps the
    machine code in its on-disk cache, next to the source (``tdmon/model/__pycache__``) or,
    where that folder is not writable (an installed package), in its user-wide cache folder
    (``NUMBA_CACHE_DIR`` overrides both); `tdmon model warmup` fills it at set-up so that no
    later process compiles. A process still pays numba's import and the cache's load, about a
    second here, on its first call.
``"python"``
    the functions as they are: a few hundred times slower per element, but no numba at all.
    A one-shot evaluation of one well (`tdmon model loads`) is done before numba would have
    loaded; and it serves where numba is missing or broken.

``TDMON_KERNELS`` (``numba`` or ``python``) sets the default; a `WellModel` built with
``engine=`` overrides it. This module imports numba only when the numba engine is loaded.
"""

from __future__ import annotations

import os
import types
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError
from tdmon.model import _kernels
from tdmon.model._kernels import (  # noqa: F401 (the model reads the loops' constants here)
    AADNOY,
    GENERAL_CURVE,
    PLANAR_BUILD,
    SOFT_STRING,
    STRAIGHT,
)

Engine = Literal["numba", "python"]
ENGINES: tuple[str, ...] = ("numba", "python")

#: The environment variable that chooses the default engine.
ENVIRONMENT = "TDMON_KERNELS"

#: The functions the model calls, by name, in both engines.
ENTRY_POINTS = ("pack_well", "all_finite_non_negative", "march_one", "march_cases",
                "march_profile", "sweep", "march_gradient")


@dataclass(frozen=True)
class Kernels:
    """Loaded kernels: the ``engine`` ("numba" or "python") and the ``module`` holding
    `ENTRY_POINTS` (numba's dispatchers, or `tdmon.model._kernels` itself)."""

    engine: str
    module: Any


class KernelWell(NamedTuple):
    """A well's arrays packed for the kernels (`tdmon.model._kernels.pack_well`): float64
    ``real`` and int64 ``integer``, every entry point's first two arguments."""

    real: NDArray[np.float64]
    integer: NDArray[np.int64]


def kernel_well(kernels: Kernels, *, node_md: ArrayLike, tangents: ArrayLike,
                dogleg: ArrayLike, curve_kind: ArrayLike, run_break: ArrayLike,
                component_top: ArrayLike, component_weight: ArrayLike,
                component_radius: ArrayLike, component_outside_sensitivity: ArrayLike,
                component_inside_sensitivity: ArrayLike) -> KernelWell:
    """Pack a well's arrays (see `tdmon.model._kernels.pack_well`) with ``kernels``.

    Each array is converted to the dtype and C layout the kernels' one compiled signature
    reads (copied only if it is not so already), so that no call compiles another.
    """
    vector = np.ascontiguousarray
    real, index = kernels.module.pack_well(
        vector(node_md, dtype=np.float64), vector(tangents, dtype=np.float64),
        vector(dogleg, dtype=np.float64), vector(curve_kind, dtype=np.int64),
        vector(run_break, dtype=np.bool_), vector(component_top, dtype=np.float64),
        vector(component_weight, dtype=np.float64), vector(component_radius, dtype=np.float64),
        vector(component_outside_sensitivity, dtype=np.float64),
        vector(component_inside_sensitivity, dtype=np.float64))
    return KernelWell(real, index)


def default_engine() -> str:
    """``TDMON_KERNELS`` as one of `ENGINES` ("numba" when unset; a ModelError otherwise)."""
    engine = os.environ.get(ENVIRONMENT, "numba").strip().lower() or "numba"
    if engine not in ENGINES:
        raise ModelError(f"environment variable {ENVIRONMENT}={engine!r}: use one of "
                         f"{', '.join(ENGINES)}")
    return engine


def load(engine: str | None = None) -> Kernels:
    """The kernels of ``engine`` (default `default_engine`): "numba" or "python"."""
    chosen = default_engine() if engine is None else engine
    if chosen == "python":
        return Kernels("python", _kernels)
    if chosen == "numba":
        return Kernels("numba", _compiled())
    raise ModelError(f"unknown kernels engine {chosen!r}: use one of {', '.join(ENGINES)}")


@lru_cache(maxsize=1)
def _compiled() -> types.SimpleNamespace:
    """Every function of `_kernels` compiled by numba, the entry points in a namespace.

    Each function is rebuilt on a copy of the module's globals in which every function is
    replaced by its numba dispatcher, so that a compiled loop calls compiled helpers; the code,
    file and name stay the module's, which is what numba's cache is keyed by. Nothing is
    compiled here: numba compiles (or loads from its cache) on a dispatcher's first call.
    """
    try:
        import numba
    except ImportError as error:
        raise ModelError(f"the model's numba kernels need numba ({error}); "
                         f"{ENVIRONMENT}=python runs them as plain Python") from error

    namespace = dict(vars(_kernels))
    plain = {name: value for name, value in namespace.items()
             if isinstance(value, types.FunctionType) and value.__module__ == _kernels.__name__}
    for name, function in plain.items():
        rebound = types.FunctionType(function.__code__, namespace, function.__name__,
                                     function.__defaults__, function.__closure__)
        rebound.__qualname__ = function.__qualname__
        rebound.__module__ = function.__module__
        rebound.__doc__ = function.__doc__
        try:
            namespace[name] = numba.njit(cache=True)(rebound)
        except RuntimeError as error:  # numba found no cache folder it can write
            raise ModelError(
                f"numba cannot cache the model's kernels ({error}): set NUMBA_CACHE_DIR to a "
                f"writable folder (and run 'tdmon model warmup' with it), or "
                f"{ENVIRONMENT}=python") from error
    return types.SimpleNamespace(**{name: namespace[name] for name in ENTRY_POINTS})
