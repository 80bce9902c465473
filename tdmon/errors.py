"""One exception tree for tdmon: a base class and one subclass per layer.

Lower libraries' exceptions are translated where they are called and raised ``from`` the cause,
so the command line can print one clear line for any ``TdmonError`` and a traceback for nothing
else.
"""

from __future__ import annotations


class TdmonError(Exception):
    """Base of every error tdmon raises on purpose."""


class ConfigError(TdmonError):
    """A configuration file is missing, unreadable or invalid.

    The message names the file, the key (dotted path) and the reason.
    """

    def __init__(self, file: str, key: str, reason: str) -> None:
        self.file = file
        self.key = key
        self.reason = reason
        where = f"{file}: {key}" if key else file
        super().__init__(f"{where}: {reason}")


class ModelError(TdmonError):
    """Inputs the physics cannot be evaluated with (e.g. bit depth below the string's length)."""


class FitError(TdmonError):
    """A regression or back-calculation did not converge or is not defined for the data."""


class IngestError(TdmonError):
    """A source cannot connect, authenticate or read its input."""


class RecordError(TdmonError):
    """A recording cannot be written or read."""
