"""The rig's canonical channels, their SI units, and the rule for a rig's topic prefix.

Every layer that names a channel (the daemon config, the decoder, the publisher's column map,
the simulator and the importers) checks it here, with one error message, and the daemon config
and the scenario files accept one and the same prefix. ``ChannelSpec``, how a topic feeds a
channel, lives here too: the config builds it and the decoder reads it, and neither has to
import the other.

This module imports nothing of tdmon: every layer may use it.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

__all__ = ["CHANNELS", "CHANNEL_UNITS", "ChannelSpec", "check_channel", "validate_prefix"]

CHANNEL_UNITS: Final[Mapping[str, tuple[str, str]]] = MappingProxyType({
    "hookload": ("N", "N"),
    "torque": ("N*m", "N m"),
    "bit_depth": ("m", "m"),
    "hole_depth": ("m", "m"),
    "block_position": ("m", "m"),
    "rpm": ("rad/s", "rad/s"),
    "flow_in": ("m**3/s", "m^3/s"),
    "spp": ("Pa", "Pa"),
    "wob": ("N", "N"),
    "downhole_wob": ("N", "N"),
    "downhole_torque": ("N*m", "N m"),
    "mud_temp_in": ("degC", "degC"),
    "mud_temp_out": ("degC", "degC"),
    "mud_density": ("kg/m**3", "kg/m^3"),
})
"""Canonical channels and their internal (SI) unit: (unit text, display string). The
temperatures are kept in degrees Celsius, the unit of the friction laws' temperature.
``wob`` is the rig's surface weight on bit; ``downhole_wob`` and ``downhole_torque`` an MWD
tool's readings at the bit (optional; docs/drilling.md)."""

CHANNELS: Final[tuple[str, ...]] = tuple(CHANNEL_UNITS)
"""The canonical channel names, in the order of `CHANNEL_UNITS`."""


def check_channel(name: str, known: Collection[str] = CHANNELS) -> str:
    """``name`` if it is a channel of ``known``, else ValueError naming it and the known ones.

    Parameters
    ----------
    name : a channel name from a file or a command line
    known : the accepted channels (default: every canonical channel; a producer that sends
        fewer, like the simulator, passes its own)

    Raises
    ------
    ValueError
        ``"unknown channel 'name' (one of hookload, torque, ...)"``
    """
    if name not in known:
        raise ValueError(f"unknown channel '{name}' (one of {', '.join(known)})")
    return name


@dataclass(frozen=True, slots=True)
class ChannelSpec:
    """How one topic feeds one canonical channel.

    ``unit`` is the unit assumed when the payload has none (None: the payload must say).
    ``minimum``/``maximum`` bound the converted SI value (None: unbounded).
    """

    channel: str
    topic: str
    unit: str | None = None
    minimum: float | None = None
    maximum: float | None = None


# One level of a topic path: what both MQTT topic names and Zenoh key expressions take without
# a special meaning (no MQTT wildcard + #, no Zenoh wildcard * or $ / ? specials, no space).
_LEVEL: Final = r"[A-Za-z0-9_.\-]+"
_PREFIX: Final = re.compile(rf"{_LEVEL}(?:/{_LEVEL})*")


def validate_prefix(prefix: str) -> str:
    """A rig's topic prefix without its outer slashes, or ValueError.

    The rule, for the daemon config and the scenario files alike: one or more levels separated
    by ``/``, each of ASCII letters, digits, ``_``, ``-`` or ``.`` (``rig/F4``, ``sim/trip-out``).
    So the prefix means the same on MQTT and on Zenoh: no wildcard, no empty level, no space.

    Raises
    ------
    ValueError
        The prefix is empty or holds another character.
    """
    value = prefix.strip("/")
    if not _PREFIX.fullmatch(value):
        raise ValueError(f"prefix '{prefix}' must be a plain topic path such as 'rig/F4': levels "
                         "of letters, digits, '_', '-' or '.' separated by '/'")
    return value
