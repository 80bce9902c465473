"""Cost of temperature-dependent local friction in a broomstick, against constant friction.

Run: ``.venv/bin/python benchmarks/bench_temperature_friction.py [--repeat 7] [--json out.json]``
(project virtualenv; no peers).

Both sides compute the same broomstick (pick-up, slack-off, rotating hook load and rotating
torque at every bit depth, soft-string method) and are timed side by side in one run, best of
``--repeat``, alternating. The ratio temperature / constant is the figure of merit (target:
at most 2).

- constant: ``broomstick`` with one friction factor for every element;
- temperature: the mud-temperature profile at every element midpoint (``temperature_profile``,
  Kabir/Apak analytic in TVD, Table 10 inputs with the Table 11 U values), each element's
  friction from the Glydril law at its annulus temperature (``local_friction``), then
  ``broomstick`` with that per-element friction (one 2-D friction case). The profile and the
  friction evaluation are inside the timed part.

Each is timed two ways:

- "from the well": everything the command line does per run, i.e. the hole grid and the
  element geometry are built inside the timing (the temperature side builds the grid for the
  midpoints and the broomstick builds its own, as ``tdmon model broomstick`` does);
- "prepared model": a ``WellModel`` built once outside the timing (as the daemon keeps it), so
  only the temperature profile, the friction and the compiled sweep are timed: the strictest
  ratio, since the constant side then does the least work.

The ``numerical`` temperature model (``solve_bvp`` along MD) is timed too, for information.

Cases: the thesis's Case 2 well file (Example 7.1, 10 m elements, bit depths every 30 m as the
broomstick command's default) and the 6000 m well of docs/reference-values.md §6 (vertical 1000 m,
build 3 deg/30 m to 80 deg, tangent; 1 m elements; 20 bit depths) with the same thermal inputs.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tdmon.config.well import load_well
from tdmon.model.broomstick import broomstick, broomstick_from_model
from tdmon.model.friction import KAARSTAD_2009, local_friction
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.survey import minimum_curvature
from tdmon.model.temperature import CirculationParameters, Geotherm, temperature_profile
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Fluid, HoleSection, Well, hole_grid

ROOT = Path(__file__).resolve().parents[1]
CASE_2 = ROOT / "config" / "wells" / "thesis-case2-apak.toml"
CONSTANT_MU = 0.25
GLYDRIL = KAARSTAD_2009["glydril"]


def best_of(function: Callable[[], Any], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def case_2() -> tuple[Well, Geotherm, CirculationParameters, np.ndarray]:
    config = load_well(CASE_2)
    well = config.to_model(CASE_2)
    assert config.temperature is not None
    circulation = config.temperature.circulation()
    assert circulation is not None
    deepest = min(well.string.length, well.hole_bottom)
    depths = np.append(np.arange(30.0, deepest, 30.0), deepest)
    return well, config.temperature.geotherm(), circulation, depths


def long_well() -> tuple[Well, Geotherm, CirculationParameters, np.ndarray]:
    """docs/reference-values.md §6's 6000 m well with 1 m elements and Case 2's thermal inputs."""
    _, geotherm, circulation, _ = case_2()
    md = np.union1d(np.arange(0.0, 6000.5, 1.0), [1000.0, 1800.0])
    inclination = np.clip((md - 1000.0) * 3.0 / 30.0, 0.0, 80.0)
    survey = minimum_curvature(md, inclination, np.zeros_like(md))
    inch = 0.0254
    pipe = StringComponent(name="drill pipe", length=6000.0, outer_diameter=5.0 * inch,
                           inner_diameter=4.276 * inch,
                           weight_in_air=math.pi / 4 * ((5.0 * inch) ** 2 - (4.276 * inch) ** 2)
                           * 7850.0 * 9.80665)
    well = Well(survey=survey, string=DrillString((pipe,)),
                sections=(HoleSection(top=0.0, bottom=6000.0, diameter=8.5 * inch, kind="open",
                                      friction=CONSTANT_MU),),
                fluid=Fluid(density=1200.0), element_length=1.0, name="docs/reference-values.md §6")
    return well, geotherm, circulation, np.linspace(300.0, 6000.0, 20)


def measure(name: str, well: Well, geotherm: Geotherm, circulation: CirculationParameters,
            depths: np.ndarray, repeat: int) -> dict[str, Any]:
    prepared = WellModel(well)
    midpoints = prepared.grid.element_mid_md
    bottom = well.hole_bottom

    def local_mu(model: str, grid_md: np.ndarray, grid_tvd: np.ndarray, mid: np.ndarray,
                 section: np.ndarray) -> np.ndarray:
        profile = temperature_profile(model, mid, grid_md, grid_tvd, geotherm, circulation,
                                      total_md=bottom)
        return local_friction([GLYDRIL], section, profile.annulus)

    def constant_from_well() -> Any:
        return broomstick(well, depths, [CONSTANT_MU])

    def temperature_from_well(model: str = "apak") -> Any:
        grid = hole_grid(well)
        mu = local_mu(model, grid.md, grid.tvd, grid.element_mid_md, grid.element_section)
        return broomstick(well, depths, mu[np.newaxis, :])

    grid = prepared.grid

    def constant_prepared() -> Any:
        return broomstick_from_model(prepared, depths, [CONSTANT_MU])

    def temperature_prepared(model: str = "apak") -> Any:
        mu = local_mu(model, grid.md, grid.tvd, midpoints, grid.element_section)
        return broomstick_from_model(prepared, depths, mu[np.newaxis, :])

    def profile_and_friction_only() -> Any:
        return local_mu("apak", grid.md, grid.tvd, midpoints, grid.element_section)

    def numerical_prepared() -> Any:
        return temperature_prepared("numerical")

    # warm the compiled kernels and check that both sides compute the same kind of thing
    constant_from_well()
    check = temperature_prepared()
    assert check.hookload["pick_up"].shape == (1, depths.size)

    timings: dict[str, float] = {}
    # alternate the two sides so that the machine's noise hits both alike
    for _ in range(repeat):
        for label, function in (("constant_from_well", constant_from_well),
                                ("temperature_from_well", temperature_from_well),
                                ("constant_prepared", constant_prepared),
                                ("temperature_prepared", temperature_prepared),
                                ("profile_and_friction", profile_and_friction_only)):
            elapsed = best_of(function, 1)
            timings[label] = min(timings.get(label, math.inf), elapsed)
    timings["numerical_prepared"] = best_of(numerical_prepared, max(2, repeat // 3))
    return {
        "case": name,
        "elements": prepared.n_elements,
        "bit_depths": int(depths.size),
        "seconds": timings,
        "ratio_from_well": timings["temperature_from_well"] / timings["constant_from_well"],
        "ratio_prepared": timings["temperature_prepared"] / timings["constant_prepared"],
        "ratio_numerical_prepared": timings["numerical_prepared"] / timings["constant_prepared"],
    }


def report(results: list[dict[str, Any]]) -> None:
    print(f"Python {platform.python_version()}, numpy {np.__version__}; best of the runs; "
          "times in ms")
    print()
    print("| case | elements | bit depths | constant, from the well | temperature, from the "
          "well | ratio | constant, prepared model | temperature, prepared model | ratio | "
          "profile + friction alone | numerical model, prepared | ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for result in results:
        s = {key: value * 1e3 for key, value in result["seconds"].items()}
        print(f"| {result['case']} | {result['elements']} | {result['bit_depths']} | "
              f"{s['constant_from_well']:.2f} | {s['temperature_from_well']:.2f} | "
              f"{result['ratio_from_well']:.2f} | {s['constant_prepared']:.2f} | "
              f"{s['temperature_prepared']:.2f} | {result['ratio_prepared']:.2f} | "
              f"{s['profile_and_friction']:.3f} | {s['numerical_prepared']:.1f} | "
              f"{result['ratio_numerical_prepared']:.1f} |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7, help="runs per timing (best kept)")
    parser.add_argument("--json", type=Path, help="also write the figures as JSON")
    args = parser.parse_args(argv)
    results = [measure("thesis Case 2 (Example 7.1, 10 m)", *case_2(), args.repeat),
               measure("docs/reference-values.md §6 well (6000 m, 1 m)", *long_well(), args.repeat)]
    report(results)
    worst = max(max(r["ratio_from_well"], r["ratio_prepared"]) for r in results)
    print()
    print(f"largest ratio temperature / constant (analytic model): {worst:.2f} "
          f"({'within' if worst <= 2.0 else 'ABOVE'} the 2x target)")
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2))
    return 0 if worst <= 2.0 else 1


if __name__ == "__main__":
    sys.exit(main())
