"""WITS Level 0 (WITS0): the pure codec, no sockets (docs/wits0.md).

A WITS0 feed is ASCII text: each frame opens with a line ``&&``, carries one line per item
(a four-digit code, record number then item number, followed at once by the value, e.g.
``01141436.5`` for item 14 of record 01 = 1436.5) and closes with a line ``!!``. Lines end in
CR LF; LF alone is tolerated. WITS0 has no checksum.

This module:

* names the items of record 01 that tdmon reads (:data:`DEFAULT_ITEMS`) and the WITS unit
  names (:data:`WITS_UNITS`);
* builds the item map of one feed, which item feeds which canonical channel in which unit
  (:func:`item_map`);
* splits a byte stream into frames whatever the reads look like (:class:`FrameParser`);
* turns a frame into SI values on channels, a time and the reasons for what it rejected
  (:func:`decode_frame`);
* and writes frames, for the simulator and the tests (:func:`encode_frame`, :func:`si_to_items`,
  :func:`time_items`, :func:`encode_sample_frame`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from datetime import datetime, tzinfo
from types import MappingProxyType
from typing import Final, Literal
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from tdmon.channels import CHANNEL_UNITS, check_channel
from tdmon.units import T_MAX, T_MIN, clip, conversion

__all__ = [
    "DATE_CODE", "DEFAULT_ITEMS", "MAX_FRAME_BYTES", "TIME_CODE", "WITS_UNITS", "DecodedFrame",
    "FrameError", "FrameParser", "ItemOverride", "ItemSpec", "ItemValue", "LineError",
    "UnitSystem", "WitsFrame", "WitsItem", "WitsLine", "decode_frame", "encode_frame",
    "encode_sample_frame", "item_map", "parse_line", "resolve_timezone", "si_to_items",
    "time_items",
]

UnitSystem = Literal["metric", "field"]


@dataclass(frozen=True, slots=True)
class WitsItem:
    """One item of the WITS record layout as tdmon knows it.

    ``channel`` is the canonical channel it feeds by default (None: read, but not a channel by
    default); ``metric`` and ``field`` are the WITS unit names the specification gives for
    the item in its metric and its field (FPS) unit set.
    """

    code: str
    mnemonic: str
    name: str
    channel: str | None
    metric: str
    field: str


#: The date item: YYMMDD
DATE_CODE: Final = "0105"
#: The time item: HHMMSS
TIME_CODE: Final = "0106"

DEFAULT_ITEMS: Final[Mapping[str, WitsItem]] = MappingProxyType({item.code: item for item in (
    WitsItem("0105", "DATE", "Date (YYMMDD)", None, "", ""),
    WitsItem("0106", "TIME", "Time (HHMMSS)", None, "", ""),
    WitsItem("0108", "DBTM", "Depth Bit (meas)", "bit_depth", "M", "F"),
    WitsItem("0110", "DMEA", "Depth Hole (meas)", "hole_depth", "M", "F"),
    WitsItem("0112", "BPOS", "Block Position", "block_position", "M", "F"),
    WitsItem("0114", "HKLA", "Hookload (avg)", "hookload", "KDN", "KLB"),
    # the maximum over the sampling interval: not what the torque-and-drag model compares
    # with; map it with `channel = "hookload"` (and 0114 off) if a rig sends only this one
    WitsItem("0115", "HKLX", "Hookload (max)", None, "KDN", "KLB"),
    WitsItem("0116", "WOBA", "Weight-on-Bit (surf,avg)", "wob", "KDN", "KLB"),
    WitsItem("0118", "TQA", "Rotary Torque (surf,avg)", "torque", "KNM", "KFLB"),
    WitsItem("0120", "RPMA", "Rotary Speed (surf,avg)", "rpm", "RPM", "RPM"),
    WitsItem("0121", "SPPA", "Standpipe Pressure (avg)", "spp", "KPA", "PSI"),
    WitsItem("0130", "MFIA", "Mud Flow In (avg)", "flow_in", "L/M", "GPM"),
    WitsItem("0132", "MDIA", "Mud Density In (avg)", "mud_density", "KGM3", "PPG"),
    WitsItem("0133", "MTOA", "Mud Temperature Out (avg)", "mud_temp_out", "DEGC", "DEGF"),
    WitsItem("0134", "MTIA", "Mud Temperature In (avg)", "mud_temp_in", "DEGC", "DEGF"),
    # record 09 ("MWD Mechanical"): the MWD tool's averages at the bit
    WitsItem("0915", "MWBA", "Downhole Wt-on-Bit (avg)", "downhole_wob", "KDN", "KLB"),
    WitsItem("0917", "MTQA", "Downhole Torque (avg)", "downhole_torque", "KNM", "KFLB"),
)})
"""Record 01 ("General Time-Based") items tdmon reads, and record 09's ("MWD Mechanical")
downhole weight on bit and torque, by code. Item numbers, mnemonics and both unit sets as in
the WITS specification's record layouts (docs/wits0.md)."""

