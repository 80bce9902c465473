"""Build the model's kernels ahead of time: one extension module that runs without numba.

numba's ``pycc`` compiles the very functions of `tdmon.model._kernels` (their Python source,
``py_func``) for the signatures below into a C extension module, which needs a C compiler at
build time and nothing of numba at run time. `tdmon model warmup` calls `build`; the model
loads the result through `tdmon.model.kernels`.

The signatures are the types the model's callers pass (`tests/model/test_warmup.py` checks
that the JIT compiles no other for the real calls). The module checks only each array's item
size, not its dtype, layout or number of dimensions: callers pass exactly these
(`tdmon.model.kernels.kernel_well` converts the well's arrays, `WellModel` its friction).
The target is the highest x86-64 level the processor has (`tdmon.model.kernels.target_cpu`,
part of the build's key; the generic processor elsewhere): the batched march of several
friction cases runs about 9 % slower on the generic x86-64 than with AVX-512, and the
processor's own model (pycc's "host") ran Aadnoy's march a third slower (docs/benchmarks.md).
Either way the numbers are the JIT's (numba allows no fused multiply-add contraction).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
import warnings
from pathlib import Path

from tdmon.model import kernels

_WELL = "f8[::1], i8[::1], i8"  # the packed well and the method
_TERMS = "f8[::1], f8[::1], f8[::1], f8[::1]"  # per operation: bit force, torque, two factors

#: numba signature of each entry point.
SIGNATURES: dict[str, str] = {
    "pack_well": "Tuple((f8[::1], i8[::1]))(f8[::1], f8[:, ::1], f8[::1], i8[::1], b1[::1], "
                 "f8[::1], f8[::1], f8[::1])",
    "all_finite_non_negative": "b1(f8[::1])",
    "march_one": f"UniTuple(f8, 2)({_WELL}, f8[::1], f8, f8, f8, f8, f8)",
    "march_cases": f"UniTuple(f8[:, ::1], 2)({_WELL}, f8[:, ::1], f8, {_TERMS})",
    "march_profile": f"i8({_WELL}, f8[::1], f8, {_TERMS}, f8[::1], f8[:, ::1], f8[:, ::1], "
                     f"i8[::1], f8[:, ::1])",
    "sweep": f"UniTuple(f8[:, :, ::1], 2)({_WELL}, f8[:, ::1], f8[::1], {_TERMS})",
    "march_gradient": f"Tuple((f8, f8, f8[::1]))({_WELL}, f8[::1], f8, f8, f8, f8, f8, f8, f8)",
}


def build(destination: Path | None = None) -> tuple[Path, float]:
    """Compile every entry point into the module `tdmon.model.kernels.aot_path` names.

    Parameters
    ----------
    destination : the file to write (default `tdmon.model.kernels.aot_path`); its name, up
        to the first dot, must be `tdmon.model.kernels.module_name` (the module's init
        function is named after it)

    Returns
    -------
    the module's path and the build's wall time [s]. Raises whatever the compiler or numba
    raise when the build fails (no C compiler, a kernel that pycc cannot compile).
    """
    start = time.perf_counter()
    target = kernels.aot_path() if destination is None else destination
    target.parent.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pycc is pending deprecation in numba: it still works
        from numba.pycc import CC

        from tdmon.model import _kernels

        # built in a scratch folder beside the target, then renamed into place: a concurrent
        # build or load never sees half a file
        with tempfile.TemporaryDirectory(dir=target.parent, prefix=".build-") as scratch:
            compiler = CC(kernels.module_name())
            compiler.output_dir = scratch
            compiler.verbose = False
            compiler.target_cpu = kernels.target_cpu()
            for name, signature in SIGNATURES.items():
                compiler.export(name, signature)(getattr(_kernels, name).py_func)
            compiler.compile()
            built = Path(scratch) / compiler.output_file
            os.replace(built, target)
    return target, time.perf_counter() - start


def is_current() -> bool:
    """Whether the ahead-of-time module of the current source and versions exists."""
    return kernels.aot_path().is_file()


def compiler_available() -> bool:
    """Whether a C compiler is on the path (pycc needs one)."""
    return any(shutil.which(name) for name in (os.environ.get("CC", "cc"), "gcc", "clang"))


def ensure_built() -> float | None:
    """`build` unless the current build exists; returns the build's time [s], or None."""
    if is_current():
        return None
    return build()[1]
