"""The daemon's well file, read once: its validated configuration, the model's well, its path.

The daemon's builder, its steps (model coverage, mu(T), the well and profile messages) and the
fleet all take one :class:`WellFile`; it sits here, beside the well file's schema
(:mod:`tdmon.config.well`), so that they all import it from below rather than from each other.
The model layer cannot hold it: it carries the pydantic ``WellConfig``.

Not the API's ``tdmon.WellFile`` (docs/api.md), which a script gets from ``tdmon.load_well``
with the friction per element: this one is the daemon's, with the string made to reach the
bottom of the hole, its tally and the file's digest for reloads.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tdmon.config.daemon import DaemonConfig
    from tdmon.config.well import WellConfig
    from tdmon.model.well import Well

__all__ = ["WellFile", "read_well_file", "read_well_path"]


@dataclass(frozen=True)
class WellFile:
    """The daemon's well file, read once: its configuration, the model's ``Well``, the path.

    ``well`` is the file's well with its top string component reaching the bottom of the hole
    (the model never runs out of string; :mod:`tdmon.daemon.steps.coverage` alarms when the bit
    goes deeper than the file's own tally, ``tally_length`` [m]); ``digest`` is the SHA-256 of
    the file's bytes (a reload of an unchanged file changes nothing).
    """

    config: WellConfig
    well: Well
    path: Path
    tally_length: float = 0.0
    digest: str = ""


def read_well_path(path: Path) -> WellFile:
    """Read one well file into a :class:`WellFile` (``ConfigError`` when it is not valid)."""
    # imported here: the schema brings the model layer's modules, which a caller that only
    # names WellFile (a type annotation) does not need
    from tdmon.config.well import load_well

    well_config = load_well(path)
    well = well_config.to_model(path)
    tally = float(well.string.length)
    covering = replace(well, string=well.string.reaching(well.hole_bottom))
    try:
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:  # read a moment ago; gone now: no digest, every reload applies it
        digest = ""
    return WellFile(well_config, covering, path, tally, digest)


def read_well_file(config: DaemonConfig) -> WellFile | None:
    """Read the daemon file's well file (None when it names none)."""
    if config.well is None:
        return None
    return read_well_path(config.resolve(config.well))