WITS_UNITS: Final[Mapping[str, tuple[float, str]]] = MappingProxyType({
    # length
    "M": (1.0, "m"), "F": (1.0, "ft"), "FT": (1.0, "ft"),
    # force: KDN is the kilodecanewton, 10 kN; TON the metric tonne-force (9.80665 kN)
    "N": (1.0, "N"), "DAN": (1.0, "daN"), "KN": (1.0, "kN"), "KDN": (10.0, "kN"),
    "TON": (1.0, "force_metric_ton"), "LB": (1.0, "lbf"), "KLB": (1.0, "kip"),
    # torque: KFLB is 1000 ft lbf
    "NM": (1.0, "N*m"), "KNM": (1.0, "kN*m"), "FLB": (1.0, "ft*lbf"), "KFLB": (1.0, "kip*ft"),
    # rotary speed
    "RPM": (1.0, "rpm"),
    # pressure
    "KPA": (1.0, "kPa"), "MPA": (1.0, "MPa"), "BAR": (1.0, "bar"), "PSI": (1.0, "psi"),
    # flow rate: GPM is the US gallon per minute
    "L/M": (1.0, "L/min"), "LPM": (1.0, "L/min"), "M3M": (1.0, "m**3/min"),
    "M3/M": (1.0, "m**3/min"), "GPM": (1.0, "gal/min"),
    # density: PPG is pounds per US gallon, SG and G/CC relative to water
    "KGM3": (1.0, "kg/m**3"), "G/CC": (1.0, "g/cm**3"), "SG": (1.0, "sg"), "PPG": (1.0, "ppg"),
    # temperature
    "DEGC": (1.0, "degC"), "DEGF": (1.0, "degF"),
})
"""WITS unit name -> (factor, pint unit): a value ``v`` in the WITS unit is ``v * factor``
in the pint unit (KDN has no pint name of its own). Names are matched case-insensitively."""


@dataclass(frozen=True, slots=True)
class ItemOverride:
    """A feed's change to one item: the channel it feeds (None: keep the default, False: not
    a channel) and its WITS unit (None: the default of the unit system)."""

    channel: str | Literal[False] | None = None
    unit: str | None = None


@dataclass(frozen=True, slots=True)
class ItemSpec:
    """How one item of a feed becomes a channel value: ``si = value * scale + offset``."""

    code: str
    channel: str
    unit: str
    scale: float
    offset: float

    def to_si(self, value: float) -> float:
        return value * self.scale + self.offset

    def from_si(self, value: float) -> float:
        return (value - self.offset) / self.scale


def unit_factor(unit: str, target: str) -> tuple[float, float]:
    """(scale, offset) from the WITS unit name ``unit`` to the pint unit ``target``.

    Raises
    ------
    ValueError
        The name is not in :data:`WITS_UNITS` or does not measure what ``target`` measures.
    """
    entry = WITS_UNITS.get(unit.strip().upper())
    if entry is None:
        raise ValueError(f"unknown WITS unit '{unit}' (one of {', '.join(WITS_UNITS)})")
    factor, pint_unit = entry
    try:
        scale, offset = conversion(pint_unit, target)
    except ValueError:
        raise ValueError(f"WITS unit '{unit}' ({pint_unit}) cannot be converted to "
                         f"'{target}'") from None
    return factor * scale, offset


