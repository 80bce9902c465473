"""The column map of ``tdmon import csv`` as a pydantic model, and ``load_column_map_config``.

A column map (a small TOML file) says how a rig's CSV feeds the canonical channels: the time
column and its format (``[time]``), one ``[channels.<channel>]`` table per mapped column with
its unit, and optionally the topic ``prefix``, the ``delimiter`` and the ``missing`` cell texts
meaning "no value" (such as ``"-999.25"``). :func:`tdmon.replay.importers.load_column_map`
turns it into a CSV layout. See docs/replays.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Final

from pydantic import Field, field_validator

from tdmon.channels import check_channel
from tdmon.config.common import StrictModel, load_model, quantity

__all__ = ["ISO_FORMATS", "ChannelColumn", "ColumnMapConfig", "TimeColumn",
           "load_column_map_config"]


#: names of the ISO 8601 time format a column map accepts (read as ``"iso8601"``)
ISO_FORMATS: Final = ("iso8601", "iso")


class TimeColumn(StrictModel):
    """The time column: ``format`` is ``"iso8601"`` (or ``"iso"``), ``"unix"`` [s],
    ``"unix_ms"`` [ms] or a ``strptime`` format; ``utc_offset`` is what naive times are ahead
    of UTC [s]."""

    column: str = Field(min_length=1)
    format: str = "iso8601"
    utc_offset: Annotated[float, quantity("s")] = 0.0

    @field_validator("format")
    @classmethod
    def _iso(cls, value: str) -> str:
        return "iso8601" if value.strip().lower() in ISO_FORMATS else value


class ChannelColumn(StrictModel):
    """The column feeding one channel, and the unit its numbers are in."""

    column: str = Field(min_length=1)
    unit: str = Field(min_length=1)


class ColumnMapConfig(StrictModel):
    """A generic CSV's column map: ``[time]``, ``[channels.<channel>]``, optional ``prefix``,
    ``delimiter``, ``missing`` (cell texts meaning no value)."""

    prefix: str | None = None
    delimiter: str = Field(default=",", min_length=1, max_length=1)
    missing: list[str] = Field(default_factory=list)
    time: TimeColumn
    channels: dict[str, ChannelColumn] = Field(min_length=1)

    @field_validator("channels")
    @classmethod
    def _known(cls, channels: dict[str, ChannelColumn]) -> dict[str, ChannelColumn]:
        for name in channels:
            check_channel(name)
        return channels


def load_column_map_config(path: str | Path) -> ColumnMapConfig:
    """Read and validate a column map.

    Raises
    ------
    ConfigError
        The file is missing, not TOML, or invalid (unknown channel, missing key); the message
        names the key and the reason.
    """
    return load_model(ColumnMapConfig, path)
