"""Fast ``__init__`` for the frozen, slotted value types made once per message or frame.

The ``__init__`` a frozen dataclass gets sets each field through ``object.__setattr__`` (its
own ``__setattr__`` refuses), about 0.1 us a field; the slot's descriptor sets it in half
that: 0.44 instead of 0.82 us for a RawMessage (docs/benchmarks.md). The classes made on every
input message (``RawMessage``, ``Sample``) and the monitor's loads write their ``__init__`` by
hand with these setters and nothing else (the calibration's per-frame states are plain frozen
dataclasses: their share of a replay is too small to be worth a hand-written ``__init__``);
``tests/test_hand_written_inits.py`` checks that each takes its fields, in order, with their
defaults, the classes' own tests that the instances stay frozen.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields
from typing import Any

__all__ = ["slot_setters"]


def slot_setters(cls: type) -> tuple[Callable[[Any, Any], None], ...]:
    """The ``__set__`` of each field's slot of the frozen, slotted dataclass ``cls``, in
    field order."""
    return tuple(cls.__dict__[f.name].__set__ for f in fields(cls))
