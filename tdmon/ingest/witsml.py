"""WITSML 1.4.1.1 and 1.3.1.1 time logs, read as a stream: bytes in, typed rows and SI samples
out.

A ``<logs>`` document holds one or more ``<log>`` elements (chunks of one log: the same well,
wellbore and log name; their ``uid`` may differ from run to run). Each has a header
(``indexType``, ``indexCurve``, ``nullValue``, one ``logCurveInfo`` per curve: ``mnemonic``,
``classWitsml``, ``unit``, per-curve ``nullValue``) and a ``logData`` block of ``<data>`` rows,
comma separated cells, one row per index. Where each curve's cells are differs by version:
1.4.1.1 lists the columns in ``logData``'s ``mnemonicList`` (and ``unitList``); 1.3.1.1 has no
such lists and gives each ``logCurveInfo`` a ``columnIndex`` (1-based; 0: no values in the
rows), which the reader turns into the same column list (docs/witsml.md, "WITSML 1.3.1.1").

The reader (:func:`iter_log`) walks the document with ``xml.etree.ElementTree.iterparse`` and
clears every ``<data>`` row once read, so memory stays flat whatever the file's size. It yields a
:class:`LogBlock` (the header and column list of one ``<log>``) before that block's
:class:`DataRow` items. :func:`resolve_curves` picks, for each canonical channel, the curve
to read through :data:`CURVE_TABLE` (by ``classWitsml`` or mnemonic, first match wins) or an
override, and :func:`block_samples` turns rows into SI values. No file or network I/O here: the
caller opens the files (:mod:`tdmon.replay.witsml_import`). See docs/witsml.md.
"""

from __future__ import annotations

import contextlib
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import IO, Final

from tdmon.channels import CHANNEL_UNITS
from tdmon.errors import IngestError
from tdmon.units import conversion

__all__ = [
    "CURVE_HINTS",
    "CURVE_TABLE",
    "OBJECT_KINDS",
    "RIG_ACTIVITY_MNEMONICS",
    "WITSML_UNITS",
    "CurveChoice",
    "CurveFate",
    "DataRow",
    "LogBlock",
    "LogCurve",
    "ResolvedCurve",
    "block_samples",
    "curve_fates",
    "cut",
    "detect_object",
    "iter_log",
    "local_name",
    "parse_time",
    "pint_unit",
    "resolve_curves",
]

#: Root element of each WITSML object file (1.3.1.1 and 1.4.1.1 alike) -> the object kind it
#: holds.
OBJECT_KINDS: Final[Mapping[str, str]] = {
    "logs": "log", "trajectorys": "trajectory", "tubulars": "tubular",
    "wbGeometrys": "wbGeometry", "rigs": "rig", "fluidsReports": "fluidsReport",
}


@dataclass(frozen=True)
class CurveChoice:
    """How one channel's curve is recognised: ``classWitsml`` values and mnemonics, in order
    of preference (compared case-insensitively, spaces and underscores ignored)."""

    classes: tuple[str, ...]
    mnemonics: tuple[str, ...]