def item_map(units: UnitSystem = "metric",  # noqa: C901  (complex today; simplify when next touched)
             overrides: Mapping[str, ItemOverride] | None = None) -> dict[str, ItemSpec]:
    """The mapped items of one feed, by code: :data:`DEFAULT_ITEMS` with ``overrides``.

    ``units`` picks each item's default unit (the specification's metric or field set);
    an override may give another channel, ``False`` (the item is not a channel) or another
    unit. An override may name a code outside :data:`DEFAULT_ITEMS` (any record), and must
    then give its channel and unit.

    Raises
    ------
    ValueError
        A code is not four digits, a channel or unit is unknown or does not fit, an item has
        no unit, or two items feed one channel. The message names the code.
    """
    if units not in ("metric", "field"):
        raise ValueError(f"units must be 'metric' or 'field', not '{units}'")
    overrides = overrides or {}
    result: dict[str, ItemSpec] = {}
    for code in [*DEFAULT_ITEMS, *(c for c in overrides if c not in DEFAULT_ITEMS)]:
        if not re.fullmatch(r"\d{4}", code):
            raise ValueError(f"item '{code}': a WITS item code is four digits, e.g. '0114'")
        if code in (DATE_CODE, TIME_CODE) and code in overrides:
            raise ValueError(f"item {code}: the date and time items give the frame's time "
                             "and cannot be remapped")
        default = DEFAULT_ITEMS.get(code)
        override = overrides.get(code, ItemOverride())
        channel = override.channel if override.channel is not None else (
            default.channel if default else None)
        if channel is None or channel is False:
            continue
        try:
            check_channel(channel)
        except ValueError as exc:
            raise ValueError(f"item {code}: {exc}") from None
        unit = override.unit
        if unit is None and default is not None:
            unit = default.metric if units == "metric" else default.field
        if not unit:
            raise ValueError(f"item {code}: give its unit (a WITS unit name such as KDN)")
        try:
            scale, offset = unit_factor(unit, CHANNEL_UNITS[channel][0])
        except ValueError as exc:
            raise ValueError(f"item {code}: {exc}") from None
        result[code] = ItemSpec(code, channel, unit.strip().upper(), scale, offset)
    by_channel: dict[str, str] = {}
    for spec in result.values():
        if spec.channel in by_channel:
            raise ValueError(f"items {by_channel[spec.channel]} and {spec.code} both feed "
                             f"'{spec.channel}': set channel = false on one of them")
        by_channel[spec.channel] = spec.code
    return result


def resolve_timezone(name: str) -> tzinfo:
    """The zone of the date and time items: an IANA name ("UTC", "Europe/Oslo").

    Raises
    ------
    ValueError
        The name is not a known time zone.
    """
    try:
        return ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError):
        raise ValueError(f"unknown time zone '{name}' (an IANA name such as 'UTC' or "
                         "'Europe/Oslo')") from None


# ----------------------------------------------------------------------------- frames

#: Longest frame kept [bytes]: a record 01 with all its items is about 600 bytes; a frame
#: beyond this lost its '!!' (or is not WITS) and is dropped, so memory stays bounded.
MAX_FRAME_BYTES: Final = 2048

_OPEN: Final = b"&&"
_CLOSE: Final = b"!!"


@dataclass(frozen=True, slots=True)
class WitsLine:
    """One data line: ``code`` (four digits) and the value text after it."""

    code: str
    value: str
    text: str


@dataclass(frozen=True, slots=True)
class LineError:
    """A line that could not be read, with the reason."""

    text: str
    reason: str


@dataclass(frozen=True, slots=True)
class WitsFrame:
    """A frame as received (``raw``, markers included) and its lines.

    ``error`` says what was wrong with the frame as a whole though its lines are kept
    (it was not closed by ``!!`` before the next ``&&``); None for a good frame.
    """

    raw: bytes
    lines: tuple[WitsLine, ...]
    errors: tuple[LineError, ...]
    error: str | None = None


