"""Unit conversions pint computed once are read back from the user's cache folder, without
importing pint; a foreign or corrupt file is ignored (tdmon/units.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROBE = (
    "import sys\n"
    "from tdmon.units import parse_quantity\n"
    "print(repr(parse_quantity('9950 ft', 'm')), repr(parse_quantity('60 degF', 'degC')),\n"
    "      repr(parse_quantity('13 ppg', 'kg/m^3')), 'pint' in sys.modules)\n"
)


def _run(cache: Path) -> list[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "XDG_CACHE_HOME": str(cache)}
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                          env=env, timeout=120, check=True)
    return done.stdout.split()


def test_a_second_process_converts_without_pint(tmp_path: Path) -> None:
    first = _run(tmp_path)
    expected = [9950 * 0.3048, (60 - 32) / 1.8, 13 * 0.45359237 / 0.003785411784]
    assert [float(v) for v in first[:3]] == pytest.approx(expected, rel=1e-12)
    assert first[3] == "True"
    stored = json.loads((tmp_path / "tdmon" / "conversions.json").read_text())
    assert stored["conversions"]["ft\x1fm"] == pytest.approx([0.3048, 0.0], rel=1e-12)
    second = _run(tmp_path)
    assert second == [*first[:3], "False"]


def test_a_foreign_or_corrupt_store_is_ignored(tmp_path: Path) -> None:
    store = tmp_path / "tdmon" / "conversions.json"
    store.parent.mkdir(parents=True)
    store.write_text(json.dumps({"key": "another pint", "conversions": {"ft\x1fm": [2.0, 0.0]}}))
    assert float(_run(tmp_path)[0]) == pytest.approx(9950 * 0.3048, rel=1e-12)
    store.write_text("{not json")
    assert float(_run(tmp_path)[0]) == pytest.approx(9950 * 0.3048, rel=1e-12)
