"""Real rig data (CSV) into the input format: ``/tdmon/raw`` messages in an MCAP file.

Two layouts:

* the Volve CSV layout (:data:`VOLVE_LAYOUT`, the files of Equinor's Volve F-4 time logs:
  ``time_utc, bit_depth_m, hookload_kN, surface_torque_kNm, ...``), whose
  ``rig_activity_code`` is kept as a reference on ``/reference/rig_activity``;
* any CSV with a column map (:func:`load_column_map`, a small TOML file: column -> channel and
  unit, the time column and its format).

Each non-empty cell of a mapped column becomes one payload ``{"t", "value", "unit"}`` on
``<prefix>/<channel>``, converted to SI. Missing values (an empty cell, ``nan``, ``null``,
``na`` or a configured null value such as ``-999.25``) send nothing, as a rig would. A cell that
is not a number, or a time that cannot be read, is an error naming the file, the line and the
column: a half-imported file would silently shift every statistic computed from it.

The row parser (:func:`parse_rows`) is pure; :func:`import_csv` owns the files. A column map is
read and validated by :mod:`tdmon.config.column_map`; :func:`load_column_map` makes it a layout.
"""

from __future__ import annotations

import csv
import math
from collections import Counter
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any, Final

from tdmon.channels import CHANNEL_UNITS, check_channel
from tdmon.config.column_map import load_column_map_config
from tdmon.errors import ConfigError, IngestError
from tdmon.replay.simulate import RAW_TOPIC, MessageRecord, raw_input, write_mcap
from tdmon.units import conversion

__all__ = [
    "REFERENCE_SCHEMAS",
    "RIG_ACTIVITIES",
    "VOLVE_ATTRIBUTION",
    "VOLVE_LAYOUT",
    "VOLVE_LICENCE",
    "ColumnSpec",
    "CsvLayout",
    "ImportResult",
    "import_csv",
    "import_volve",
    "load_column_map",
    "parse_rows",
    "rig_activity",
]

VOLVE_LICENCE: Final = "Equinor Open Data Licence (CC BY-NC-SA 4.0 terms)"
VOLVE_ATTRIBUTION: Final = "Equinor and the former Volve licence partners"

#: The Volve rig contractor's activity codes (the last digit; +10 circulating, +100 rotating).
RIG_ACTIVITIES: Final[Mapping[int, str]] = {
    0: "none", 1: "drilling", 2: "reaming", 3: "off bottom", 4: "in slips", 6: "tripping in",
    7: "tripping out", 8: "trip in slips",
}

_MISSING: Final = frozenset({"", "nan", "null", "na", "n/a", "none"})

REFERENCE_SCHEMAS: Final[dict[str, dict[str, Any]]] = {
    "/reference/rig_activity": {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": "https://tdmon.invalid/schemas/reference.rig_activity.json",
        "title": "the rig contractor's activity code (a reference, not a ground truth)",
        "type": "object",
        "properties": {"t": {"type": "number"}, "code": {"type": "integer"},
                       "activity": {"type": "string"}, "circulating": {"type": "boolean"},
                       "rotating": {"type": "boolean"}},
        "required": ["t", "code", "activity", "circulating", "rotating"],
    },
    "/reference/source": {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": "https://tdmon.invalid/schemas/reference.source.json",
        "title": "where imported data came from, with its licence",
        "type": "object",
        "properties": {"t": {"type": "number"}, "file": {"type": "string"},
                       "layout": {"type": "string"}, "rows": {"type": "integer"},
                       "licence": {"type": ["string", "null"]},
                       "attribution": {"type": ["string", "null"]}},
        "required": ["t", "file", "layout", "rows"],
    },
}


@dataclass(frozen=True)
class ColumnSpec:
    """One CSV column feeding one canonical channel; ``value_SI = value * scale + offset``."""

    column: str
    channel: str
    unit: str
    scale: float
    offset: float

    @classmethod
    def of(cls, column: str, channel: str, unit: str) -> ColumnSpec:
        """A column in ``unit`` (raises ValueError for an unknown channel or unusable unit)."""
        check_channel(channel)
        scale, offset = conversion(unit, CHANNEL_UNITS[channel][0])
        return cls(column, channel, unit, scale, offset)


@dataclass(frozen=True)
class CsvLayout:
    """How to read one kind of CSV file.

    Attributes
    ----------
    name : label (``"volve"``, or the map file's name)
    time_column : column holding the sample time
    time_format : ``"iso8601"`` (or ``"iso"``), ``"unix"`` [s], ``"unix_ms"`` [ms] or a
        ``strptime`` format
    utc_offset : what naive times are ahead of UTC [s]
    channels : mapped columns
    rig_activity_column : column of Volve-style rig activity codes (None: none)
    missing : extra cell texts meaning "no value" (e.g. ``"-999.25"``)
    delimiter : field separator
    licence, attribution : carried into ``/reference/source``
    """

    name: str
    time_column: str
    channels: tuple[ColumnSpec, ...]
    time_format: str = "iso8601"
    utc_offset: float = 0.0
    rig_activity_column: str | None = None
    missing: frozenset[str] = field(default_factory=frozenset)
    delimiter: str = ","
    licence: str | None = None
    attribution: str | None = None

    @property
    def columns(self) -> list[str]:
        """Every column the layout needs."""
        needed = [self.time_column, *(spec.column for spec in self.channels)]
        if self.rig_activity_column:
            needed.append(self.rig_activity_column)
        return needed


