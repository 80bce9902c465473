"""Argument types and options shared by the commands: quantities with units, ``--units``.

Kept free of pint and numpy at import time: ``tdmon --help`` builds every parser.
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tdmon.config.daemon import MqttConfig, ZenohConfig
    from tdmon.display import UnitSystem

UNIT_SYSTEMS = ("si", "field")
_NUMBER_FIRST = re.compile(r"\s*[-+]?\.?\d")  # tdmon.display.SYSTEMS, without importing it here


def quantity_arg(target: str, example: str, *, positive: bool = False) -> Callable[[str], float]:
    """An argparse ``type`` reading a number in ``target`` or a number with a unit.

    Parameters
    ----------
    target : the internal unit the value is returned in (a unit text, e.g. ``"m"``)
    example : a valid value with a unit, quoted in the error message (e.g. ``"6500 ft"``)
    positive : refuse zero and negative values

    Returns
    -------
    A function ``text -> float [target]``: ``quantity_arg("m", "6500 ft")("6500 ft")``
    is 1981.2. A bad value raises :class:`argparse.ArgumentTypeError`; argparse then names the
    flag and exits with code 2.
    """

    shown = target.replace("**", "^").replace("*", " ")

    def parse(text: str) -> float:
        from tdmon.units import UnitError, parse_quantity

        hint = f"give a number [{shown}] or a number with a unit, e.g. '{example}'"
        try:
            value = float(text)
        except ValueError:
            if not _NUMBER_FIRST.match(text):
                raise argparse.ArgumentTypeError(f"'{text}': {hint}") from None
            try:
                value = parse_quantity(text, target)
            except ValueError as exc:
                # the flag's own example rather than the unit module's list of units
                reason = exc.reason if isinstance(exc, UnitError) else str(exc)
                raise argparse.ArgumentTypeError(f"{reason}; {hint}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"'{text}' is not finite; e.g. '{example}'")
        if positive and not value > 0:
            raise argparse.ArgumentTypeError(f"'{text}' must be positive, e.g. '{example}'")
        return value

    parse.__name__ = f"quantity [{target}]"  # argparse names the type in some messages
    return parse


def add_units_option(parser: argparse.ArgumentParser, what: str = "tables") -> None:
    """``--units si|field``: the units ``what`` is shown in (default: ``TDMON_UNITS``, else the
    daemon file's ``[display] units`` where the command reads one, else si)."""
    parser.add_argument(
        "--units", choices=UNIT_SYSTEMS, default=None,
        help=f"units of {what}: 'si' (kN, kN m, m, degC) or 'field' (klbf, kft lbf, ft, ppg, "
             "degF, psi, gpm); default: $TDMON_UNITS, else si. JSON and CSV stay SI")


def display_units(args: argparse.Namespace, config: str | None = None) -> UnitSystem:
    """The unit system the command shows (``--units``, ``TDMON_UNITS``, ``config``, si)."""
    from tdmon.display import resolve

    return resolve(getattr(args, "units", None), config)


def flag_targets(args: argparse.Namespace, password: str | None
                 ) -> tuple[MqttConfig | None, ZenohConfig | None]:
    """Where ``--mqtt HOST:PORT`` or ``--zenoh-connect``/``--zenoh-listen`` say to publish
    (``tdmon publish``, ``tdmon bridge``); (None, None) when neither is given."""
    from tdmon.config.daemon import MqttConfig, TlsConfig, ZenohConfig
    from tdmon.errors import TdmonError

    if args.mqtt:
        host, _, port = args.mqtt.rpartition(":")
        if not host or not port.isdigit():
            raise TdmonError(f"--mqtt must be HOST:PORT, got '{args.mqtt}'")
        return MqttConfig(host=host, port=int(port), client_id=args.client_id,
                          username=args.username, password=password,
                          tls=TlsConfig(ca_file=args.ca_file) if args.ca_file else None,
                          clean_session=True), None
    if args.zenoh_connect or args.zenoh_listen:
        return None, ZenohConfig(connect=args.zenoh_connect, listen=args.zenoh_listen)
    return None, None


def toward_zenoh_source(source: ZenohConfig) -> ZenohConfig:
    """A session that reaches a daemon's Zenoh source: connect where it listens (or where it
    connects), as a peer if it is one, else as a client."""
    from tdmon.config.daemon import ZenohConfig

    return ZenohConfig(mode="peer" if source.mode == "peer" else "client",
                       connect=source.listen or source.connect)


def output_file(path: Path, what: str = "") -> Path:
    """``path`` with its missing parent folders created, as every command that writes a file
    does (docs/configuration.md, "Output files"); a folder that cannot be made is one line.

    Raises
    ------
    TdmonError
        Naming the file (and ``what``, e.g. the flag) and the reason.
    """
    from tdmon.errors import TdmonError

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        label = f"{what}: " if what else ""
        raise TdmonError(f"{label}cannot create the folder of {path}: "
                         f"{exc.strerror or exc}") from exc
    return path
