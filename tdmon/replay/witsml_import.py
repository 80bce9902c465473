"""WITSML 1.4.1.1 and 1.3.1.1 time logs into the input format: ``/tdmon/raw`` messages in an
MCAP file.

The output is the same as the CSV importers' (:mod:`tdmon.replay.importers`): one payload
``{"t", "value", "unit"}`` per non-null mapped cell on ``<prefix>/<channel>``, in SI, the rig
activity code (when the log has one) on ``/reference/rig_activity``, and where the data came
from on ``/reference/source`` (the log's well, name, uid and service company, with the licence
and attribution: given, or Equinor's when the well is a Volve one, ``15/9-F-*``).

Several files (or several ``<log>`` chunks of one log: the same well, wellbore and log name,
whatever their uids, as runs exported apart have) are joined in time order: the files are
merged on their row times, each file being read in order; a row whose time was already written
(an overlap between chunks) is a duplicate and is dropped (on equal times the file given first
wins); a row earlier than one already written is dropped and counted as out of order. Memory
stays flat: rows stream from the parser (:func:`tdmon.ingest.witsml.iter_log`) to the recorder.
The result lists every curve of the log and what became of it
(:func:`tdmon.ingest.witsml.curve_fates`). See docs/witsml.md.
"""

from __future__ import annotations

import heapq
import math
import os
import re
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Final

from tdmon.channels import CHANNEL_UNITS
from tdmon.errors import IngestError
from tdmon.ingest.witsml import (
    CURVE_TABLE,
    CurveChoice,
    CurveFate,
    DataRow,
    LogBlock,
    ResolvedCurve,
    block_samples,
    curve_fates,
    iter_log,
    resolve_curves,
    rig_activity_column,
)
from tdmon.replay.importers import REFERENCE_SCHEMAS, VOLVE_ATTRIBUTION, VOLVE_LICENCE, rig_activity
from tdmon.replay.simulate import RAW_TOPIC, MessageRecord, raw_input, write_mcap

__all__ = ["WITSML_SCHEMAS", "WitsmlImportResult", "import_witsml", "is_volve_well"]

_VOLVE_WELL: Final = re.compile(r"15/9-F-\d+")

#: ``/reference/source`` of a WITSML import: the CSV importers' fields and the log's metadata.
WITSML_SCHEMAS: Final[dict[str, dict[str, Any]]] = {
    "/reference/rig_activity": REFERENCE_SCHEMAS["/reference/rig_activity"],
    "/reference/source": {
        **REFERENCE_SCHEMAS["/reference/source"],
        "properties": {
            **REFERENCE_SCHEMAS["/reference/source"]["properties"],
            "files": {"type": "array", "items": {"type": "string"}},
            "well": {"type": "string"}, "wellbore": {"type": "string"},
            "log_name": {"type": "string"}, "log_uid": {"type": "string"},
            "log_uids": {"type": "array", "items": {"type": "string"}},
            "runs": {"type": "array", "items": {"type": "string"}},
            "service_company": {"type": "string"},
            "curves": {"type": "object", "additionalProperties": {"type": "string"}},
            "note": {"type": ["string", "null"]},
        },
    },
}


def is_volve_well(name: str) -> bool:
    """Whether a WITSML well name is one of the Volve field's (``NO 15/9-F-4``...)."""
    return bool(_VOLVE_WELL.search(name))


@dataclass(frozen=True)
class WitsmlImportResult:
    """What an import wrote.

    ``rows`` counts rows written, ``duplicates`` rows dropped because their time was already
    written, ``out_of_order`` rows dropped because they came after a later one; ``curves`` is
    channel -> ``"MNEMONIC [uom]"`` of the first block; ``curve_report`` every curve of the log
    (over all its chunks, in the order first seen) with what became of it; ``log_uids`` the
    uids of the chunks joined, ``version`` the WITSML version of the first.
    """

    path: Path
    rows: int
    messages: int
    per_channel: dict[str, int]
    first_t: float | None
    last_t: float | None
    duplicates: int = 0
    out_of_order: int = 0
    curves: dict[str, str] = field(default_factory=dict)
    curve_report: tuple[CurveFate, ...] = ()
    log_uids: tuple[str, ...] = ()
    version: str = "1.4.1.1"


class _Progress:
    """A binary file wrapper that reports bytes read to a tqdm bar."""

    def __init__(self, handle: IO[bytes], bar: Any) -> None:
        self._handle = handle
        self._bar = bar

    def read(self, size: int = -1) -> bytes:
        data = self._handle.read(size)
        self._bar.update(len(data))
        return data


@dataclass
class _Log:
    """What the chunks of the one log being imported share: its identity (the first block's,
    and where it came from) and the fate of each curve seen so far."""

    first: tuple[LogBlock, str] | None = None
    fates: dict[str, CurveFate] = field(default_factory=dict)

    def add(self, block: LogBlock, source: str, curves: tuple[ResolvedCurve, ...]) -> None:
        """Take a chunk, or refuse one of another log."""
        if self.first is None:
            self.first = (block, source)
        else:
            first, where = self.first
            if block.identity != first.identity:
                raise IngestError(
                    f"{source}: log {_describe(block)} is not {_describe(first)} of {where}: "
                    "chunks of one log share well, wellbore and log name; import one log at "
                    "a time")
        for fate in curve_fates(block, curves):
            known = self.fates.get(fate.mnemonic.lower())
            if known is None or (known.channel is None and fate.channel is not None):
                self.fates[fate.mnemonic.lower()] = fate


