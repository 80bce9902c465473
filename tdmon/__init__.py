"""tdmon: real-time torque-and-drag monitoring and friction back-calculation.

The Python API (docs/api.md) is loaded on first use, so that ``import tdmon`` stays cheap
(no pandas, numba or Dask until a function needs them)::

    import tdmon
    recording = tdmon.read_recording("out/trip-out.mcap")
    recording.estimates        # a pandas DataFrame, one row per estimate
"""

from __future__ import annotations

import importlib as _importlib
from typing import TYPE_CHECKING

__version__ = "0.1.0"

__all__ = ["Recording", "WellFile", "__version__", "batch", "evaluate_loads", "load_well",
           "read_recording", "replay"]

if TYPE_CHECKING:  # names listed in __all__ are re-exported
    from typing import Any

    from tdmon.api import (
        Recording,
        WellFile,
        batch,
        evaluate_loads,
        load_well,
        read_recording,
        replay,
    )

#: names of the API defined in tdmon.api (``replay`` is the callable package tdmon.replay)
_API = frozenset(__all__) - {"__version__", "replay"}


def __getattr__(name: str) -> Any:
    if name == "replay":
        # the package tdmon.replay is callable as tdmon.api.replay (see its docstring): a name
        # here would be replaced by the package as soon as one of its modules is imported
        return _importlib.import_module("tdmon.replay")
    if name in _API:
        value = getattr(_importlib.import_module("tdmon.api"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'tdmon' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The API (``__all__``) and the module's own dunder names: not the helpers this module
    imports, nor the subpackages some import loaded (``tdmon.model`` and the like stay
    importable by name)."""
    own = {name for name in globals() if name.startswith("__") and name.endswith("__")}
    return sorted({*own, *__all__})
