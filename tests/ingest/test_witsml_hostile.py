"""WITSML logs written to hurt the importer (issue 32, fault 9): a time outside what a recording
can hold (an OverflowError traceback before), a bad cell of 100 000 characters (echoed whole to
stderr), and 10 MB of elements the reader does not know inside a ``<log>`` (kept in memory
until the log ended: 100 MB peaked at 1.2 GB)."""

from __future__ import annotations

import io
import itertools
import tracemalloc
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import pytest

from tdmon.cli import main
from tdmon.errors import IngestError
from tdmon.ingest.witsml import DataRow, LogBlock, iter_log

ROOT = Path(__file__).resolve().parents[2]
LOG = ROOT / "tests" / "ingest" / "data" / "witsml" / "volve-f4-run0.xml"
SECOND_ROW = "<data>2016-10-04T17:00:15.000Z,0.00061204178,6009.3769,"


def _with(tmp_path: Path, old: str, new: str) -> Path:
    text = LOG.read_text()
    assert old in text
    path = tmp_path / "log.xml"
    path.write_text(text.replace(old, new, 1))
    return path


def _import(path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """``tdmon import witsml`` as the command line runs it: (exit code, stderr)."""
    code = main(["import", "witsml", str(path), "--out", str(tmp_path / "out.mcap")])
    return code, capsys.readouterr().err


@pytest.mark.parametrize("year", ["3000", "0001", "1969"])
def test_a_time_outside_1970_2554_is_one_line_exit_2(tmp_path: Path, year: str,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    path = _with(tmp_path, SECOND_ROW, SECOND_ROW.replace("2016", year))
    code, stderr = _import(path, tmp_path, capsys)
    assert code == 2, stderr
    assert stderr == (f"tdmon: error: {path}: data row 2: time '{year}-10-04T17:00:15.000Z'"
                             " is outside 1970-2554, the times a recording can hold\n")
    assert not (tmp_path / "out.mcap").exists()


def test_a_bad_cell_is_cut_when_echoed(tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    cell = "x" * 100_000
    path = _with(tmp_path, SECOND_ROW, SECOND_ROW.replace("6009.3769", cell))
    code, stderr = _import(path, tmp_path, capsys)
    assert code == 2, stderr
    assert stderr == (f"tdmon: error: {path}: row at 2016-10-04T17:00:15Z, curve 'WOB': "
                             f"'{'x' * 40}... (100000 characters)' is not a number\n")


class _Stream(io.RawIOBase):
    """A file made on the fly, so that the test holds no copy of it: the log with ``middle``
    put before its first logCurveInfo, inside the ``<log>``."""

    def __init__(self, middle: Iterable[bytes] = ()) -> None:
        text = LOG.read_bytes()
        split = text.index(b"<logCurveInfo")
        self._parts: Iterator[bytes] = itertools.chain([text[:split]], middle, [text[split:]])
        self._left = b""

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: bytearray | memoryview) -> int:  # type: ignore[override]
        while not self._left:
            self._left = next(self._parts, b"")
            if not self._left:
                return 0
        size = min(len(buffer), len(self._left))
        buffer[:size] = self._left[:size]
        self._left = self._left[size:]
        return size


def _peak_reading(stream: io.RawIOBase) -> tuple[int, int]:
    """(rows read, peak of Python's allocations while reading) [bytes]."""
    tracemalloc.start()
    try:
        rows = sum(isinstance(item, DataRow) for item in iter_log(
            io.BufferedReader(stream, 64 * 1024), "log.xml"))
        return rows, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("middle", [
    # 10 MB in 30 000 elements
    lambda: itertools.repeat(b"<junk><a>" + b"y" * 1000 + b"</a><b/></junk>", 10_000),
    # 10 MB of text in one element
    lambda: itertools.chain([b"<junk>"], itertools.repeat(b"z" * 50_000, 200), [b"</junk>"]),
], ids=["elements", "text"])
def test_unknown_elements_cost_no_memory(middle: Callable[[], Iterable[bytes]]) -> None:
    rows_plain, _ = _peak_reading(_Stream())
    rows, peak = _peak_reading(_Stream(middle()))
    assert rows == rows_plain > 0
    # ElementTree's own builder kept all 10 MB (and more in element objects) until the log
    # ended; the reader's target drops them as they are parsed: what is left is the parser's
    # 64 KiB buffer and the log's rows
    assert peak < 2_000_000, peak


def test_a_kept_element_over_the_bound_is_refused() -> None:
    row = b"<data>" + b"1," * 600_000 + b"1</data>"
    text = LOG.read_bytes()
    at = text.index(b"<data>")
    with pytest.raises(IngestError, match=r"<data> holds more than 1048576 characters"):
        for _item in iter_log(io.BytesIO(text[:at] + row + text[at:]), "log.xml"):
            pass


def test_the_log_reads_as_before() -> None:
    items = list(iter_log(LOG.open("rb"), "log.xml"))
    blocks = [item for item in items if isinstance(item, LogBlock)]
    assert len(blocks) == 1
    assert blocks[0].name == "GwdTime" and blocks[0].service_company == "Baker Hughes"
    assert len(blocks[0].curves) == len(blocks[0].mnemonics) == 31
    assert items[1] == DataRow(1475600400.0, items[1].cells)  # type: ignore[union-attr]