VOLVE_LAYOUT: Final = CsvLayout(
    name="volve",
    time_column="time_utc",
    channels=(
        ColumnSpec.of("hookload_kN", "hookload", "kN"),
        ColumnSpec.of("surface_torque_kNm", "torque", "kN*m"),
        ColumnSpec.of("bit_depth_m", "bit_depth", "m"),
        ColumnSpec.of("hole_depth_m", "hole_depth", "m"),
        # heave-compensated block position: what moves the string
        ColumnSpec.of("block_pos_comp_m", "block_position", "m"),
        ColumnSpec.of("surface_rpm", "rpm", "rpm"),
        ColumnSpec.of("flow_in_Lpm", "flow_in", "L/min"),
        ColumnSpec.of("spp_bar", "spp", "bar"),
        ColumnSpec.of("wob_kN", "wob", "kN"),
    ),
    rig_activity_column="rig_activity_code",
    licence=VOLVE_LICENCE,
    attribution=VOLVE_ATTRIBUTION,
)
"""The Volve F-4 CSV files (see the data README): the channels tdmon reads. Left out on
purpose: ``bit_rpm`` (a copy of the surface RPM), ``flow_out_Lpm`` (paddle, unreliable),
``rop_mph``, ``block_pos_uncomp_m``, ``rig_heave_m``, ``bit_depth_5s_m`` and the contractor's
trip counters."""


