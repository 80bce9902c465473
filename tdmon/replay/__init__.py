"""Rig sessions for replay: the simulator, real-data import and the replay driver.

The package is also the function ``tdmon.replay(recording, out, ...)`` of the Python API
(docs/api.md): ``tdmon.replay`` names both, since a submodule import sets the package as the
attribute ``replay`` of ``tdmon`` whatever ``tdmon/__init__.py`` put there. Calling the package
calls :func:`tdmon.replay.run.replay_file`; its submodules stay importable as usual.
"""

from __future__ import annotations

import sys
import types
from typing import Any


class _CallablePackage(types.ModuleType):
    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        from tdmon.replay.run import replay_file

        return replay_file(*args, **kwargs)


sys.modules[__name__].__class__ = _CallablePackage
