"""Make the small WITSML files of this folder from the Volve F-4 time log (run from the
repository: ``python tests/ingest/data/witsml/derive.py``). The rows are the log's own, from
2016-10-04 17:00:00 to 17:30:00 UTC (the start of the trip out, 121 rows of 15 s, all 31
curves); what changes is only how they are packaged:

- ``volve-f4-1.3.1.1.xml``: the WITSML 1.3.1.1 layout of the same log (namespace
  ``.../schemas/131``, ``version="1.3.1.1"``, each ``logCurveInfo`` with its 1-based
  ``columnIndex`` and the ``indexCurve`` with its ``columnIndex`` attribute, no
  ``mnemonicList``/``unitList``, the rows' times without a time zone);
- ``volve-f4-run0.xml``, ``volve-f4-run1.xml``: the log exported in pieces, one chunk per run
  with its own uid and ``runNumber``: run 0 (17:00:00-17:20:00) in one file, runs 1
  (17:15:00-17:25:00) and 2 (17:25:00-17:30:00) as two ``<log>`` elements of the other; the
  pieces overlap by 21 rows and 1 row.

Equinor's Volve data: see README.md in this folder for the licence.
"""

from __future__ import annotations

import re
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCE = HERE.parents[3] / "data" / "volve-f4" / "witsml" / "GwdTime-2016-10-03-to-05.xml"
FIRST, LAST = "2016-10-04T17:00:00", "2016-10-04T17:30:00"
NOTE = ("<!-- Derived from Equinor's Volve 15/9-F-4 WITSML time log: Equinor Open Data Licence "
        "(CC BY-NC-SA 4.0 terms); attribution: Equinor and the former Volve licence partners. "
        "Made by derive.py in this folder. -->")


def _parts() -> tuple[str, str, str, list[str]]:
    text = SOURCE.read_text(encoding="utf-8")
    log_start = text.index("<log ")
    header_end = text.index("<logData>")
    data_end = text.index("</logData>")
    head = text[log_start:header_end]
    tail = text[data_end + len("</logData>"):text.index("</logs>")]
    lists = text[header_end + len("<logData>"):text.index("<data>", header_end)]
    rows = re.findall(r"<data>([^<]*)</data>", text[header_end:data_end])
    rows = [row for row in rows if FIRST <= row[:19] <= LAST]
    return head, lists, tail, rows


def _log(head: str, lists: str, tail: str, rows: list[str], uid: str, run: str) -> str:
    head = head.replace('uid="36VIRG33"', f'uid="{uid}"')
    head = head.replace("<runNumber>0</runNumber>", f"<runNumber>{run}</runNumber>")
    data = "".join(f"<data>{row}</data>" for row in rows)
    return f"{head}<logData>{lists}{data}</logData>{tail}"  # tail ends with </log>


def _document(logs: list[str], namespace: str, version: str) -> str:
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n{NOTE}\n<logs xmlns="{namespace}" '
            f'xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" version="{version}">'
            + "".join(logs) + "</logs>\n")


def main() -> None:
    head, lists, tail, rows = _parts()
    assert len(rows) == 121, len(rows)
    series = "http://www.witsml.org/schemas/1series"
    cut0, cut1, cut2 = 80, 60, 100  # 17:20:00, 17:15:00, 17:25:00
    (HERE / "volve-f4-run0.xml").write_text(_document(
        [_log(head, lists, tail, rows[:cut0 + 1], "36VIRG33-r0", "0")], series, "1.4.1.1"))
    (HERE / "volve-f4-run1.xml").write_text(_document(
        [_log(head, lists, tail, rows[cut1:cut2 + 1], "36VIRG33-r1", "1"),
         _log(head, lists, tail, rows[cut2:], "36VIRG33-r2", "2")], series, "1.4.1.1"))

    # 1.3.1.1: the columns as columnIndex, no lists in logData, times without a zone
    mnemonics = re.search(r"<mnemonicList>([^<]*)</mnemonicList>", lists)
    assert mnemonics is not None
    columns = {name: index for index, name in enumerate(mnemonics.group(1).split(","), 1)}

    def with_column(match: re.Match[str]) -> str:
        info = match.group(0)
        mnemonic = re.search(r"<mnemonic>([^<]*)</mnemonic>", info)
        assert mnemonic is not None
        index = columns[mnemonic.group(1)]
        return info.replace("<curveDescription>",
                            f"<columnIndex>{index}</columnIndex><curveDescription>")

    old_head = re.sub(r"<logCurveInfo [^>]*>.*?</logCurveInfo>", with_column, head)
    # 1.3.1.1's indexCurve carries the index's column too
    old_head = old_head.replace("<indexCurve>Time</indexCurve>",
                                f'<indexCurve columnIndex="{columns["Time"]}">Time</indexCurve>')
    old_rows = [row.replace(".000Z", "", 1) for row in rows]
    (HERE / "volve-f4-1.3.1.1.xml").write_text(_document(
        [_log(old_head, "", tail, old_rows, "36VIRG33", "0")],
        "http://www.witsml.org/schemas/131", "1.3.1.1"))


if __name__ == "__main__":
    main()