def _describe(block: LogBlock) -> str:
    return (f"'{block.name or block.uid}' (uid {block.uid}, well '{block.well}', wellbore "
            f"'{block.wellbore}')")


@dataclass
class _Stream:
    """One file's rows, mapped to samples with its current block's curves."""

    source: str
    events: Iterator[LogBlock | DataRow]
    overrides: Mapping[str, tuple[str, str | None]]
    table: Mapping[str, CurveChoice]
    log: _Log
    blocks: list[LogBlock] = field(default_factory=list)
    curves: tuple[ResolvedCurve, ...] = ()
    activity: int | None = None

    def rows(self, order: int) -> Iterator[tuple[float, int, list[tuple[str, float]], int | None]]:
        for item in self.events:
            if isinstance(item, LogBlock):
                self.curves = resolve_curves(item, self.source, overrides=self.overrides,
                                             table=self.table)
                self.log.add(item, self.source, self.curves)
                self.activity = rig_activity_column(item)
                self.blocks.append(item)
                continue
            samples = list(block_samples(item, self.curves, self.source))
            yield item.t, order, samples, self._activity(item)

    def _activity(self, row: DataRow) -> int | None:
        if self.activity is None:
            return None
        text = row.cells[self.activity].strip()
        try:
            code = float(text)
        except ValueError:
            return None
        if not math.isfinite(code) or code != int(code) or code < 0:
            return None
        return int(code)


def import_witsml(paths: Sequence[str | Path], out: str | Path, *, prefix: str,  # noqa: C901  (complex today; simplify when next touched)
                  overrides: Mapping[str, tuple[str, str | None]] | None = None,
                  table: Mapping[str, CurveChoice] = CURVE_TABLE,
                  licence: str | None = None, attribution: str | None = None,
                  note: str | None = None, progress: bool = False) -> WitsmlImportResult:
    """Read WITSML time logs (one log, in one or more files) and write ``out``.

    Parameters
    ----------
    paths : the log files (any order: their rows are merged by time)
    out : the MCAP file to write (replaced if present; never left half written)
    prefix : topic prefix, e.g. ``"rig/F4"``
    overrides : channel -> (mnemonic, unit or None), before the table
    table : the curve table (default :data:`tdmon.ingest.witsml.CURVE_TABLE`)
    licence, attribution : for ``/reference/source`` (default: Equinor's for a Volve well)
    note : free text carried on ``/reference/source``
    progress : a progress bar (bytes read) on stderr when it is a terminal

    Raises
    ------
    IngestError
        A file cannot be read, is not a WITSML time log, lacks the needed curves, holds
        a bad cell, or the files hold different logs (uids).
    RecordError
        The output cannot be written.
    """
    if not paths:
        raise IngestError("no WITSML log file given")
    log = _Log()
    prefix = prefix.strip("/")
    topics = {channel: f"{prefix}/{channel}" for channel in CHANNEL_UNITS}
    counts: Counter[str] = Counter()
    tally = {"rows": 0, "duplicates": 0, "out_of_order": 0}
    span: list[float] = []
    streams: list[_Stream] = []
    with ExitStack() as stack:
        bar = None
        if progress:
            from tqdm import tqdm

            total = sum(_size(Path(path)) for path in paths)
            bar = stack.enter_context(tqdm(total=total, desc="import witsml", unit="B",
                                           unit_scale=True, leave=False, disable=None))
        for path in paths:
            source = Path(path)
            try:
                handle: IO[bytes] = stack.enter_context(source.open("rb"))
            except OSError as exc:
                raise IngestError(f"cannot read {source}: {exc.strerror or exc}") from exc
            reader: Any = _Progress(handle, bar) if bar is not None else handle
            streams.append(_Stream(str(source), iter_log(reader, str(source)),
                                   overrides or {}, table, log))
        merged = heapq.merge(*(stream.rows(order) for order, stream in enumerate(streams)),
                             key=lambda item: (item[0], item[1]))

        def records() -> Iterator[MessageRecord]:
            last: float | None = None
            for t, _order, samples, activity in merged:
                if last is not None and t <= last:
                    tally["duplicates" if t == last else "out_of_order"] += 1
                    continue
                if last is None:
                    span.extend((t, t))
                    yield round(t * 1e9), "/reference/source", _source_message(
                        t, streams, licence, attribution, note)
                last = t
                span[1] = t
                tally["rows"] += 1
                log_ns = round(t * 1e9)
                for channel, value in samples:
                    counts[channel] += 1
                    yield log_ns, RAW_TOPIC, raw_input(topics[channel], t, value,
                                                       CHANNEL_UNITS[channel][0], t)
                if activity is not None:
                    counts["/reference/rig_activity"] += 1
                    yield log_ns, "/reference/rig_activity", {"t": t, **rig_activity(activity)}
            if last is None:
                raise IngestError(f"{', '.join(map(str, paths))}: no data rows (empty logData)")

        written = write_mcap(out, records(), WITSML_SCHEMAS)
    first = next(stream for stream in streams if stream.blocks)
    curves = {curve.channel: f"{curve.mnemonic} [{curve.unit}]" for curve in first.curves}
    return WitsmlImportResult(path=Path(out), rows=tally["rows"], messages=written,
                              per_channel=dict(counts), first_t=span[0] if span else None,
                              last_t=span[1] if span else None, duplicates=tally["duplicates"],
                              out_of_order=tally["out_of_order"], curves=curves,
                              curve_report=tuple(log.fates.values()),
                              log_uids=_uids(streams), version=first.blocks[0].version)