def rig_activity(code: int) -> dict[str, Any]:
    """Decode a Volve rig activity code (e.g. 116: tripping in, circulating, rotating flag)."""
    base = code % 10
    return {"code": code, "activity": RIG_ACTIVITIES.get(base, f"code {base}"),
            "circulating": (code // 10) % 10 == 1, "rotating": code >= 100}


def _parse_time(text: str, layout: CsvLayout) -> float:
    """Unix seconds of a time cell (ValueError with the reason)."""
    fmt = layout.time_format
    if fmt == "unix":
        seconds = float(text)
    elif fmt == "unix_ms":
        seconds = float(text) / 1000.0
    else:
        stamp = (datetime.fromisoformat(text) if fmt in ("iso8601", "iso")
                 else datetime.strptime(text, fmt))
        if stamp.tzinfo is None:
            stamp = stamp.replace(tzinfo=UTC) - timedelta(seconds=layout.utc_offset)
        seconds = stamp.timestamp()
    if not math.isfinite(seconds):
        raise ValueError("not a finite time")
    return seconds


def check_columns(header: Iterable[str], layout: CsvLayout, source: str) -> None:
    """Raise IngestError naming every column the layout needs and the file lacks."""
    present = set(header)
    missing = [column for column in layout.columns if column not in present]
    if missing:
        raise IngestError(f"{source}: no column {', '.join(repr(c) for c in missing)} "
                          f"(columns: {', '.join(sorted(present))})")


def parse_rows(rows: Iterable[tuple[int, Mapping[str, str]]], layout: CsvLayout, prefix: str,
               source: str = "<csv>") -> Iterator[MessageRecord]:
    """Input messages from CSV rows, in row order (one per non-missing mapped cell).

    Parameters
    ----------
    rows : (line number in the file, {column: cell text})
    layout : how to read the columns
    prefix : topic prefix, e.g. ``"rig/F4"``
    source : file name used in error messages

    Yields
    ------
    (log time [ns], topic, message): ``/tdmon/raw`` messages, and ``/reference/rig_activity``
    when the layout has an activity column. The log and receive time are the row's time.

    Raises
    ------
    IngestError
        A non-numeric cell or an unreadable time, naming the line and the column.
    """
    prefix = prefix.strip("/")
    missing = _MISSING | {text.lower() for text in layout.missing}
    topics = {spec.column: f"{prefix}/{spec.channel}" for spec in layout.channels}
    for line, row in rows:
        time_text = (row.get(layout.time_column) or "").strip()
        if time_text.lower() in missing:
            raise IngestError(f"{source}: line {line}, column '{layout.time_column}': "
                              "no time (a row's values cannot be placed without one)")
        try:
            t = _parse_time(time_text, layout)
        except (ValueError, OverflowError) as exc:
            raise IngestError(f"{source}: line {line}, column '{layout.time_column}': cannot "
                              f"read time '{time_text}' as {layout.time_format} ({exc})") from None
        log_ns = round(t * 1e9)
        for spec in layout.channels:
            text = (row.get(spec.column) or "").strip()
            if text.lower() in missing:
                continue
            value = _number(text, line, spec.column, source)
            yield log_ns, RAW_TOPIC, raw_input(topics[spec.column], t,
                                               value * spec.scale + spec.offset,
                                               CHANNEL_UNITS[spec.channel][0], t)
        if layout.rig_activity_column:
            text = (row.get(layout.rig_activity_column) or "").strip()
            if text.lower() not in missing:
                code = _number(text, line, layout.rig_activity_column, source)
                if code != int(code):
                    raise IngestError(f"{source}: line {line}, column "
                                      f"'{layout.rig_activity_column}': '{text}' is not an "
                                      "activity code (an integer)")
                yield log_ns, "/reference/rig_activity", {"t": t, **rig_activity(int(code))}


def _number(text: str, line: int, column: str, source: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise IngestError(f"{source}: line {line}, column '{column}': '{text}' is not a "
                          "number") from None
    if not math.isfinite(value):
        raise IngestError(f"{source}: line {line}, column '{column}': '{text}' is not a "
                          "finite number")
    return value


@dataclass(frozen=True)
class ImportResult:
    """What an import wrote: rows read, messages per channel (and references), time span."""

    path: Path
    rows: int
    messages: int
    per_channel: dict[str, int]
    first_t: float | None
    last_t: float | None


def import_csv(path: str | Path, layout: CsvLayout, out: str | Path, *, prefix: str,
               progress: bool = False) -> ImportResult:
    """Read a CSV file with ``layout`` and write its input messages to the MCAP file ``out``.

    Raises
    ------
    IngestError
        The file cannot be read, lacks a column, or holds a bad cell.
    RecordError
        The output cannot be written.
    """
    source = Path(path)
    try:
        handle = source.open(newline="", encoding="utf-8-sig")
    except OSError as exc:
        raise IngestError(f"cannot read {source}: {exc.strerror or exc}") from exc
    with handle:
        try:
            lines = sum(1 for _ in handle) - 1
            handle.seek(0)
            reader = csv.DictReader(handle, delimiter=layout.delimiter)
            header = reader.fieldnames
            if not header:
                raise IngestError(f"{source}: empty file (no header line)")
            check_columns(header, layout, str(source))
            rows = ((reader.line_num, row) for row in reader)
            counts: Counter[str] = Counter()
            span: list[float] = []

            def counted() -> Iterator[MessageRecord]:
                for record in parse_rows(_progress(rows, lines, progress, source.name), layout,
                                         prefix, str(source)):
                    topic = record[1]
                    key = (record[2]["topic"].rsplit("/", 1)[-1] if topic == RAW_TOPIC
                           else topic)
                    counts[key] += 1
                    t = record[0] / 1e9
                    if not span:
                        span.extend((t, t))
                        yield record[0], "/reference/source", {
                            "t": t, "file": source.name, "layout": layout.name, "rows": lines,
                            "licence": layout.licence, "attribution": layout.attribution}
                    span[0], span[1] = min(span[0], t), max(span[1], t)
                    yield record

            written = write_mcap(out, counted(), REFERENCE_SCHEMAS)
        except UnicodeDecodeError as exc:
            raise IngestError(f"{source}: not UTF-8 text ({exc.reason})") from exc
        except csv.Error as exc:
            raise IngestError(f"{source}: line {reader.line_num}: {exc}") from exc
    return ImportResult(path=Path(out), rows=lines, messages=written, per_channel=dict(counts),
                        first_t=span[0] if span else None, last_t=span[1] if span else None)


def _progress(rows: Iterator[tuple[int, Mapping[str, str]]], total: int, enabled: bool,
              name: str) -> Iterator[tuple[int, Mapping[str, str]]]:
    if not enabled:
        return rows
    from tqdm import tqdm

    return iter(tqdm(rows, total=total, desc=f"import {name}", unit="row", leave=False,
                     disable=None))


def import_volve(path: str | Path, out: str | Path, *, prefix: str = "rig/F4",
                 progress: bool = False) -> ImportResult:
    """Import a Volve F-4 CSV time log (:data:`VOLVE_LAYOUT`) into ``out``."""
    return import_csv(path, VOLVE_LAYOUT, out, prefix=prefix, progress=progress)


# -- the column map ----------------------------------------------------------------------------

def load_column_map(path: str | Path) -> tuple[CsvLayout, str | None]:
    """Read a column map; returns the layout and the map's prefix (None if not given).

    Raises
    ------
    ConfigError
        Naming the file, the key and the reason (unknown channel, unit not convertible to the
        channel's SI unit, missing keys).
    """
    config = load_column_map_config(path)
    specs = []
    for channel, item in config.channels.items():
        try:
            specs.append(ColumnSpec.of(item.column, channel, item.unit))
        except ValueError as exc:
            raise ConfigError(str(path), f"channels.{channel}.unit", str(exc)) from exc
    layout = CsvLayout(name=Path(path).stem, time_column=config.time.column,
                       time_format=config.time.format, utc_offset=config.time.utc_offset,
                       channels=tuple(specs), missing=frozenset(config.missing),
                       delimiter=config.delimiter)
    return layout, config.prefix