@dataclass(frozen=True, slots=True)
class FrameError:
    """Bytes that are not (part of) a usable frame, with the reason; ``raw`` is clipped to
    :data:`MAX_FRAME_BYTES`."""

    reason: str
    raw: bytes


def parse_line(text: str) -> WitsLine | LineError | None:
    """Read one line inside a frame (None: a blank line, which is skipped)."""
    line = text.strip()
    if not line:
        return None
    if len(line) < 5:
        return LineError(line, f"line '{clip(line, 40)}' is too short for a four-digit code and "
                               "a value")
    code, value = line[:4], line[4:].strip()
    if not code.isdigit() or not code.isascii():
        return LineError(line, f"line '{clip(line, 40)}' does not start with a four-digit item "
                               "code")
    if not value:
        return LineError(line, f"item {code} has no value")
    return WitsLine(code, value, line)


class FrameParser:
    """Split a WITS0 byte stream into frames, whatever the reads look like.

    ``feed(data)`` returns what the new bytes completed, in stream order: :class:`WitsFrame`
    for each frame, :class:`FrameError` for bytes outside frames that are not blank
    (garbage), for a frame longer than ``max_frame_bytes`` (dropped whole: its ``!!`` was
    lost, and what follows cannot be trusted to belong to it) and for bytes that are not
    ASCII text. A frame not closed by ``!!`` before the next ``&&`` is kept with its
    ``error`` set (its lines arrived whole). Memory is bounded by ``max_frame_bytes``.
    """

    def __init__(self, max_frame_bytes: int = MAX_FRAME_BYTES) -> None:
        if max_frame_bytes < 16:
            raise ValueError("max_frame_bytes must be at least 16")
        self.max_frame_bytes = max_frame_bytes
        self._partial = bytearray()  # an incomplete line
        self._frame: list[bytes] | None = None  # lines of the open frame (None: outside)
        self._frame_bytes = 0
        self._skipping = False  # dropping an overlong frame up to its end
        self._garbage = bytearray()

    def feed(self, data: bytes) -> list[WitsFrame | FrameError]:
        out: list[WitsFrame | FrameError] = []
        self._partial += data
        start = 0
        while True:
            end = self._partial.find(b"\n", start)
            if end < 0:
                break
            self._line(bytes(self._partial[start:end + 1]), out)
            start = end + 1
        del self._partial[:start]
        if len(self._partial) > self.max_frame_bytes:
            # one line longer than a whole frame: no line end is coming that makes sense
            self._line(bytes(self._partial), out, cut=True)
            self._partial.clear()
        return out

    def close(self) -> list[WitsFrame | FrameError]:
        """End of the stream: report what is left (an unfinished frame, garbage)."""
        out: list[WitsFrame | FrameError] = []
        if self._partial:
            # a last line without its end: part of the open frame, or garbage
            if self._frame is not None:
                self._frame.append(bytes(self._partial))
            elif not self._skipping and self._partial.strip():
                self._garbage += self._partial[: self.max_frame_bytes - len(self._garbage)]
            self._partial.clear()
        if self._frame is not None:
            raw = b"".join(self._frame)
            self._frame = None
            out.append(FrameError("stream ended inside a frame (no '!!')",
                                  raw[: self.max_frame_bytes]))
        self._skipping = False
        self._flush_garbage(out)
        return out

    def _line(self, line: bytes, out: list[WitsFrame | FrameError], cut: bool = False) -> None:
        marker = line.strip()
        if marker == _OPEN:
            self._skipping = False
            self._flush_garbage(out)
            if self._frame is not None:
                out.append(self._finish("frame not closed by '!!' before the next '&&'"))
            self._frame = [line]
            self._frame_bytes = len(line)
            return
        if self._skipping:
            if marker == _CLOSE:
                self._skipping = False
            return
        if self._frame is None:
            if marker:
                self._garbage += line[: self.max_frame_bytes - len(self._garbage)]
                if len(self._garbage) >= self.max_frame_bytes or cut:
                    self._flush_garbage(out)
            return
        self._frame.append(line)
        self._frame_bytes += len(line)
        if self._frame_bytes > self.max_frame_bytes or cut:
            raw = b"".join(self._frame)[: self.max_frame_bytes]
            self._frame = None
            self._skipping = marker != _CLOSE
            out.append(FrameError(f"frame longer than {self.max_frame_bytes} bytes without "
                                  "'!!', dropped", raw))
            return
        if marker == _CLOSE:
            out.append(self._finish(None))

    def _finish(self, error: str | None) -> WitsFrame:
        assert self._frame is not None
        lines = self._frame
        self._frame = None
        good: list[WitsLine] = []
        bad: list[LineError] = []
        for line in lines[1:]:
            if line.strip() == _CLOSE:
                continue
            try:
                text = line.decode("ascii")
            except UnicodeDecodeError:
                bad.append(LineError(line.decode("ascii", "replace").strip(),
                                     "line is not ASCII text"))
                continue
            parsed = parse_line(text)
            if isinstance(parsed, WitsLine):
                good.append(parsed)
            elif parsed is not None:
                bad.append(parsed)
        return WitsFrame(b"".join(lines), tuple(good), tuple(bad), error)

    def _flush_garbage(self, out: list[WitsFrame | FrameError]) -> None:
        if self._garbage:
            out.append(FrameError("bytes outside a frame (no '&&' before them)",
                                  bytes(self._garbage)))
            self._garbage.clear()


