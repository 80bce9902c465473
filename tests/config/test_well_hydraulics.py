"""The well file's ``[hydraulics]`` table: the mud's rheology from Fann readings or PV and YP
with their units, the bit's nozzles, a float valve and the pressure window, into the model's
:class:`tdmon.model.hydraulics.WellHydraulics`; an unknown rheology models no viscous drag."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from tdmon.config.well import load_well_model
from tdmon.errors import ConfigError
from tdmon.model.fluid_force import HydraulicModel

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "config" / "wells" / "aadnoy-example-7-1.toml"
INCH = 0.0254


def _with(tmp_path: Path, table: str) -> Path:
    path = tmp_path / "well.toml"
    path.write_text(EXAMPLE.read_text() + "\n[hydraulics]\n" + table)
    return path


def test_fann_readings_give_pv_and_yp_by_hand(tmp_path: Path) -> None:
    well = load_well_model(_with(tmp_path, "fann_600 = 65\nfann_300 = 40\n"))
    mud = well.hydraulics.rheology
    assert mud is not None and mud.model == "bingham"
    assert mud.plastic_viscosity == pytest.approx(0.025)  # 65 - 40 = 25 cP
    assert mud.yield_point == pytest.approx(15 * 0.4788026)  # 2 x 40 - 65 = 15 lbf/100 ft^2
    # the same mud given as PV and YP with units
    given = load_well_model(_with(tmp_path, 'plastic_viscosity = "25 cP"\n'
                                            'yield_point = "15 lbf/100ft2"\n'))
    other = given.hydraulics.rheology
    assert other is not None
    assert other.plastic_viscosity == pytest.approx(mud.plastic_viscosity, rel=1e-12)
    assert other.yield_point == pytest.approx(mud.yield_point, rel=1e-7)  # 7 digits of 0.4788026


def test_power_law_from_the_file(tmp_path: Path) -> None:
    well = load_well_model(_with(tmp_path, 'rheology_model = "power_law"\nfann_600 = 65\n'
                                           "fann_300 = 40\n"))
    mud = well.hydraulics.rheology
    assert mud is not None and mud.model == "power_law"
    assert mud.flow_index == pytest.approx(3.32 * math.log10(65 / 40))  # 0.700
    assert mud.consistency == pytest.approx(0.4788026 * 1.067 * 40 / 511**mud.flow_index)


def test_nozzles_valve_and_window(tmp_path: Path) -> None:
    well = load_well_model(_with(tmp_path, 'fann_600 = 65\nfann_300 = 40\n'
                                           'nozzles = ["12 in/32", "12 in/32", "13 in/32"]\n'
                                           "float_valve = true\n"
                                           'pump_open_area = "6 in2"\n'
                                           'pore_density = "9.5 ppg"\n'
                                           'fracture_density = "1.6 sg"\n'))
    hydraulics = well.hydraulics
    assert hydraulics.nozzle_area == pytest.approx(math.pi / 4 * (2 * 12**2 + 13**2)
                                                   * (INCH / 32) ** 2)  # 0.3505 in^2
    assert hydraulics.nozzle_area == pytest.approx(0.3505 * INCH**2, rel=1e-3)
    assert hydraulics.float_valve
    assert hydraulics.pump_open_area == pytest.approx(6 * INCH**2)
    assert hydraulics.pore_density == pytest.approx(9.5 * 119.8264, rel=1e-5)
    assert hydraulics.fracture_density == pytest.approx(1600.0)
    # the trip-speed limits are then known for this well
    limits = HydraulicModel(well).trip_speed_limits(4000.0)
    assert 0.0 < limits.pulling_out < math.inf and 0.0 < limits.running_in < math.inf
    area = load_well_model(_with(tmp_path, 'nozzle_area = "0.3505 in2"\n')).hydraulics
    assert area.nozzle_area == pytest.approx(hydraulics.nozzle_area, rel=1e-3)


def test_no_table_means_no_rheology_and_no_drag(tmp_path: Path) -> None:
    well = load_well_model(EXAMPLE)
    assert well.hydraulics.rheology is None and well.hydraulics.nozzle_area is None
    forces = HydraulicModel(well).forces(4000.0, -0.8)
    assert forces.terms.axial is None and forces.surge_at_bit == 0.0


@pytest.mark.parametrize(("table", "message"), [
    ("fann_600 = 65\n", "hydraulics.fann_300: missing key (give both fann_600 and fann_300)"),
    ('yield_point = "15 lbf/100ft2"\n',
     "hydraulics.plastic_viscosity: missing key (give both plastic_viscosity and yield_point)"),
    ('fann_600 = 65\nfann_300 = 40\nplastic_viscosity = "25 cP"\nyield_point = "15 Pa"\n',
     "give the Fann readings or plastic_viscosity and yield_point, not both"),
    ('nozzles = ["12 in/32"]\nnozzle_area = "0.1 in2"\n',
     "give 'nozzles' or 'nozzle_area', not both"),
    ('pore_density = "1.5 sg"\nfracture_density = "1.4 sg"\n',
     "pore_density (1500 kg/m3) must be below fracture_density (1400 kg/m3)"),
    ("fann_600 = 90\nfann_300 = 40\n",
     "hydraulics: Fann readings 90 and 40 give a negative yield point: use the power law"),
    ('plastic_viscosity = 0.025\nyield_point = "15 Pa"\n', "plastic_viscosity"),
])
def test_bad_tables_are_named(tmp_path: Path, table: str, message: str) -> None:
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_well_model(_with(tmp_path, table))
