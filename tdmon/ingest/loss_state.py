"""The loss detector's state kept beside a live daemon's recordings, so that a restarted daemon
counts the messages that never came while it was away (docs/daemon.md, "Loss the daemon can
see"): the last ``seq`` of each topic with the jumps still held open, and each channel's
sampling history. One small JSON file, replaced whole (written beside it, then renamed), so a
daemon killed while writing it leaves the previous one."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any, Final

log = logging.getLogger(__name__)

#: The file's name in the recorder's folder
LOSS_STATE_FILE: Final = "loss-state.json"
#: Its format; a file of another version is ignored (a fresh start, with a warning)
VERSION: Final = 1
#: [bytes] Largest state file read (a state is a few kB; a larger file is not ours)
MAX_STATE_BYTES: Final = 4 * 1024 * 1024


def write_state(path: Path, state: dict[str, Any]) -> None:
    """Replace the state file at ``path`` by ``state`` (atomically: a rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(json.dumps({"version": VERSION, **state}), encoding="utf-8")
    os.replace(temporary, path)


def read_state(path: Path) -> dict[str, Any] | None:
    """The state saved at ``path``, or None when there is none or it cannot be used (logged
    once: the daemon then starts its counting afresh, as before)."""
    try:
        if path.stat().st_size > MAX_STATE_BYTES:
            raise ValueError(f"larger than {MAX_STATE_BYTES} bytes")
        state = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(state, dict) or state.get("version") != VERSION:
            raise ValueError(f"not a version {VERSION} loss state")
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        log.warning("%s: loss state not used (%s); counting loss afresh", path, exc)
        return None
    return state
