"""Which compiled kernels the model runs: the ahead-of-time module, or numba's JIT.

The element loops live once, in `tdmon.model._kernels` (numba ``@njit``). `tdmon model warmup`
compiles them ahead of time (`tdmon.model.aot`) into an extension module in the user's cache
folder (``~/.cache/tdmon/kernels`` on Linux), named by a key of the kernels' source, numba's and
numpy's versions, the Python ABI and the processor level it targets. `load` returns that module
when it is there for the current key: then neither numba nor LLVM is imported, which saves about
120 MB and most of a second per process (docs/benchmarks.md). Otherwise (not built yet, a
changed source, no C compiler at set-up) it returns `tdmon.model._kernels` itself, compiled by
numba on the first call and kept in numba's cache, and logs why at INFO. Both run the same
functions and give the same numbers.

``TDMON_KERNELS`` chooses: ``auto`` (the default, as above), ``jit`` (numba always) or ``aot``
(the ahead-of-time module or an error). This module imports neither numba nor the kernels.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.machinery
import importlib.util
import logging
import os
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from types import ModuleType
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError

_log = logging.getLogger(__name__)

SOFT_STRING = 0
AADNOY = 1

# element curve kinds (of the survey interval the element lies on)
STRAIGHT = 0
PLANAR_BUILD = 1
GENERAL_CURVE = 2

#: The environment variable that chooses the kernels: "auto", "jit" or "aot".
ENVIRONMENT = "TDMON_KERNELS"
_MODES = ("auto", "jit", "aot")

#: The functions the model calls, by name, in both kinds of kernels (positional arguments).
ENTRY_POINTS = ("pack_well", "all_finite_non_negative", "march_one", "march_cases",
                "march_profile", "sweep", "march_gradient")

_HERE = Path(__file__).resolve().parent
#: The files whose text the ahead-of-time build depends on.
_SOURCES = (_HERE / "_kernels.py", _HERE / "aot.py", _HERE / "kernels.py")


@dataclass(frozen=True)
class Kernels:
    """Loaded kernels: ``kind`` "aot" or "jit", the ``module`` holding `ENTRY_POINTS`, and
    ``where`` they come from (the extension module's path, or numba's JIT)."""

    kind: str
    module: Any
    where: str


class KernelWell(NamedTuple):
    """A well's arrays packed for the kernels (`tdmon.model._kernels.pack_well`): float64
    ``real`` and int64 ``integer``, every entry point's first two arguments."""

    real: NDArray[np.float64]
    integer: NDArray[np.int64]


def kernel_well(kernels: Kernels, *, node_md: ArrayLike, tangents: ArrayLike,
                dogleg: ArrayLike, curve_kind: ArrayLike, run_break: ArrayLike,
                component_top: ArrayLike, component_weight: ArrayLike,
                component_radius: ArrayLike) -> KernelWell:
    """Pack a well's arrays (see `tdmon.model._kernels.pack_well`) with ``kernels``.

    Each array is converted to the dtype and C layout the kernels read (copied only if it is
    not so already): the ahead-of-time module checks neither.
    """
    vector = np.ascontiguousarray
    real, index = kernels.module.pack_well(
        vector(node_md, dtype=np.float64), vector(tangents, dtype=np.float64),
        vector(dogleg, dtype=np.float64), vector(curve_kind, dtype=np.int64),
        vector(run_break, dtype=np.bool_), vector(component_top, dtype=np.float64),
        vector(component_weight, dtype=np.float64), vector(component_radius, dtype=np.float64))
    return KernelWell(real, index)


def _numba_version_text() -> bytes:
    """numba's version file, read without importing numba (importlib.metadata costs 50 ms)."""
    spec = importlib.util.find_spec("numba")
    if spec is None or spec.origin is None:
        return b"no numba"
    try:
        return (Path(spec.origin).parent / "_version.py").read_bytes()
    except OSError:
        return spec.origin.encode()


