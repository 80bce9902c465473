"""The bounds every file tdmon reads at start-up is held to, each with the reason for it.

A file that breaks one is refused with one line naming the file, the key and the bound
(:class:`tdmon.errors.ConfigError`, exit code 2), within a second, before any of it is used:
a typing mistake (``"1e308 s"``, ``10**30``) or a hostile file (a million survey stations,
brackets nested thousands deep) never makes the daemon hang, overflow or exhaust memory.
"""

from __future__ import annotations

from typing import Final

#: [bytes] Largest TOML file read. tomllib parses about 1 MB/s on a loaded 2-core machine,
#: so this bound keeps any file's parse within a second or two; the largest file shipped is
#: under 10 kB. A long survey belongs in a CSV file (``[survey] file``).
MAX_TOML_BYTES: Final = 1024 * 1024

#: [bytes] Largest survey CSV file read (:data:`MAX_SURVEY_STATIONS` rows of 40 characters,
#: with room for extra columns).
MAX_SURVEY_FILE_BYTES: Final = 16 * 1024 * 1024

#: Most survey stations in one well. Surveys are taken every 30 m (about 500 stations in a
#: 15 km well), a continuous gyro survey every metre or so; beyond this the stations are
#: closer than any element length the model uses.
MAX_SURVEY_STATIONS: Final = 50_000

#: [m] Deepest measured depth accepted (a survey station, a hole section's bottom, a string
#: component's length). The longest wells drilled reach about 15 km measured depth.
MAX_MEASURED_DEPTH: Final = 20_000.0

#: Most model elements along the hole (the hole's depth over ``element_length``): the model
#: marches element by element for every hook load, so more would miss the rig's sample rate.
MAX_ELEMENTS: Final = 100_000

#: [s] Longest duration in a daemon or scenario file (timeouts, intervals, rotation): one
#: week. asyncio's timers overflow near 1e10 s, and a longer wait is a typing mistake.
MAX_DURATION: Final = 7 * 24 * 3600.0

#: Most messages a queue of the daemon may hold (``[queues] ingest`` and ``publish``). At the
#: default 4 KiB payload bound that is up to 4 GB; more would only trade a lag for a crash.
MAX_QUEUE: Final = 1_000_000

#: [bytes] Largest ``[queues] max_payload_bytes``: 16 MiB, an upper bound on any rig message
#: (they are tens of bytes) that still keeps a recorded rejection's copy bounded.
MAX_PAYLOAD_BYTES: Final = 16 * 1024 * 1024

__all__ = [
    "MAX_DURATION",
    "MAX_ELEMENTS",
    "MAX_MEASURED_DEPTH",
    "MAX_PAYLOAD_BYTES",
    "MAX_QUEUE",
    "MAX_SURVEY_FILE_BYTES",
    "MAX_SURVEY_STATIONS",
    "MAX_TOML_BYTES",
]
