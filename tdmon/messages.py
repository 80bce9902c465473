"""Constructors of the daemon's ``alarm``, ``estimate`` and ``status`` messages.

One place builds each shape of docs/architecture.md ("Daemon messages"), so that the producers
(the calib alarms, the recorders' own alarms, the pipeline's status) cannot drift apart from each
other or from the JSON Schemas of `tdmon.record.schemas`. The words of a message are checked
against `tdmon.vocabulary` (an unknown alarm kind raises ``ValueError`` here, where the
producer is, not later in a schema check of a recording) and stored as plain ``str``: a
message is pickled to the recorder child and compared with recordings, and a plain string is
what it held before the vocabulary.

Like the vocabulary this module imports nothing of tdmon above it: every layer may use it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from tdmon.vocabulary import AlarmKind, EstimateKind, Severity

__all__ = ["alarm_message", "estimate_message", "status_message"]


def _finite_or_none(x: float | None) -> float | None:
    """JSON has no NaN or infinity: a non-finite number becomes null."""
    return float(x) if x is not None and math.isfinite(x) else None


def alarm_message(t: float, kind: AlarmKind | str, severity: Severity | str, message: str,
                  value: float | None = None, limit: float | None = None) -> dict[str, Any]:
    """The ``alarm`` message.

    Parameters
    ----------
    t : Unix time [s]
    kind : an `AlarmKind` (or its value)
    severity : a `Severity` (or its value)
    message : text for the operator
    value : the measured value that raised it, in SI (non-finite: null)
    limit : the limit it crossed, same unit (non-finite: null)

    Returns
    -------
    dict with ``t``, ``kind``, ``severity``, ``message``, ``value``, ``limit``

    Raises
    ------
    ValueError
        ``kind`` or ``severity`` is not in the vocabulary.
    """
    return {"t": float(t), "kind": AlarmKind(kind).value, "severity": Severity(severity).value,
            "message": message, "value": _finite_or_none(value),
            "limit": _finite_or_none(limit)}


def estimate_message(t: float, kind: EstimateKind | str, operation: str, mu: float,
                     mu_std: float | None, **fields: Any) -> dict[str, Any]:
    """The ``estimate`` message: the common fields, then the kind-specific ``fields``.

    Parameters
    ----------
    t : Unix time [s]
    kind : an `EstimateKind` (or its value)
    operation : the load case it calibrates (an `Operation`, or for the combined-motion
        windows their `RigState`, ``reaming`` or ``back_reaming``)
    mu : friction factor [-]
    mu_std : its standard deviation [-] (None: one sample has no spread)
    **fields : kind-specific fields (docs/architecture.md), kept in their order

    Raises
    ------
    ValueError
        ``kind`` is not an `EstimateKind`.
    """
    return {"t": t, "kind": EstimateKind(kind).value, "operation": str(operation), "mu": mu,
            "mu_std": mu_std, **fields}


def status_message(t: float, samples_in: int, rejected: int, dropped: int,
                   lag_s: float | None, connections: Mapping[str, str],
                   **counters: int) -> dict[str, Any]:
    """The periodic ``status`` message.

    Parameters
    ----------
    t : Unix time [s]
    samples_in : decoded samples so far [-]
    rejected : rejected inputs so far [-]
    dropped : messages dropped by full queues so far [-]
    lag_s : wall-clock time since the newest sample [s] (None: no sample yet)
    connections : each source's and publisher's state: a `ConnectionState` value or
        ``"retrying in N s: reason"``
    **counters : further counters, appended in their order

    Returns
    -------
    dict (``connections`` copied, its states plain strings)
    """
    return {"t": t, "samples_in": samples_in, "rejected": rejected, "dropped": dropped,
            "lag_s": lag_s,
            "connections": {name: str(state) for name, state in connections.items()},
            **counters}
