"""Commands of this area are added by the issue that builds them."""

from __future__ import annotations

import argparse
from typing import Any


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add this area's commands (none yet)."""
