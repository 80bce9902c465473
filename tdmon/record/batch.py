"""A batch of daemon messages of one topic: what the pipeline hands every sink.

A :class:`Batch` carries the topic, the messages' log times [ns since the Unix epoch] and the
items they are made of (a step's message, or the ``RawMessage``/``Sample`` objects of a burst),
with how a message is made of an item (:class:`Items`). Each sink asks for the form it needs;
every form is made once, on first demand, for all the sinks that share the batch:

* :meth:`Batch.messages`: the message dicts (docs/architecture.md, "Daemon messages");
* :meth:`Batch.encoded`: their JSON bytes, NaN and infinities written as ``null`` and counted
  (the in-process recorder, the publishers); a replay of tdmon's own recording may hand over
  the bytes its recording held (:attr:`Items.encoded`);
* :meth:`Batch.rows`: tuples of plain values from which :attr:`Items.from_row` makes the
  messages again (the recorder in a child process: a batch pickles as its rows, and the
  messages are made on the other side).

A single message is a batch of one (:meth:`Batch.one`).
"""

from __future__ import annotations

import json
import math
from bisect import bisect_right
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from itertools import accumulate
from typing import Any, Final, NamedTuple

import orjson

__all__ = ["MESSAGES", "Batch", "Encoded", "Items", "encode_message"]

@dataclass(frozen=True, slots=True)
class Items:
    """How the items of a batch become its messages.

    Attributes
    ----------
    message
        An item's message; None when the items are the messages.
    row
        An item's *row*: a tuple of plain values (picklable, cheaper to pickle than the
        message); None when a message is its own row.
    from_row
        A row's message (with ``row``): a module-level function or a ``functools.partial`` of
        one, as it is pickled by name.
    encoded
        The items' messages as JSON bytes when the items hold them already (each exactly what
        :func:`encode_message` would write of its message, with no NaN or infinity), else
        None: the bytes are then encoded from the messages.
    """

    message: Callable[[Any], dict[str, Any]] | None = None
    row: Callable[[Any], Any] | None = None
    from_row: Callable[[Any], dict[str, Any]] | None = None
    encoded: Callable[[Sequence[Any]], list[bytes] | None] | None = None


#: Items that are the messages themselves (what the steps emit).
MESSAGES: Final = Items()


class Encoded(NamedTuple):
    """A batch's messages as JSON bytes (:meth:`Batch.encoded`)."""

    datas: list[bytes]
    """The JSON bytes of each message that is JSON, in order."""
    log_times_ns: Sequence[int]
    """The log time of each of ``datas`` [ns since the Unix epoch]."""
    nonfinite: int
    """How many of them had a NaN or an infinity, written as ``null``."""
    refused: Sequence[str]
    """Why each message left out is not JSON (a value no encoder takes, a row that makes no
    message)."""


_NOTHING_REFUSED: Final[Sequence[str]] = ()