def _uids(streams: list[_Stream]) -> tuple[str, ...]:
    """The chunks' uids, each once, in the order the files were given and read."""
    return tuple(dict.fromkeys(block.uid for stream in streams for block in stream.blocks))


_DATA_END: Final = re.compile(rb"</(?:[\w.-]+:)?data>")
#: a ``<log ...>`` start tag's uid (not ``<logs>``, ``<logData>``, ``<logCurveInfo>``), and a
#: ``runNumber``: the chunks a file holds, listed in ``/reference/source`` before its rows are
#: parsed
_LOG_HEADER: Final = re.compile(rb"<(?:[\w.-]+:)?log(?=[\s>])[^>]*?\suid=[\"']([^\"']*)[\"']"
                                rb"|<(?:[\w.-]+:)?runNumber>\s*([^<]*?)\s*</")
#: bytes kept from one read to the next so that a tag cut by the read is found whole
_TAIL: Final = 4096


@dataclass(frozen=True)
class LogFileScan:
    """What :func:`scan_log_file` counts in a file: ``<data>`` rows, the ``<log>`` uids and the
    ``runNumber`` values (each once, in file order)."""

    rows: int
    uids: tuple[str, ...]
    runs: tuple[str, ...]


def scan_log_file(path: Path) -> LogFileScan:
    """Rows, log uids and run numbers of a file, read on the bytes 1 MB at a time (flat
    memory), for ``/reference/source``, which is written before the rows are parsed."""
    count = 0
    uids: dict[str, None] = {}
    runs: dict[str, None] = {}
    tail = b""
    scanned = 0  # bytes of `tail` already searched for log headers
    try:
        with path.open("rb") as handle:
            while chunk := handle.read(1 << 20):
                block = tail + chunk
                matches = list(_DATA_END.finditer(block))
                count += len(matches)
                last = matches[-1].end() if matches else 0
                header_end = 0
                for match in _LOG_HEADER.finditer(block):
                    if match.end() <= scanned:
                        continue  # found in the previous read already
                    uid, run = match.group(1), match.group(2)
                    if uid is not None:
                        uids.setdefault(uid.decode("utf-8", "replace"), None)
                    elif run:
                        runs.setdefault(run.decode("utf-8", "replace"), None)
                    header_end = match.end()
                keep = max(len(block) - _TAIL, last, header_end)
                tail = block[keep:]
                scanned = len(tail)  # a match inside it was found in this read
    except OSError as exc:
        raise IngestError(f"cannot read {path}: {exc.strerror or exc}") from exc
    return LogFileScan(count, tuple(uids), tuple(runs))


def count_rows(path: Path) -> int:
    """``<data>`` rows in a file, counted on the bytes (:func:`scan_log_file`)."""
    return scan_log_file(path).rows


def _size(path: Path) -> int:
    try:
        return os.stat(path).st_size
    except OSError:
        return 0


def _source_message(t: float, streams: list[_Stream], licence: str | None,
                    attribution: str | None, note: str | None) -> dict[str, Any]:
    block = next(stream.blocks[-1] for stream in streams if stream.blocks)
    volve = is_volve_well(block.well) or is_volve_well(block.wellbore)
    if volve:
        licence = licence or VOLVE_LICENCE
        attribution = attribution or VOLVE_ATTRIBUTION
    curves = next(stream.curves for stream in streams if stream.blocks)
    first = next(stream.blocks[0] for stream in streams if stream.blocks)
    scans = [scan_log_file(Path(stream.source)) for stream in streams]
    return {"t": t, "file": Path(streams[0].source).name,
            "files": [Path(stream.source).name for stream in streams],
            "layout": f"witsml-{first.version}",
            "rows": sum(scan.rows for scan in scans), "licence": licence,
            "attribution": attribution, "well": block.well, "wellbore": block.wellbore,
            "log_name": block.name, "log_uid": first.uid,
            "log_uids": list(dict.fromkeys(uid for scan in scans for uid in scan.uids)),
            "runs": list(dict.fromkeys(run for scan in scans for run in scan.runs)),
            "service_company": block.service_company,
            "curves": {curve.channel: f"{curve.mnemonic} [{curve.unit}]" for curve in curves},
            "note": note}
