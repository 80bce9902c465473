"""Rig names that come from the network: the rule they must meet before they are used.

A fleet daemon (``[fleet]``) takes a rig's name from the first level of a topic under its
prefix, ``<prefix>/<name>/...``; the name becomes a folder and file names of the recording,
a key in the daemon's tables, a part of the rig's result topics and words in log lines. Anyone
who can publish chooses it, so it is checked first (docs/fleet.md, "Rig names"):

- 1 to :data:`MAX_NAME_CHARS` characters of ASCII letters, digits, ``_``, ``-`` and ``.``;
- first a letter or a digit (no ``.``/``..``, no hidden folder, nothing read as an option);
- and the file's ``[fleet] name_pattern``, which can narrow the rule but never widen it.

A name that fails is refused and counted; it is never kept, and it appears in a log line only
through :func:`printable` (escaped and cut short).
"""

from __future__ import annotations

import re

#: The longest rig name accepted [characters].
MAX_NAME_CHARS = 64

#: The rule every rig name found on the network meets (documented above).
SAFE_NAME = re.compile(rf"[A-Za-z0-9][A-Za-z0-9_.-]{{0,{MAX_NAME_CHARS - 1}}}")

#: ``[fleet] name_pattern`` when the file gives none: the safe rule itself.
DEFAULT_NAME_PATTERN = SAFE_NAME.pattern

#: Characters of a network text shown in a log line, at most.
SHOWN_CHARS = 48


def name_refusal(name: str, pattern: re.Pattern[str]) -> str | None:
    """Why ``name`` cannot be a rig's name (None: it can); the reason never quotes the name."""
    if not name:
        return "empty name"
    if len(name) > MAX_NAME_CHARS:
        return f"name of {len(name)} characters (at most {MAX_NAME_CHARS})"
    if SAFE_NAME.fullmatch(name) is None:
        return "name outside [A-Za-z0-9_.-] or not starting with a letter or digit"
    if pattern.fullmatch(name) is None:
        return "name not matching [fleet] name_pattern"
    return None


def printable(text: str, limit: int = SHOWN_CHARS) -> str:
    """``text`` fit for one log line: control and non-ASCII characters escaped (a newline can
    forge no line), cut to ``limit`` characters with the whole length said."""
    shown = text[:limit].encode("ascii", "backslashreplace").decode("ascii")
    shown = "".join(c if c.isprintable() else f"\\x{ord(c):02x}" for c in shown)
    return shown if len(text) <= limit else f"{shown}... ({len(text)} characters)"
