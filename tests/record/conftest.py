"""Shared fixtures of the recording tests: a synthetic stream and a helper to run child scripts."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tdmon.record.reader import RecordedMessage
from tdmon.record.synthetic import synthetic_messages

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def stream() -> list[RecordedMessage]:
    """Ten minutes of every topic (about 4800 messages)."""
    return list(synthetic_messages(duration_s=600))


@pytest.fixture
def repo() -> Path:
    """The checkout (working directory of child interpreters)."""
    return REPO


@pytest.fixture
def run_child() -> Callable[..., dict[str, Any]]:
    """Runs a Python snippet in a fresh interpreter; see :func:`_run_child`."""
    return _run_child


def _run_child(script: str, *args: str, timeout: float = 120.0) -> dict[str, Any]:
    """Run a Python snippet in a fresh interpreter; it prints one JSON object as its last line."""
    completed = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(script), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=REPO,
        check=False,
    )
    assert completed.returncode == 0, completed.stderr
    return json.loads(completed.stdout.strip().splitlines()[-1])