#: The default curve table: channel -> what finds its curve. The ``classWitsml`` values are
#: those of WITSML's log trace classes as Volve writes them (``tqAv``, ``rpmAv``...). The
#: mnemonics, in order of preference (docs/witsml.md has the table with the source of each):
#: Baker Hughes' (the Volve F-4 log in data/volve-f4/witsml; the ``_AVG`` curves and
#: ``BLOCKCOMP`` of Baker Hughes exports of other Volve wells), the WITS record 1 mnemonics that
#: rig contractors and mud loggers send (``HKLA``, ``TQA``, ``WOBA``...; docs/wits0.md),
#: Schlumberger's surface parameters (``HKLD``, ``SWOB``, ``SPPA``, ``BD``, ``TD`` in its LWD/MWD
#: lists), then common LAS-style names. Maximum or instantaneous curves (``HKLX``, ``tqMx``)
#: are left out on purpose: the model compares averages.
CURVE_TABLE: Final[Mapping[str, CurveChoice]] = {
    "hookload": CurveChoice(("hkldAv", "hook load", "hookload"),
                            ("HKLD", "HKLD_AVG", "HKLA", "HKL", "HOOKLOAD", "HKLDAV",
                             "HOOK_LOAD", "HL")),
    "torque": CurveChoice(("tqAv", "surface torque", "torque"),
                          ("TORQUE", "TORQUE_AVG", "TQA", "STOR", "TQ", "TORQ", "SURF_TORQUE",
                           "TQAV", "TQ_AVG")),
    "bit_depth": CurveChoice(("depthBit", "bit depth"),
                             ("BITDEP", "DBTM", "BDEP", "BDTI", "BIT_DEPTH", "DBIT", "BD")),
    "hole_depth": CurveChoice(("depthHole", "hole depth"),
                              ("MDEPTH", "DMEA", "HDTH", "HOLE_DEPTH", "DEPTH", "TD")),
    "block_position": CurveChoice(("blockPos", "block position"),
                                  ("BLOCKCOMP", "BPOS", "BLKPOS", "BLOCK_POS", "BLKH", "HKHT",
                                   "BLOCK_HEIGHT")),
    "rpm": CurveChoice(("rpmAv", "rotary speed"),
                       ("SURF_RPM", "SURF_RPM_AVG", "RPMA", "RPM", "TRPM", "RPMAV")),
    "flow_in": CurveChoice(("flowInAv", "flow in"),
                           ("FLOWIN", "FLOWIN_AVG", "MFIA", "TFLO", "FLOW_IN")),
    "spp": CurveChoice(("presPumpAv", "standpipe pressure"),
                       ("PUMP", "PUMP_AVG", "SPPA", "SPP", "STP")),
    "wob": CurveChoice(("wobAv", "weight on bit"), ("WOB", "WOB_AVG", "WOBA", "SWOB")),
    "downhole_wob": CurveChoice(("downhole weight on bit",),
                                ("MWBA", "DWOB", "DHWOB", "WOB_DH")),
    "downhole_torque": CurveChoice(("downhole torque",),
                                   ("MTQA", "DTOR", "DHTQ", "TQ_DH")),
    "mud_density": CurveChoice(("wtMudInAv", "mud density in"), ("MWIN", "MDIA", "MW_IN")),
    "mud_temp_in": CurveChoice(("tempMudInAv", "mud temperature in"),
                               ("MTIA", "TEMPIN", "MT_IN", "MTIN")),
    "mud_temp_out": CurveChoice(("tempMudOutAv", "mud temperature out"),
                                ("MTOA", "TEMPOUT", "MT_OUT", "MTOUT")),
}

#: What a curve the table does not take may be, for the import summary's suggestion: channel
#: -> words of its mnemonic or description (compared as in the table: case, spaces and
#: underscores ignored), and words that rule the channel out (the other end of the mud loop,
#: a downhole value).
CURVE_HINTS: Final[Mapping[str, tuple[tuple[str, ...], tuple[str, ...]]]] = {
    "hookload": (("hkl", "hook", "hookload"), ("height", "speed", "block")),
    "torque": (("torq", "tq"), ("bit", "dh", "motor", "makeup", "mu")),
    "wob": (("wob", "weightonbit"), ("dh", "downhole")),
    "downhole_wob": (("dwob", "dhwob", "wobdh", "downholewob", "downholeweightonbit"), ()),
    "downhole_torque": (("dtor", "dhtq", "tqdh", "downholetorque", "torqueonbit"), ()),
    "rpm": (("rpm", "rotaryspeed", "rotspeed"), ("bit", "motor", "turb", "dh", "collar")),
    "bit_depth": (("bitdep", "bitdepth", "bdep", "dbtm"), ()),
    "hole_depth": (("holedep", "holedepth", "totaldepth", "dmea", "mdepth"), ("tvd",)),
    "block_position": (("block", "blk", "bpos", "hookheight"), ("speed", "velocity")),
    "spp": (("spp", "standpipe", "pumppress", "pumppressure"), ()),
    "flow_in": (("flowin", "mfi", "flowrate", "flow"), ("out", "mfo")),
    "mud_density": (("mwin", "mdin", "densityin", "mudweightin", "mudweight", "mw"),
                    ("out", "ecd")),
    "mud_temp_in": (("tempin", "mtin", "mti", "temperaturein"), ("out",)),
    "mud_temp_out": (("tempout", "mtout", "mto", "temperatureout"), ()),
}

#: Words of a curve's mnemonic or description that make it an extreme, not an average
_EXTREMES: Final = ("max", "min", "peak", "mx")

#: Curves carrying the Volve contractor's rig activity code (kept as a reference).
RIG_ACTIVITY_MNEMONICS: Final = frozenset({"rigactivitycode"})