# the x86-64 micro-architecture levels, and the /proc/cpuinfo flags each needs beyond the last
_X86_LEVELS = (
    ("x86-64-v2", {"cx16", "lahf_lm", "popcnt", "sse4_1", "sse4_2", "ssse3"}),
    ("x86-64-v3", {"avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "movbe", "xsave", "abm"}),
    ("x86-64-v4", {"avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl"}),
)


@lru_cache(maxsize=1)
def target_cpu() -> str:
    """The processor the ahead-of-time build targets: the highest x86-64 level this one has
    (its flags in Linux's /proc/cpuinfo), or "" (the architecture's generic processor).

    Not the processor's own model: numba's pycc with the model's tuning ran Aadnoy's march
    a third slower here (AMD znver4), the level as fast as the JIT (docs/benchmarks.md). The
    level is part of the build's key, so a processor without it finds no build.
    """
    if "x86_64" not in importlib.machinery.EXTENSION_SUFFIXES[0]:
        return ""
    try:
        with open("/proc/cpuinfo", "rb") as info:
            head = info.read(32768).decode("ascii", "replace")
    except OSError:
        return ""
    for line in head.splitlines():
        name, _, value = line.partition(":")
        if name.strip() == "flags":
            return x86_level(set(value.split()))
    return ""


def x86_level(flags: set[str]) -> str:
    """The highest x86-64 micro-architecture level whose flags (/proc/cpuinfo's names) are all
    in ``flags``, or "" for the baseline x86-64."""
    level = ""
    for name, needed in _X86_LEVELS:
        if not needed <= flags:
            break
        level = name
    return level


@lru_cache(maxsize=1)
def build_key() -> str:
    """Hex key of what the ahead-of-time module is built from: the kernels' source, numba's
    and numpy's versions, the Python ABI and the platform (the extension suffix), and the
    target processor (`target_cpu`)."""
    digest = hashlib.sha256()
    for source in _SOURCES:
        digest.update(source.read_bytes())
    digest.update(target_cpu().encode())
    digest.update(_numba_version_text())
    digest.update(np.__version__.encode())
    digest.update(sys.implementation.cache_tag.encode())
    digest.update(importlib.machinery.EXTENSION_SUFFIXES[0].encode())
    return digest.hexdigest()[:20]


def module_name() -> str:
    """The ahead-of-time module's name (it includes the key: each build is its own module)."""
    return f"tdmon_kernels_{build_key()}"


def cache_root() -> Path:
    """The folder that holds every ahead-of-time build (one file per key)."""
    import platformdirs

    return platformdirs.user_cache_path("tdmon", appauthor=False) / "kernels"


def aot_path() -> Path:
    """Where the ahead-of-time module of the current key is (or would be)."""
    return cache_root() / f"{module_name()}{importlib.machinery.EXTENSION_SUFFIXES[0]}"


def load_aot(path: Path | None = None) -> ModuleType:
    """Import the ahead-of-time module at ``path`` (default `aot_path`); OSError or
    ImportError when it is missing or cannot be loaded, AttributeError when it lacks an
    entry point."""
    path = aot_path() if path is None else path
    name = path.name.split(".")[0]
    if not path.is_file():
        raise FileNotFoundError(f"no ahead-of-time kernels at {path}")
    loaded = sys.modules.get(name)  # this build, loaded before (from this or another path)
    if loaded is not None:
        return loaded
    loader = importlib.machinery.ExtensionFileLoader(name, str(path))
    spec = importlib.util.spec_from_file_location(name, path, loader=loader)
    if spec is None:
        raise ImportError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    for entry in ENTRY_POINTS:
        getattr(module, entry)
    sys.modules[name] = module
    return module


def mode() -> str:
    """``TDMON_KERNELS`` as one of "auto", "jit", "aot" (a ModelError otherwise)."""
    mode = os.environ.get(ENVIRONMENT, "auto").strip().lower() or "auto"
    if mode not in _MODES:
        raise ModelError(f"environment variable {ENVIRONMENT}={mode!r}: use one of "
                         f"{', '.join(_MODES)}")
    return mode


def load() -> Kernels:
    """The kernels to run, as ``TDMON_KERNELS`` chooses (see the module's docstring)."""
    return _load(mode())


@lru_cache(maxsize=len(_MODES))
def _load(mode: str) -> Kernels:
    if mode != "jit":
        path = aot_path()
        try:
            return Kernels("aot", load_aot(path), str(path))
        except (OSError, ImportError, AttributeError) as error:
            if mode == "aot":
                raise ModelError(f"{ENVIRONMENT}=aot but the ahead-of-time kernels do not "
                                 f"load ({error}): run 'tdmon model warmup'") from error
            _log.info("model kernels: numba's JIT (%s; 'tdmon model warmup' builds them "
                      "ahead of time)", error)
    return Kernels("jit", importlib.import_module("tdmon.model._kernels"), "numba's JIT")


def forget() -> None:
    """Forget the loaded choice (after a build, or a change of ``TDMON_KERNELS``)."""
    _load.cache_clear()
