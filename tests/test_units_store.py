"""No conversion store (issue 32): conversions come from tdmon's own table of unit names, so a
process converting the usual units neither imports pint nor writes to the user's cache folder,
and what one process remembers is bounded. The store it replaces grew with every unit string,
was rewritten whole each time and read by every process at start (5000 distinct units: 115 s
of stalled daemon)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tdmon import units

ROOT = Path(__file__).resolve().parents[1]
PROBE = (
    "import sys\n"
    "from tdmon.units import parse_quantity\n"
    "print(repr(parse_quantity('9950 ft', 'm')), repr(parse_quantity('60 degF', 'degC')),\n"
    "      repr(parse_quantity('13 ppg', 'kg/m^3')), repr(parse_quantity('40 t', 'N')),\n"
    "      repr(parse_quantity(sys.argv[1], 'm')), 'pint' in sys.modules)\n"
)


def _run(cache: Path, length: str) -> list[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "XDG_CACHE_HOME": str(cache)}
    done = subprocess.run([sys.executable, "-c", PROBE, length], capture_output=True,
                          text=True, env=env, timeout=120, check=True)
    return done.stdout.split()


def _files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")) if folder.exists() \
        else []


def test_the_usual_units_need_neither_pint_nor_a_file(tmp_path: Path) -> None:
    out = _run(tmp_path, "12 1/4 in")
    expected = [9950 * 0.3048, (60 - 32) / 1.8, 13 * 0.45359237 / 0.003785411784,
                40e3 * 9.80665, 12.25 * 0.0254]
    assert [float(v) for v in out[:5]] == pytest.approx(expected, rel=1e-14)
    assert out[5] == "False"
    assert _files(tmp_path) == []


def test_a_name_outside_the_table_is_pints_and_still_no_store(tmp_path: Path) -> None:
    out = _run(tmp_path, "2 furlongs")
    # pint's furlong: 660 US survey feet of 1200/3937 m
    assert float(out[4]) == pytest.approx(2 * 660 * 1200 / 3937, rel=1e-12)
    assert out[5] == "True"
    # only pint's own cache of its definition files, a fixed set: no tdmon store
    assert [name for name in _files(tmp_path / "tdmon") if "/" not in name] == ["pint"]


def test_what_a_process_remembers_is_bounded() -> None:
    for memo in (units._conversion_or_reason, units.parse_unit, units._name):
        memo.cache_clear()
    for i in range(5000):
        assert units.conversion(f"kN*{i + 1}/{i + 1}", "N") == pytest.approx((1000.0, 0.0))
        with pytest.raises(units.UnitError):
            units.conversion(f"m**{i + 5}", "m")
    assert units._conversion_or_reason.cache_info().currsize == 512
    assert units.parse_unit.cache_info().currsize <= 512
    assert units._name.cache_info().currsize <= 256
