"""``tdmon model temperature`` on the thesis's Case 2 and 3 well files: JSON against the model
functions, Tables 11-12 at surface and TD, the text table, the PNG and the one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tdmon.cli import main
from tdmon.config.well import load_well, load_well_with_friction
from tdmon.model.friction import KAARSTAD_2009, THESIS_GLYDRIL_FIT
from tdmon.model.temperature import apak_temperature
from tdmon.model.well import hole_grid

ROOT = Path(__file__).resolve().parents[2]
WELLS = ROOT / "config" / "wells"
APAK = WELLS / "thesis-case2-apak.toml"
GEOTHERMAL = WELLS / "thesis-case2-geothermal.toml"
CASE_3 = WELLS / "thesis-case3.toml"
NO_TEMPERATURE = WELLS / "aadnoy-example-7-1.toml"

ARRAYS = ("md_m", "tvd_m", "pipe_C", "annulus_C", "formation_C", "friction")


def _reject_nan(name: str) -> None:
    raise AssertionError(f"JSON holds {name}")


def run_json(capsys: pytest.CaptureFixture[str], well: Path) -> dict:
    assert main(["model", "temperature", "--well", str(well), "--json"]) == 0
    return json.loads(capsys.readouterr().out, parse_constant=_reject_nan)


def fahrenheit(celsius: float) -> float:
    return celsius * 1.8 + 32.0


def test_json_arrays_on_the_element_midpoints(capsys):
    document = run_json(capsys, APAK)
    well = load_well(APAK).to_model(APAK)
    grid = hole_grid(well)
    for key in ARRAYS:
        assert len(document[key]) == grid.n_elements, key
    assert document["md_m"] == pytest.approx(grid.element_mid_md)
    assert document["model"] == "apak"
    assert document["bottom_md_m"] == pytest.approx(4223.5988)
    assert np.all(np.diff(document["tvd_m"]) > 0)


def test_json_friction_is_what_the_loads_command_uses(capsys):
    document = run_json(capsys, APAK)
    _, friction = load_well_with_friction(APAK)
    assert document["friction"] == pytest.approx(friction, rel=1e-12)
    # and it is the Glydril law at the annulus temperature of each element
    assert document["friction"] == pytest.approx(
        KAARSTAD_2009["glydril"](np.array(document["annulus_C"])), rel=1e-12)


def test_json_temperatures_equal_the_analytic_model(capsys):
    """The arrays are Kabir's solution in TVD with H = TVD of the bit (the thesis's way)."""
    document = run_json(capsys, APAK)
    config = load_well(APAK)
    assert config.temperature is not None
    circulation = config.temperature.circulation()
    assert circulation is not None
    tvd = np.array(document["tvd_m"])
    direct = apak_temperature(tvd, document["bottom"]["tvd_m"], config.temperature.geotherm(),
                              circulation)
    assert document["annulus_C"] == pytest.approx(direct.annulus, abs=1e-9)
    assert document["pipe_C"] == pytest.approx(direct.pipe, abs=1e-9)
    assert document["formation_C"] == pytest.approx(direct.formation, abs=1e-9)


def test_tables_11_and_12_at_surface_and_td(capsys):
    document = run_json(capsys, APAK)
    surface, bottom = document["surface"], document["bottom"]
    assert bottom["tvd_m"] == pytest.approx(3032.8, abs=0.5)  # 9950 ft
    # Table 11 / docs/reference-values.md §2: Ta(0) = 67.8 F, Ta(H) = 135.85-135.88 F (57.7 C)
    assert fahrenheit(surface["annulus_C"]) == pytest.approx(67.8, abs=0.1)
    assert fahrenheit(bottom["annulus_C"]) == pytest.approx(135.88, abs=0.1)
    assert bottom["annulus_C"] == pytest.approx(57.7, abs=0.05)
    # Table 12: 0.256 -> 0.305 (three decimals printed)
    assert surface["friction"] == pytest.approx(0.256, abs=0.0005)
    assert bottom["friction"] == pytest.approx(0.305, abs=0.0005)
    # the last element midpoint, 1.8 m above TD, is within 0.01 degC of it: Ta is flat there
    assert document["annulus_C"][-1] == pytest.approx(bottom["annulus_C"], abs=0.01)
    assert document["friction"][-1] == pytest.approx(0.305, abs=0.0005)


def test_kabir_coefficients_in_the_json(capsys):
    coefficients = run_json(capsys, APAK)["coefficients"]
    ft = 0.3048
    # Table 11 / docs/temperature.md: A 0.0011366 /ft, B 6.648e-5 /ft, theta1 3.10e-4 /ft
    assert coefficients["A_per_m"] * ft == pytest.approx(0.0011366, rel=0.002)
    assert coefficients["B_per_m"] * ft == pytest.approx(6.648e-5, rel=0.002)
    assert coefficients["theta1_per_m"] * ft == pytest.approx(3.10e-4, rel=0.005)
    assert coefficients["t_D"] == pytest.approx(14.2, abs=0.05)
    assert coefficients["T_D"] == pytest.approx(1.81, abs=0.005)


def test_geothermal_well_file(capsys):
    document = run_json(capsys, GEOTHERMAL)
    assert document["model"] == "geothermal"
    assert document["coefficients"] is None
    assert document["annulus_C"] == document["formation_C"] == document["pipe_C"]
    # docs/reference-values.md §2: 15.3 C at surface, 85.5 C at 3033 m; Table 12: 0.250 -> 0.341
    assert document["surface"]["annulus_C"] == pytest.approx(15.28, abs=0.01)
    assert document["bottom"]["annulus_C"] == pytest.approx(85.49, abs=0.01)
    assert document["surface"]["friction"] == pytest.approx(0.250, abs=0.0005)
    assert document["bottom"]["friction"] == pytest.approx(0.341, abs=0.0005)
    # the friction at the formation temperature is then the same as at the annulus
    assert document["friction_at_formation_temperature"] == pytest.approx(document["friction"])


def test_case_3_uses_eq_21(capsys):
    document = run_json(capsys, CASE_3)
    expected = THESIS_GLYDRIL_FIT(np.array(document["annulus_C"]))
    assert document["friction"] == pytest.approx(expected, rel=1e-12)
    assert document["bottom"]["friction"] == pytest.approx(0.25231 + 0.00085 * 57.71, abs=1e-4)


def test_text_table(capsys):
    assert main(["model", "temperature", "--well", str(APAK), "--step", "500"]) == 0
    out = capsys.readouterr().out
    assert "degC" in out and "friction" in out and "135.88 degF" in out
    rows = [line for line in out.splitlines() if line[:9].strip().replace(".", "").isdigit()]
    assert 8 <= len(rows) <= 12  # every ~500 m of 4224 m, plus the deepest element
    assert rows[-1].split()[0] == "4221.8"


def test_png_is_a_png(tmp_path, capsys):
    target = tmp_path / "temperature.png"
    assert main(["model", "temperature", "--well", str(APAK), "--png", str(target)]) == 0
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert target.stat().st_size > 10_000
    assert str(target) in capsys.readouterr().out


def test_constant_friction_with_a_temperature_table(tmp_path, capsys):
    text = APAK.read_text().replace('friction = "kaarstad-glydril"', "friction = 0.2")
    well = tmp_path / "constant.toml"
    well.write_text(text)
    document = run_json(capsys, well)
    assert set(document["friction"]) == {0.2}
    assert document["bottom"]["friction"] == 0.2


def test_section_without_friction_reports_temperatures_only(tmp_path, capsys):
    lines = [line for line in APAK.read_text().splitlines()
             if not line.startswith('friction = "kaarstad-glydril"')]
    well = tmp_path / "frictionless.toml"
    well.write_text("\n".join(lines) + "\n")
    document = run_json(capsys, well)
    assert document["friction"] is None and document["bottom"]["friction"] is None
    assert len(document["annulus_C"]) == len(document["md_m"])
    assert main(["model", "temperature", "--well", str(well)]) == 0
    header = next(line for line in capsys.readouterr().out.splitlines() if "MD m" in line)
    assert "annulus degC" in header and "friction" not in header


def _one_line_error(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(list(argv)) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("tdmon: error: ")
    return lines[0]


def test_well_without_temperature_table(capsys):
    line = _one_line_error(capsys, "model", "temperature", "--well", str(NO_TEMPERATURE))
    assert "aadnoy-example-7-1.toml: temperature: missing table" in line


def test_missing_well_file(tmp_path, capsys):
    line = _one_line_error(capsys, "model", "temperature", "--well", str(tmp_path / "no.toml"))
    assert "no such file" in line


def test_bad_temperature_input(tmp_path, capsys):
    well = tmp_path / "bad.toml"
    well.write_text(APAK.read_text().replace('flow_rate = "12600 gal/h"', 'flow_rate = "-1 gal/h"'))
    line = _one_line_error(capsys, "model", "temperature", "--well", str(well))
    assert "temperature.flow_rate" in line and "positive" in line


def test_bad_step(capsys):
    line = _one_line_error(capsys, "model", "temperature", "--well", str(APAK), "--step", "0")
    assert "--step" in line


def test_help_explains(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["model", "temperature", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert "Figure 9" in out and "annulus" in out and "--json" in out