#: WITSML ``uom`` spellings that pint reads differently or not at all -> pint spellings.
#: Rotation rates: WITSML's ``c/s`` (cycles per second), ``rpm`` and ``1/min`` are revolutions,
#: which pint must be told (its ``c`` is the speed of light, and ``1/min`` would be radians).
WITSML_UNITS: Final[Mapping[str, str]] = {
    "c/s": "rps", "rpm": "rpm", "1/min": "rpm",
    "rev/min": "rpm", "1/s": "rps",
    "N.m": "N*m", "kN.m": "kN*m", "daN.m": "daN*m", "ft.lbf": "ft*lbf",
    "kft.lbf": "kft*lbf", "lbf.ft": "lbf*ft", "klbf.ft": "klbf*ft",
    "kkgf": "kkgf", "tonf": "tf", "kdaN": "kN*10",
    "m3/s": "m**3/s", "m3/min": "m**3/min", "m3/h": "m**3/h", "L/min": "L/min",
    "gpm": "gpm", "galUS/min": "gpm", "bbl/min": "bbl/min",
    "ft3/min": "ft**3/min",
    "kg/m3": "kg/m**3", "g/cm3": "g/cm**3", "kg/L": "kg/L", "lbm/galUS": "lb/gallon",
    "ppg": "ppg", "sg": "sg", "SG": "sg", "lbm/ft3": "lb/ft**3",
    "degC": "degC", "degF": "degF", "K": "K", "dega": "degree", "lbm/ft": "lb/ft",
}

_NOT_UNITS: Final = frozenset({"", "unitless", "euc", "none", "n/a"})
_EXPONENT = re.compile(r"([A-Za-z])(\d)")


def pint_unit(uom: str) -> str | None:
    """The pint spelling of a WITSML ``uom`` (None when it names no unit, e.g. ``unitless``).

    The table :data:`WITSML_UNITS` first; otherwise WITSML's grammar rewritten for pint:
    ``.`` multiplies and a trailing digit is a power (``kN.m`` -> ``kN*m``, ``m3`` -> ``m**3``).
    """
    uom = uom.strip()
    if uom.lower() in _NOT_UNITS:
        return None
    if uom in WITSML_UNITS:
        return WITSML_UNITS[uom]
    return _EXPONENT.sub(r"\1**\2", uom.replace(".", "*"))


def local_name(tag: str) -> str:
    """An element's name without its namespace (``{http://...}log`` -> ``log``)."""
    return tag.rpartition("}")[2]


def _normal(text: str) -> str:
    return text.replace(" ", "").replace("_", "").lower()


#: [Unix s] The first time after the last an MCAP recording can hold: its log times are
#: unsigned 64-bit nanoseconds since 1970, which end in July 2554.
LATEST_TIME: Final = 2.0**64 / 1e9


def parse_time(text: str) -> float:
    """Unix seconds of a WITSML ``dateTime`` (ISO 8601; without an offset it is taken as UTC).

    Raises
    ------
    ValueError
        Not an ISO 8601 time, or one outside 1970-01-01 to :data:`LATEST_TIME` (2554-07-21).
    """
    try:
        stamp = datetime.fromisoformat(text.strip())
    except ValueError:
        raise ValueError(f"cannot read time '{cut(text.strip())}' (ISO 8601 expected)") from None
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=UTC)
    t = stamp.timestamp()
    if not 0.0 <= t < LATEST_TIME:
        raise ValueError(f"time '{cut(text.strip())}' is outside 1970-2554, the times a "
                         "recording can hold")
    return t


#: [characters] Most of a file's text an error message quotes
QUOTED_TEXT: Final = 40