# ----------------------------------------------------------------------------- decoding

@dataclass(frozen=True, slots=True)
class ItemValue:
    """A mapped item of a frame: its SI value on its channel, and the line it came from."""

    code: str
    channel: str
    value: float
    line: str


@dataclass(frozen=True, slots=True)
class DecodedFrame:
    """What a frame gives: the time ``t`` [Unix s] (``time_from`` "wits" when the frame's
    date and time items gave it, else "receive"), the mapped items, and the rejected lines
    (the frame's own parse errors, values that are not numbers, a bad date or time)."""

    t: float
    time_from: Literal["wits", "receive"]
    items: tuple[ItemValue, ...]
    errors: tuple[LineError, ...]


def decode_frame(frame: WitsFrame, items: Mapping[str, ItemSpec], receive_time: float,
                 tz: tzinfo | None = None) -> DecodedFrame:
    """Decode a parsed frame with the feed's item map.

    Time: from the date (0105, YYMMDD) and time (0106, HHMMSS) items when the frame carries
    both and they are valid, read in ``tz`` (default UTC); else ``receive_time``. Items not
    in ``items`` are skipped (a feed sends many items tdmon has no use for); a mapped item
    whose value is not a finite number is rejected with the reason. When an item appears
    twice in a frame the last one counts.
    """
    errors = list(frame.errors)
    by_code = {line.code: line for line in frame.lines}
    t: float | None = None
    date, clock = by_code.get(DATE_CODE), by_code.get(TIME_CODE)
    if date is not None and clock is not None:
        stamp = wits_time(date.value, clock.value, tz)
        if isinstance(stamp, str):
            errors.append(LineError(f"{date.text} {clock.text}", stamp))
        else:
            t = stamp
    values: list[ItemValue] = []
    for code, line in by_code.items():
        spec = items.get(code)
        if spec is None:
            continue
        number = _number(line.value)
        if number is None:
            errors.append(LineError(line.text, f"item {code} ({spec.channel}): value "
                                               f"'{clip(line.value, 40)}' is not a number"))
            continue
        si = spec.to_si(number)
        if not math.isfinite(si):
            errors.append(LineError(line.text, f"item {code} ({spec.channel}): value "
                                               f"'{clip(line.value, 40)}' out of range"))
            continue
        values.append(ItemValue(code, spec.channel, si, line.text))
    if t is None:
        return DecodedFrame(receive_time, "receive", tuple(values), tuple(errors))
    return DecodedFrame(t, "wits", tuple(values), tuple(errors))