class Batch:
    """Messages of one topic, their log times and the items they are made of.

    The items must not change once the batch is made: the forms are made when a sink first
    asks (a recorder may ask later, when it writes), and are shared by every sink.
    """

    __slots__ = ("_encoded", "_messages", "_rows", "items", "kind", "log_times_ns", "topic")

    def __init__(self, topic: str, log_times_ns: Sequence[int], items: Sequence[Any],
                 kind: Items = MESSAGES) -> None:
        if len(log_times_ns) != len(items):
            raise ValueError(f"{len(log_times_ns)} log times for {len(items)} items")
        self.topic = topic
        self.log_times_ns = log_times_ns
        self.items = items
        self.kind = kind
        self._messages: Sequence[dict[str, Any]] | None = None
        self._rows: Sequence[Any] | None = None
        self._encoded: Encoded | None = None

    @classmethod
    def one(cls, topic: str, log_time_ns: int, message: dict[str, Any]) -> Batch:
        """A batch of one message."""
        return cls(topic, (log_time_ns,), (message,))

    def __len__(self) -> int:
        return len(self.items)

    def __repr__(self) -> str:
        return f"Batch({self.topic!r}, {len(self.items)} messages)"

    def messages(self) -> Sequence[dict[str, Any]]:
        """The messages, in order."""
        messages = self._messages
        if messages is None:
            make = self.kind.message
            messages = self.items if make is None else list(map(make, self.items))
            self._messages = messages
        return messages

    def rows(self) -> Sequence[Any]:
        """Each message as a row of plain values (:attr:`Items.row`; the message itself when
        the items have no rows)."""
        rows = self._rows
        if rows is None:
            row = self.kind.row
            rows = self.messages() if row is None else list(map(row, self.items))
            self._rows = rows
        return rows

    def encoded(self) -> Encoded:
        """The messages as JSON bytes (:func:`encode_message`'s), with what was replaced or
        left out."""
        encoded = self._encoded
        if encoded is None:
            encoded = self._encoded = self._encode()
        return encoded

    def __reduce__(self) -> tuple[Callable[..., Batch], tuple[Any, ...]]:
        # pickled as its rows and the function that makes a message of one
        from_row = self.kind.from_row if self.kind.row is not None else None
        return _batch_of_rows, (self.topic, self.log_times_ns, self.rows(), from_row)

    def _encode(self) -> Encoded:
        held = self.kind.encoded
        if held is not None:
            datas = held(self.items)
            if datas is not None:
                return Encoded(datas, self.log_times_ns, 0, _NOTHING_REFUSED)
        try:
            messages = self.messages()
            if len(messages) == 1:  # a step's message: several per frame
                message = messages[0]
                data = _dumps(message)
                nonfinite = b"null" in data and has_nonfinite(message)
                return Encoded([data], self.log_times_ns, int(nonfinite), _NOTHING_REFUSED)
            # every message in one C loop; numpy values through ``default``
            datas = list(map(_dumps, messages))
        except Exception:  # a message orjson refuses, an item that makes no message
            return self._encode_each()
        return Encoded(datas, self.log_times_ns, _count_nonfinite(messages, datas),
                       _NOTHING_REFUSED)

    def _encode_each(self) -> Encoded:
        """``_encode`` one message at a time: those that are not JSON are left out."""
        datas: list[bytes] = []
        times: list[int] = []
        refused: list[str] = []
        nonfinite = 0
        made, make = self._messages, self.kind.message
        for index, (item, log_time_ns) in enumerate(zip(self.items, self.log_times_ns,
                                                        strict=True)):
            try:
                message = (made[index] if made is not None
                           else item if make is None else make(item))
                data, replaced = encode_message(message)
            except Exception as exc:
                refused.append(f"a message on {self.topic} is not JSON: {exc}")
                continue
            datas.append(data)
            times.append(log_time_ns)
            nonfinite += replaced
        return Encoded(datas, times, nonfinite, refused)


def _batch_of_rows(topic: str, log_times_ns: Sequence[int], rows: Sequence[Any],
                   from_row: Callable[[Any], dict[str, Any]] | None) -> Batch:
    """A pickled batch again (see ``Batch.__reduce__``)."""
    return Batch(topic, log_times_ns, rows,
                 MESSAGES if from_row is None else Items(message=from_row))


# -- JSON ------------------------------------------------------------------------------------

def numpy_default(value: Any) -> Any:
    """The ``default`` of a JSON encoder: numpy scalars and arrays (float32, int64, ndarray)
    as their Python numbers and lists; ``TypeError`` for anything else."""
    tolist = getattr(value, "tolist", None)
    if tolist is None:
        raise TypeError(f"{type(value).__name__} is not JSON serialisable")
    return tolist()


# numpy values through ``default`` (``tolist``), not orjson's own numpy option: the same
# numbers as the json module writes (float32 included)
_dumps: Final = partial(orjson.dumps, default=numpy_default)

# the stdlib encoder, for what orjson refuses (keys that are not strings, integers beyond 64
# bits) and to find whether a ``null`` in orjson's output was a NaN or an infinity (json
# refuses those). One encoder object: json.dumps with options builds a new one per call.
_ENCODER: Final = json.JSONEncoder(separators=(",", ":"), allow_nan=False,
                                   default=numpy_default)


