"""The ``tdmon`` command line: one entry point, one sub-command module per area.

Each module in ``_COMMAND_MODULES`` exposes ``register(subparsers)``, which adds its commands
and sets ``func`` (a callable taking the parsed arguments and returning the exit code).
User mistakes surface as :class:`tdmon.errors.TdmonError` and are printed as one line on stderr
with exit code 2; anything else is a bug and keeps its traceback.

``-q`` and ``-v`` (before the command) apply to every command: the log's level, over
``--log-level`` where a command has it, and with ``-q`` no progress bar or status line.

SIGINT is handled from this module's first line: a shell without job control starts a
background job (``tdmon publish ... &`` in a script) with SIGINT ignored, and Python then
installs no handler of its own, so ``kill -INT`` would be lost until a command re-armed it.
Until :func:`main` runs, a SIGINT ends the process at once with code 130 (nothing has started
that needs a clean stop); from then on it is a KeyboardInterrupt like any other.
"""

from __future__ import annotations

import signal
import sys
from types import FrameType


def _interrupted_while_starting(signum: int, frame: FrameType | None) -> None:
    """SIGINT before :func:`main`: exit 130 quietly, wherever the imports are."""
    print("tdmon: interrupted", file=sys.stderr)
    raise SystemExit(130)


if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, _interrupted_while_starting)

import argparse  # noqa: E402 (after SIGINT is armed)
import importlib  # noqa: E402
import logging  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from typing import NoReturn  # noqa: E402

from tdmon import __version__  # noqa: E402
from tdmon.blas import limit_blas_threads  # noqa: E402
from tdmon.errors import TdmonError  # noqa: E402

_COMMAND_MODULES = ("model", "lab", "run", "record", "replay", "bridge", "fleet", "batch",
                    "examples")

#: The log's format with -q or -v (that of ``tdmon run``'s log).
LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


class _Parser(argparse.ArgumentParser):
    """Usage mistakes on one line, like every other user mistake (the usage is one ``--help``
    away and, for commands with many options, longer than the message)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="tdmon",
        description=(
            "Real-time torque-and-drag monitor: modelled pick-up, slack-off and rotating loads "
            "with temperature-dependent friction, live friction back-calculation, MCAP flight "
            "recording. JSON, CSV and recordings are SI (N, N m, m); tables, reports and Rerun "
            "views show SI or field units (--units, TDMON_UNITS); inputs and flags accept units."
        ),
    )
    parser.add_argument("--version", action="version", version=f"tdmon {__version__}")
    loudness = parser.add_mutually_exclusive_group()
    loudness.add_argument("-v", "--verbose", action="count", default=0,
                          help="more in the log: info messages, -vv debug (run and bridge, "
                               "which log info by default: debug); over --log-level")
    loudness.add_argument("-q", "--quiet", action="store_true",
                          help="errors only in the log, and no progress bar or status line "
                               "(as --no-progress, --status-every 0); results still print")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in _COMMAND_MODULES:
        module = importlib.import_module(f"tdmon.cli.{name}")
        module.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    if signal.getsignal(signal.SIGINT) is _interrupted_while_starting:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return _run(argv)
    except KeyboardInterrupt:  # at any stage: parsing, imports, the command itself
        print("tdmon: interrupted", file=sys.stderr)
        return 130


def _run(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help(sys.stderr)
        return 2
    set_loudness(args)
    # the small matrices of the calibration run faster on one BLAS thread (tdmon.blas); after
    # parsing, so that --help and usage mistakes do not import numpy
    limit_blas_threads()
    try:
        return int(func(args) or 0)
    except TdmonError as exc:
        print(f"tdmon: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 0


def set_loudness(args: argparse.Namespace) -> None:
    """Apply -q / -v: the level of tdmon's loggers (other libraries' stay at warning, or
    error with -q), a handler on the root logger (which makes a command's own
    ``logging.basicConfig(level=--log-level)`` a no-op), and with -q the command's progress
    and status options off. Without either, nothing changes."""
    if not (args.quiet or args.verbose):
        return
    if args.quiet:
        level = logging.ERROR
        for name, off in (("no_progress", True), ("status_every", 0.0)):
            if hasattr(args, name):
                setattr(args, name, off)
    else:
        # one step below the command's own default: warning, or info where it has --log-level
        default = logging.INFO if hasattr(args, "log_level") else logging.WARNING
        level = max(logging.DEBUG, default - 10 * args.verbose)
    logging.basicConfig(level=max(level, logging.WARNING), stream=sys.stderr,
                        format=LOG_FORMAT, force=True)
    logging.getLogger("tdmon").setLevel(level)


if __name__ == "__main__":
    sys.exit(main())