def wits_time(date: str, clock: str, tz: tzinfo | None = None) -> float | str:
    """Unix seconds from the date (YYMMDD) and time (HHMMSS) item values, or the reason.

    Senders that write them as numbers drop leading zeros ("91520" is 09:15:20) or add a
    fraction ("231004.0"); both are read. A two-digit year YY is 20YY (19YY from 70 on).
    """
    digits = []
    for what, text in (("date", date), ("time", clock)):
        match = re.fullmatch(r"(\d{1,6})(?:\.0*)?", text.strip())
        if match is None or not match.group(1).isascii():
            return f"{what} '{clip(text, 40)}' is not {'YYMMDD' if what == 'date' else 'HHMMSS'}"
        digits.append(match.group(1).zfill(6))
    (d, c) = digits
    year = int(d[:2])
    year += 1900 if year >= 70 else 2000
    try:
        stamp = datetime(year, int(d[2:4]), int(d[4:6]), int(c[:2]), int(c[2:4]), int(c[4:6]),
                         tzinfo=tz or ZoneInfo("UTC"))
    except ValueError as exc:
        return f"date/time '{date.strip()} {clock.strip()}' is not a valid time ({exc})"
    seconds = stamp.timestamp()
    if not T_MIN <= seconds < T_MAX:
        return f"date/time '{date.strip()} {clock.strip()}' out of range"
    return seconds


def _number(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


# ----------------------------------------------------------------------------- encoding

def format_value(value: float | int | str) -> str:
    """The text of an item value: strings as they are, numbers without an exponent."""
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        raise ValueError("a WITS value is a number or a string, not a boolean")
    if isinstance(value, int):
        return str(value)
    if not math.isfinite(value):
        raise ValueError(f"cannot send {value!r} in WITS0")
    text = repr(float(value))
    if "e" in text or "E" in text:
        text = f"{value:.9f}".rstrip("0").rstrip(".")
    return text


def encode_frame(items: Mapping[str, float | int | str] | Iterable[tuple[str, float | int | str]],
                 ) -> bytes:
    """One WITS0 frame: ``&&``, a line per item (code then value), ``!!``, CR LF endings.

    Raises
    ------
    ValueError
        A code is not four digits, or a value is not finite or holds a line end or marker.
    """
    pairs = items.items() if isinstance(items, Mapping) else items
    lines = ["&&"]
    for code, value in pairs:
        if not re.fullmatch(r"\d{4}", code):
            raise ValueError(f"item code '{code}' is not four digits")
        text = format_value(value)
        if not text or any(ch in text for ch in "\r\n") or "&&" in text or "!!" in text:
            raise ValueError(f"item {code}: value {text!r} cannot be sent in a WITS0 line")
        lines.append(code + text)
    lines.append("!!")
    return ("\r\n".join(lines) + "\r\n").encode("ascii")


def si_to_items(values: Mapping[str, float], items: Mapping[str, ItemSpec]) -> dict[str, float]:
    """Channel values in SI -> item code: value in the item's configured WITS unit (the
    inverse of decoding). Channels no item feeds are left out."""
    by_channel = {spec.channel: spec for spec in items.values()}
    out: dict[str, float] = {}
    for channel, value in values.items():
        spec = by_channel.get(channel)
        if spec is not None:
            out[spec.code] = spec.from_si(value)
    return out


def time_items(t: float, tz: tzinfo | None = None) -> dict[str, str]:
    """The date (0105) and time (0106) items of Unix time ``t`` in zone ``tz`` (default
    UTC); WITS0 time has whole seconds, so the fraction is dropped."""
    stamp = datetime.fromtimestamp(math.floor(t), tz or ZoneInfo("UTC"))
    return {DATE_CODE: stamp.strftime("%y%m%d"), TIME_CODE: stamp.strftime("%H%M%S")}


def encode_sample_frame(t: float | None, values: Mapping[str, float],
                        items: Mapping[str, ItemSpec], tz: tzinfo | None = None,
                        decimals: int | None = None) -> bytes:
    """A frame as a rig's server sends it: the date and time of ``t`` (none when ``t`` is
    None) and each channel of ``values`` (SI) as its item in the configured unit, rounded to
    ``decimals`` places when given."""
    fields: dict[str, float | int | str] = dict(time_items(t, tz)) if t is not None else {}
    for code, value in si_to_items(values, items).items():
        fields[code] = round(value, decimals) if decimals is not None else value
    return encode_frame(fields)