def encode_message(message: Mapping[str, Any]) -> tuple[bytes, bool]:
    """A message's compact JSON bytes, and whether a NaN or an infinity in it was written as
    ``null``.

    orjson (about ten times faster than the json module) writes NaN and infinities as ``null``
    without saying so; only a message whose bytes hold ``null`` is searched for them. What
    orjson refuses goes through the json module, with the same rule. Raises ``TypeError`` or
    ``ValueError`` for something that is not JSON at all.
    """
    try:
        data = _dumps(message)
    except TypeError:  # orjson.JSONEncodeError: a key that is not a string, a huge integer...
        try:
            return _ENCODER.encode(message).encode(), False
        except ValueError:
            return _ENCODER.encode(replace_nonfinite(message)).encode(), True
    return data, b"null" in data and has_nonfinite(message)


def replace_nonfinite(value: Any) -> Any:
    """``value`` with every NaN and infinity replaced by None (numpy values as Python ones)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {key: replace_nonfinite(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [replace_nonfinite(item) for item in value]
    if hasattr(value, "tolist"):
        return replace_nonfinite(value.tolist())
    return value


def _count_nonfinite(messages: Sequence[Any], datas: list[bytes]) -> int:
    """How many of ``messages`` (encoded as ``datas``) had a NaN or an infinity: only those
    whose bytes hold ``null`` are searched, found in one search of the joined bytes."""
    joined = b"".join(datas)
    found = joined.find(b"null")
    if found < 0:
        return 0
    ends = list(accumulate(map(len, datas)))
    count = 0
    while found >= 0:
        # a null does not straddle two messages: each is a whole JSON value
        index = bisect_right(ends, found)
        count += has_nonfinite(messages[index])
        found = joined.find(b"null", ends[index])
    return count


#: the types of the values that are never a NaN or an infinity
_NEVER_NONFINITE: Final = frozenset((str, int, bool, type(None)))


def has_nonfinite(message: Any) -> bool:
    """Whether a NaN or an infinity is somewhere in ``message``.

    Walks plain dicts, lists, tuples, floats and strings (the daemon's messages; a model
    message with a null took ~5x longer through the json module); anything else (numpy
    values, other types) is left to the json module, which encodes the whole message again.
    Recursive: orjson refuses a message nested deeper than 255 levels, long before Python's
    recursion limit, so no message that reaches this check is too deep for it.
    """
    try:
        return _nonfinite_in((message,))
    except _NotPlain:
        try:
            _ENCODER.encode(message)
        except ValueError:
            return True
        except (TypeError, RecursionError):  # something only orjson writes (a datetime...)
            return False
        return False


class _NotPlain(Exception):
    """A value the walk leaves to the json module (a numpy value, an object)."""


def _nonfinite_in(values: Iterable[Any]) -> bool:  # noqa: C901  (complex today; simplify when next touched)
    for item in values:
        kind = type(item)
        if kind is float:
            if item - item != 0.0:  # nan - nan and inf - inf are nan
                return True
        elif kind is dict:
            if _nonfinite_in(item.values()):
                return True
        elif kind is list or kind is tuple:
            # a list of plain numbers (a model's band, a profile's bins) in one C loop: a
            # finite float sum means every element is finite; a NaN or an infinity makes it
            # non-finite, and so may an overflow, hence the walk then
            try:
                total = sum(item, 0.0)
            except (TypeError, OverflowError):
                # a long list of texts and nulls (a profile's reasons per bin): its element
                # types gathered in one C loop, not each element walked
                if len(item) >= 16 and set(map(type, item)) <= _NEVER_NONFINITE:
                    continue
            else:
                if type(total) is float and total - total == 0.0:
                    continue
            if _nonfinite_in(item):
                return True
        elif kind not in _NEVER_NONFINITE and not isinstance(item, (str, int)):
            # str and int subclasses (the vocabulary's enums, bool) are never non-finite
            raise _NotPlain
    return False