def cut(text: str, limit: int = QUOTED_TEXT) -> str:
    """``text`` as an error message quotes it: at most ``limit`` characters, a longer one cut
    with the whole length stated."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text)} characters)"


# -- the streaming reader ----------------------------------------------------------------------

@dataclass(frozen=True)
class LogCurve:
    """One ``logCurveInfo``: ``unit`` is the WITSML ``uom`` text, ``null_value`` the curve's own
    (None: the log's), ``column_index`` its 1-based column in 1.3.1.1's data rows (None: not
    given, as in 1.4.1.1)."""

    mnemonic: str
    class_witsml: str | None
    unit: str
    null_value: str | None
    description: str
    column_index: int | None = None


@dataclass(frozen=True)
class LogBlock:
    """The header of one ``<log>`` element and the columns of its ``logData``.

    Attributes
    ----------
    uid, name : the log's ``uid`` attribute and ``name``
    well, wellbore : ``nameWell``, ``nameWellbore``
    service_company : ``serviceCompany``
    index_type : ``indexType`` (``date time`` for a time log)
    index_curve : ``indexCurve`` mnemonic
    null_value : the log's ``nullValue`` (None: none)
    curves : every ``logCurveInfo``
    mnemonics, units : ``mnemonicList`` and ``unitList`` of the data block (1.3.1.1: made from
        the curves' ``columnIndex`` and ``unit``)
    version : the document's WITSML version (``1.4.1.1``, ``1.3.1.1``)
    run : ``runNumber`` ("" when not given)
    """

    uid: str
    name: str
    well: str
    wellbore: str
    service_company: str
    index_type: str
    index_curve: str
    null_value: str | None
    curves: tuple[LogCurve, ...]
    mnemonics: tuple[str, ...]
    units: tuple[str, ...]
    version: str = "1.4.1.1"
    run: str = ""

    @property
    def identity(self) -> tuple[str, str, str]:
        """What makes chunks one log: the well, the wellbore and the log's name (its uid when
        it has none), compared without case or surrounding spaces. Runs of one log exported
        apart carry the same name and different uids."""
        return (self.well.strip().casefold(), self.wellbore.strip().casefold(),
                (self.name or self.uid).strip().casefold())

    @property
    def index_column(self) -> int:
        """Column of the index (time) in each data row."""
        wanted = self.index_curve.lower()
        for column, mnemonic in enumerate(self.mnemonics):
            if mnemonic.lower() == wanted:
                return column
        return 0


@dataclass(frozen=True, slots=True)
class DataRow:
    """One ``<data>`` row: index time [Unix s] and its cells as text (in ``mnemonics`` order)."""

    t: float
    cells: list[str]


_HEADER_FIELDS: Final = {
    "name": "name", "nameWell": "well", "nameWellbore": "wellbore",
    "serviceCompany": "service_company", "indexType": "index_type",
    "indexCurve": "index_curve", "nullValue": "null_value", "runNumber": "run",
}

#: The namespace of each WITSML version's documents (the root's ``version`` attribute wins)
_NAMESPACE_VERSIONS: Final = {"http://www.witsml.org/schemas/131": "1.3.1.1",
                              "http://www.witsml.org/schemas/1series": "1.4.1.1"}


def _version(root: ET.Element) -> str:
    """The WITSML version of a document from its root: the ``version`` attribute, else the
    namespace; 1.4.1.1 when neither says."""
    stated = (root.get("version") or "").strip()
    if stated:
        return stated
    namespace = root.tag[1:].partition("}")[0] if root.tag.startswith("{") else ""
    return _NAMESPACE_VERSIONS.get(namespace, "1.4.1.1")


def _child_text(element: ET.Element, name: str) -> str | None:
    for child in element:
        if local_name(child.tag) == name:
            return (child.text or "").strip()
    return None


def _curve(element: ET.Element) -> LogCurve:
    texts = {local_name(child.tag): (child.text or "").strip() for child in element}
    column = texts.get("columnIndex", "")
    return LogCurve(mnemonic=texts.get("mnemonic", ""),
                    class_witsml=texts.get("classWitsml") or None,
                    unit=texts.get("unit", texts.get("uom", "")),
                    null_value=texts.get("nullValue") or None,
                    description=texts.get("curveDescription", ""),
                    column_index=int(column) if column.isdigit() else None)


def detect_object(stream: IO[bytes], source: str) -> str:
    """The WITSML object kind of a file from its root element (``log``, ``trajectory``,
    ``tubular``, ``wbGeometry``, ``rig``, ``fluidsReport``); reads only the first tag.

    Raises
    ------
    IngestError
        Not XML, or XML whose root is not one of :data:`OBJECT_KINDS`.
    """
    try:
        for _event, element in ET.iterparse(stream, events=("start",)):
            root = local_name(element.tag)
            if root not in OBJECT_KINDS:
                raise IngestError(f"{source}: not a WITSML object file (root element "
                                  f"<{root}>, expected one of "
                                  f"{', '.join(f'<{name}>' for name in OBJECT_KINDS)})")
            return OBJECT_KINDS[root]
    except ET.ParseError as exc:
        raise IngestError(f"{source}: not well-formed XML ({exc})") from None
    raise IngestError(f"{source}: empty file")


#: [characters] Most text kept of one element the reader uses (a ``<data>`` row, a header
#: field, a ``logCurveInfo``): a row of 10 000 curves of 100 characters fits; a longer one is
#: a broken or hostile file, refused rather than held in memory.
MAX_ELEMENT_TEXT: Final = 1024 * 1024

#: [bytes] How much of the file the parser is given at a time
_CHUNK: Final = 64 * 1024

#: Children of ``<log>`` (depth 3) and of ``<logData>`` (depth 4) the reader keeps whole
_KEPT_IN_LOG: Final = frozenset({"logCurveInfo", *_HEADER_FIELDS})
_KEPT_IN_DATA: Final = frozenset({"data", "mnemonicList", "unitList"})


class _LogTarget:
    """An ``ET.XMLParser`` target building only what :func:`iter_log` reads: the root,
    ``<log>`` and ``<logData>`` as bare elements (their start and end), and the header fields,
    ``logCurveInfo`` and the data blocks' children whole. Every other element, and its text,
    is dropped as the parser reports it, so an unknown element of any size costs no memory
    (ElementTree's own builder keeps every element of an open ``<log>``)."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.events: list[tuple[str, int, str, ET.Element]] = []
        self._path: list[str] = []
        self._builder: ET.TreeBuilder | None = None
        self._kept_depth = 0
        self._kept_text = 0

    def _kept(self, name: str) -> bool:
        path, depth = self._path, len(self._path)
        if depth == 3:
            return path[1] == "log" and name in _KEPT_IN_LOG
        return depth == 4 and path[1] == "log" and path[2] == "logData" and name in _KEPT_IN_DATA

    def start(self, tag: str, attrib: dict[str, str]) -> None:
        name = local_name(tag)
        self._path.append(name)
        depth = len(self._path)
        if self._builder is not None:
            self._builder.start(tag, attrib)
        elif depth == 1 or (depth == 2 and name == "log") or (
                depth == 3 and name == "logData" and self._path[1] == "log"):
            self.events.append(("start", depth, name, ET.Element(tag, attrib)))
        elif self._kept(name):
            self._builder, self._kept_depth, self._kept_text = ET.TreeBuilder(), depth, 0
            self._builder.start(tag, attrib)

    def data(self, text: str) -> None:
        if self._builder is None:
            return
        self._kept_text += len(text)
        if self._kept_text > MAX_ELEMENT_TEXT:
            raise IngestError(f"{self.source}: <{self._path[self._kept_depth - 1]}> holds more "
                              f"than {MAX_ELEMENT_TEXT} characters (at depth {self._kept_depth})")
        self._builder.data(text)

    def end(self, tag: str) -> None:
        name = self._path.pop()
        depth = len(self._path) + 1
        if self._builder is not None:
            self._builder.end(tag)
            if depth == self._kept_depth:
                self.events.append(("end", depth, name, self._builder.close()))
                self._builder = None
        elif depth == 1 or (depth == 2 and name == "log") or (
                depth == 3 and name == "logData" and self._path[1] == "log"):
            self.events.append(("end", depth, name, ET.Element(tag)))

    def close(self) -> None:
        return None


def _parse(stream: IO[bytes], source: str) -> Iterator[tuple[str, int, str, ET.Element]]:
    """The events of :class:`_LogTarget`, (event, depth, local name, element), as the file
    is read in chunks."""
    target = _LogTarget(source)
    parser = ET.XMLParser(target=target)
    try:
        while chunk := stream.read(_CHUNK):
            parser.feed(chunk)
            yield from target.events
            target.events.clear()
        parser.close()
    except ET.ParseError as exc:
        raise IngestError(f"{source}: not well-formed XML ({exc})") from None
    yield from target.events


def iter_log(stream: IO[bytes], source: str) -> Iterator[LogBlock | DataRow]:  # noqa: C901  (complex today; simplify when next touched)
    """Stream a WITSML ``<logs>`` document: a :class:`LogBlock` before the rows of each
    ``<log>``'s data, then its :class:`DataRow` items in file order.

    Memory stays flat: the parser's target (:class:`_LogTarget`) builds only the elements
    read here, one at a time, and drops every other element and its text as it is parsed.

    Raises
    ------
    IngestError
        Not XML or malformed XML (with the line and column), a root other than ``<logs>``, a
        depth-indexed log, data without ``mnemonicList``, a row whose time cannot be read or
        lies outside 1970-2554, or an element the reader keeps longer than
        :data:`MAX_ELEMENT_TEXT`; every message names ``source``.
    """
    root_seen = False
    in_log = in_data = False
    header: dict[str, str] = {}
    curves: list[LogCurve] = []
    lists: dict[str, tuple[str, ...]] = {}
    block: LogBlock | None = None
    version = "1.4.1.1"
    rows = 0
    for event, depth, name, element in _parse(stream, source):
        if event == "start":
            if depth == 1:
                root_seen = True
                if name != "logs":
                    raise IngestError(f"{source}: not a WITSML log file (root element "
                                      f"<{name}>, expected <logs>)")
                version = _version(element)
            elif depth == 2:
                in_log, curves, lists, block = True, [], {}, None
                header = {"uid": element.get("uid", "")}
            else:
                # a log may hold several logData blocks, each with its own columns
                in_data, lists, block = True, {}, None
            continue
        if depth == 4 and in_data and name == "data":
            if block is None:
                block = _block(header, curves, lists, source, version)
                yield block
            rows += 1
            yield _row(element.text or "", block, source, rows)
        elif depth == 4 and in_data:
            lists[name] = tuple(cell.strip() for cell in (element.text or "").split(","))
        elif depth == 3 and in_log:
            if name == "logCurveInfo":
                curves.append(_curve(element))
            elif name in _HEADER_FIELDS:
                header[_HEADER_FIELDS[name]] = (element.text or "").strip()
            elif name == "logData":
                in_data = False
        elif depth == 2:
            in_log = False
    if not root_seen:
        raise IngestError(f"{source}: empty file")


def _block(header: Mapping[str, str], curves: list[LogCurve], lists: Mapping[str, tuple[str, ...]],
           source: str, version: str = "1.4.1.1") -> LogBlock:
    uid = header.get("uid", "")
    label = f"log '{uid or header.get('name', '?')}'"
    index_type = header.get("index_type", "date time")
    if index_type.lower() not in ("date time", "datetime"):
        raise IngestError(f"{source}: {label} is indexed by '{cut(index_type)}'; only time "
                          "logs (indexType 'date time') can be imported")
    if "mnemonicList" in lists:
        mnemonics = lists["mnemonicList"]
        units = lists.get("unitList", ())
    else:
        mnemonics, units = _columns_from_indexes(curves, source, label)
    if units and len(units) != len(mnemonics):
        raise IngestError(f"{source}: {label}: unitList has {len(units)} entries, mnemonicList "
                          f"{len(mnemonics)}")
    return LogBlock(uid=uid, name=header.get("name", ""), well=header.get("well", ""),
                    wellbore=header.get("wellbore", ""),
                    service_company=header.get("service_company", ""),
                    index_type=index_type, index_curve=header.get("index_curve", mnemonics[0]),
                    null_value=header.get("null_value") or None, curves=tuple(curves),
                    mnemonics=mnemonics, units=units, version=version,
                    run=header.get("run", ""))


def _columns_from_indexes(curves: list[LogCurve], source: str, label: str
                          ) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The column list of a data block without ``mnemonicList``: WITSML 1.3.1.1 gives each
    curve's place in the rows as its ``columnIndex`` (1-based; 0 is a curve with no values in
    the rows). Columns no curve claims stay unnamed ("")."""
    unplaced = [curve.mnemonic for curve in curves if curve.column_index is None]
    placed = [curve for curve in curves if curve.column_index]
    if unplaced or not placed:
        missing = f" (none in {', '.join(unplaced)})" if unplaced and placed else ""
        raise IngestError(f"{source}: {label} has data rows but neither <mnemonicList> (WITSML "
                          "1.4.1.1 logData) nor a columnIndex in every logCurveInfo (1.3.1.1)"
                          f"{missing}")
    width = max(curve.column_index or 0 for curve in placed)
    mnemonics = [""] * width
    units = [""] * width
    for curve in placed:
        column = (curve.column_index or 0) - 1
        if mnemonics[column]:
            raise IngestError(f"{source}: {label}: curves '{mnemonics[column]}' and "
                              f"'{curve.mnemonic}' both have columnIndex {column + 1}")
        mnemonics[column], units[column] = curve.mnemonic, curve.unit
    return tuple(mnemonics), tuple(units)


def _row(text: str, block: LogBlock, source: str, number: int) -> DataRow:
    cells = text.split(",")
    if len(cells) != len(block.mnemonics):
        raise IngestError(f"{source}: data row {number} has {len(cells)} cells, mnemonicList "
                          f"{len(block.mnemonics)}")
    stamp = cells[block.index_column]
    try:
        t = parse_time(stamp)
    except ValueError as exc:
        raise IngestError(f"{source}: data row {number}: {exc}") from None
    return DataRow(t, cells)


# -- curves to channels ------------------------------------------------------------------------

@dataclass(frozen=True)
class ResolvedCurve:
    """One column of a block feeding one channel: ``value_SI = value * scale + offset``;
    cells equal to one of ``nulls`` (text or number) send nothing."""

    channel: str
    mnemonic: str
    column: int
    unit: str
    scale: float
    offset: float
    null_texts: frozenset[str]
    null_numbers: frozenset[float]
    #: how the curve was found: "classWitsml <class>", "mnemonic" or "--curve"
    found_by: str = "mnemonic"


def _nulls(*values: str | None) -> tuple[frozenset[str], frozenset[float]]:
    texts = {value.strip() for value in values if value and value.strip()}
    numbers = set()
    for text in texts:
        with contextlib.suppress(ValueError):
            numbers.add(float(text))
    return frozenset(texts), frozenset(numbers)


def _find(block: LogBlock, choice: CurveChoice) -> tuple[LogCurve, str] | None:
    """The curve ``choice`` finds in ``block``, and how (by class or by mnemonic)."""
    listed = {mnemonic.lower() for mnemonic in block.mnemonics}
    curves = [curve for curve in block.curves if curve.mnemonic.lower() in listed]
    for wanted in choice.classes:
        for curve in curves:
            if curve.class_witsml and _normal(curve.class_witsml) == _normal(wanted):
                return curve, f"classWitsml {curve.class_witsml}"
    for wanted in choice.mnemonics:
        for curve in curves:
            if _normal(curve.mnemonic) == _normal(wanted):
                return curve, "mnemonic"
    return None


def resolve_curves(block: LogBlock, source: str, *,
                   overrides: Mapping[str, tuple[str, str | None]] | None = None,
                   table: Mapping[str, CurveChoice] = CURVE_TABLE,
                   required: tuple[str, ...] = ("hookload", "bit_depth"),
                   ) -> tuple[ResolvedCurve, ...]:
    """The curves of ``block`` feeding each channel.

    Parameters
    ----------
    block : the log's header and columns
    source : file name for messages
    overrides : channel -> (mnemonic, unit or None): the curve to use instead of the table's
        (an override's unit replaces the curve's ``uom``)
    table : channel -> how its curve is recognised
    required : channels the import cannot do without

    Raises
    ------
    IngestError
        A required channel has no curve (the message lists the log's curves), an override
        names a curve the log lacks, or a curve's unit is missing, unknown or of the wrong kind.
    """
    overrides = overrides or {}
    by_mnemonic = {curve.mnemonic.lower(): curve for curve in block.curves}
    columns = {mnemonic.lower(): index for index, mnemonic in enumerate(block.mnemonics)}
    resolved = []
    for channel in CHANNEL_UNITS:
        unit_override: str | None = None
        if channel in overrides:
            mnemonic, unit_override = overrides[channel]
            if mnemonic.lower() not in columns:
                known = cut(", ".join(block.mnemonics), 400)
                raise IngestError(f"{source}: --curve {channel}={mnemonic}: the log has no "
                                  f"curve '{mnemonic}' (curves: {known})")
            curve = by_mnemonic.get(mnemonic.lower()) or LogCurve(mnemonic, None, "", None, "")
            found_by = "--curve"
        elif channel in table:
            found = _find(block, table[channel])
            if found is None:
                continue
            curve, found_by = found
        else:
            continue
        column = columns[curve.mnemonic.lower()]
        uom = unit_override or curve.unit or (block.units[column] if block.units else "")
        # an override is a WITSML uom like any other ("1/min" is rev/min, "c/s" rev/s)
        unit = pint_unit(uom)
        if unit is None:
            raise IngestError(f"{source}: curve '{curve.mnemonic}' ({channel}) has no unit "
                              f"('{cut(uom)}'); give one with --curve {channel}="
                              f"{curve.mnemonic}:UNIT")
        try:
            scale, offset = conversion(unit, CHANNEL_UNITS[channel][0])
        except ValueError as exc:
            raise IngestError(f"{source}: curve '{cut(curve.mnemonic)}' ({channel}), "
                              f"uom '{cut(uom)}': "
                              f"{exc}; give the unit with --curve {channel}="
                              f"{curve.mnemonic}:UNIT") from None
        texts, numbers = _nulls(curve.null_value or block.null_value)
        resolved.append(ResolvedCurve(channel, curve.mnemonic, column, uom, scale, offset,
                                      texts, numbers, found_by))
    missing = [channel for channel in required
               if channel not in {item.channel for item in resolved}]
    if missing:
        raise IngestError(
            f"{source}: log '{block.uid or block.name}' has no curve for "
            f"{', '.join(missing)} (looked for {_looked_for(missing, table)}; curves: "
            f"{', '.join(block.mnemonics)}); name one with --curve CHANNEL=MNEMONIC")
    return tuple(resolved)


def _looked_for(channels: list[str], table: Mapping[str, CurveChoice]) -> str:
    parts = []
    for channel in channels:
        choice = table.get(channel)
        if choice is not None:
            parts.append(f"{channel}: classWitsml {'/'.join(choice.classes)} or mnemonic "
                         f"{'/'.join(choice.mnemonics)}")
    return "; ".join(parts) or "nothing"


@dataclass(frozen=True)
class CurveFate:
    """What an import made of one curve of a log: ``channel`` it feeds (None: none) and a
    note for the user (how it was found, or why not and what would take it)."""

    mnemonic: str
    unit: str
    channel: str | None
    note: str


def curve_fates(block: LogBlock, curves: tuple[ResolvedCurve, ...]) -> tuple[CurveFate, ...]:
    """Every curve of ``block`` (its columns, then curves without values in the rows) and
    what became of it with ``curves`` (:func:`resolve_curves`): taken as a channel, the
    index, the rig activity code, or not mapped, with the ``--curve`` that would take it
    when it looks like a channel's (:data:`CURVE_HINTS`)."""
    info = {curve.mnemonic.lower(): curve for curve in block.curves}
    taken = {item.mnemonic.lower(): item for item in curves}
    by_channel = {item.channel: item.mnemonic for item in curves}
    activity = rig_activity_column(block)
    names = [m for m in block.mnemonics if m]
    names += [c.mnemonic for c in block.curves if c.mnemonic.lower() not in
              {m.lower() for m in names}]
    fates = []
    for column, mnemonic in enumerate(names):
        curve = info.get(mnemonic.lower()) or LogCurve(mnemonic, None, "", None, "")
        unit = curve.unit or (block.units[column] if column < len(block.units) else "")
        item = taken.get(mnemonic.lower())
        if item is not None:
            fates.append(CurveFate(mnemonic, unit, item.channel,
                                   f"taken as {item.channel} ({item.found_by})"))
        elif column == block.index_column and column < len(block.mnemonics):
            fates.append(CurveFate(mnemonic, unit, None, "the index (time)"))
        elif column == activity:
            fates.append(CurveFate(mnemonic, unit, None, "rig activity code "
                                                         "(/reference/rig_activity)"))
        elif mnemonic not in block.mnemonics:
            fates.append(CurveFate(mnemonic, unit, None, "no values in the data rows"))
        else:
            fates.append(CurveFate(mnemonic, unit, None, _not_mapped(curve, by_channel)))
    return tuple(fates)


def _not_mapped(curve: LogCurve, by_channel: Mapping[str, str]) -> str:
    """Why a curve was not taken, with the ``--curve`` that would take it when its mnemonic or
    description reads like a channel's."""
    text = f"{_normal(curve.mnemonic)} {_normal(curve.description)} " \
           f"{_normal(curve.class_witsml or '')}"
    for channel, (words, vetoes) in CURVE_HINTS.items():
        if not any(word in text for word in words) or any(veto in text for veto in vetoes):
            continue
        if any(word in text for word in _EXTREMES):
            return (f"not mapped: an extreme of {channel}? (the model compares averages; "
                    f"--curve {channel}={curve.mnemonic} takes it)")
        other = by_channel.get(channel)
        if other is None:
            return f"not mapped: looks like {channel}; add --curve {channel}={curve.mnemonic}"
        return (f"not mapped: looks like {channel}, taken from {other}; --curve "
                f"{channel}={curve.mnemonic} would take this one instead")
    return "not mapped (no channel of tdmon)"


def rig_activity_column(block: LogBlock) -> int | None:
    """Column of the Volve rig activity code, if the log has one."""
    for column, mnemonic in enumerate(block.mnemonics):
        if mnemonic.lower() in RIG_ACTIVITY_MNEMONICS:
            return column
    return None


def block_samples(row: DataRow, curves: tuple[ResolvedCurve, ...], source: str
                  ) -> Iterator[tuple[str, float]]:
    """(channel, SI value) of each mapped cell of ``row`` that is not empty or null.

    Raises
    ------
    IngestError
        A cell that is not a finite number, naming the time and the curve.
    """
    for curve in curves:
        text = row.cells[curve.column].strip()
        if not text or text in curve.null_texts:
            continue
        try:
            value = float(text)
        except ValueError:
            raise IngestError(f"{source}: row at {_iso(row.t)}, curve '{cut(curve.mnemonic)}': "
                              f"'{cut(text)}' is not a number") from None
        if value in curve.null_numbers or math.isnan(value):
            continue
        if math.isinf(value):
            raise IngestError(f"{source}: row at {_iso(row.t)}, curve '{cut(curve.mnemonic)}': "
                              f"'{cut(text)}' is not a finite number")
        yield curve.channel, value * curve.scale + curve.offset


def _iso(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).isoformat().replace("+00:00", "Z")


def child_text(element: ET.Element, name: str) -> str | None:
    """Text of the first child named ``name`` (namespace ignored), stripped; None if absent."""
    return _child_text(element, name)
