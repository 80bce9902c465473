"""``tdmon model temperature``: mud temperature and local friction factor along the hole.

The profiles are those the loads and broomstick commands use: the well file's ``[temperature]``
model, circulating with the bit at the bottom of the hole, evaluated at the midpoint of every
hole-grid element, and each element's friction from its section (a number or a law mu(T) at the
annulus temperature), through :meth:`tdmon.config.well.WellConfig.element_friction`.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tdmon.cli.arguments import add_units_option, display_units, quantity_arg
from tdmon.errors import ConfigError

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    Array = NDArray[np.float64]

    from tdmon.config.well import WellConfig
    from tdmon.display import UnitSystem
    from tdmon.model.temperature import WellboreTemperature
    from tdmon.model.well import Well


def register_model_commands(commands: argparse._SubParsersAction[Any]) -> None:
    """Add ``temperature`` to the ``tdmon model`` sub-commands."""
    parser = commands.add_parser(
        "temperature",
        help="mud temperature (pipe, annulus, formation) and local friction factor along the hole",
        description=(
            "Mud temperature in the drill pipe and the annulus and the undisturbed formation "
            "temperature against depth (the thesis's Figure 9), and the friction factor of each "
            "element (Figure 11): a section's number, or its law mu(T) at the annulus "
            "temperature. The well file's [temperature] model is evaluated with the mud "
            "circulating at the bottom of the hole, at the midpoint of every hole-grid element, "
            "exactly as 'tdmon model loads' and 'broomstick' use it. Temperatures in degC "
            "(degF with --units field)."
        ),
    )
    parser.add_argument("--well", type=Path, required=True, metavar="W.toml",
                        help="well file with a [temperature] table")
    parser.add_argument("--step", type=quantity_arg("m", "500 ft"), default=250.0,
                        metavar="LENGTH", help="MD spacing of the rows of the text table [m], "
                        "or with a unit, e.g. '500 ft' (default 250 m)")
    add_units_option(parser, "the table and the figure")
    out = parser.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true",
                     help="print JSON: arrays md_m, tvd_m, pipe_C, annulus_C, formation_C, "
                     "friction (one value per element midpoint), the model and its coefficients")
    out.add_argument("--png", type=Path, metavar="FILE",
                     help="draw temperature and friction factor against TVD")
    parser.set_defaults(func=_run_temperature)


@dataclass(frozen=True)
class _Profiles:
    """What the command reports, at the element midpoints and at surface and bottom."""

    well: Well
    profile: WellboreTemperature
    friction: Array | None
    friction_at_formation: Array | None
    ends: WellboreTemperature
    ends_friction: Array | None


def _profiles(path: Path) -> _Profiles:
    import numpy as np

    from tdmon.config.well import load_well
    from tdmon.model.well import hole_grid

    config = load_well(path)
    if config.temperature is None:
        raise ConfigError(str(path), "temperature",
                          "missing table: 'tdmon model temperature' needs a [temperature] table "
                          "(see docs/temperature.md)")
    well = config.to_model(path)
    grid = hole_grid(well)
    profile = config.annulus_temperature(well, grid.element_mid_md, path)
    ends = config.annulus_temperature(well, np.array([well.hole_top, well.hole_bottom]), path)
    friction = friction_formation = ends_friction = None
    if all(section.friction is not None for section in config.hole):
        friction = config.element_friction(well, path)
        sections = np.array([0, len(config.hole) - 1])
        friction_formation = _laws(config, path, grid.element_section, profile.formation)
        ends_friction = _laws(config, path, sections, ends.annulus)
    return _Profiles(well, profile, friction, friction_formation, ends, ends_friction)


def _laws(config: WellConfig, path: Path, sections: NDArray[np.int64], temperature: Array) -> Array:
    """Each section's friction (number or law) at the given temperatures [degC]."""
    from tdmon.errors import ModelError
    from tdmon.model.friction import local_friction

    laws = [section.friction.friction_model() for section in config.hole if section.friction]
    try:
        return local_friction(laws, sections, temperature)
    except ModelError as exc:
        raise ConfigError(str(path), "hole", str(exc)) from exc


def _run_temperature(args: argparse.Namespace) -> int:
    if not args.step > 0:
        raise ConfigError(str(args.well), "--step", "must be positive")
    result = _profiles(args.well)
    units = display_units(args)
    if args.json:
        json.dump(_document(result), sys.stdout, allow_nan=False)
        print()
    elif args.png is not None:
        _plot(result, args.png, units)
        print(f"wrote {args.png}")
    else:
        _print(result, args.well, args.step, units)
    return 0


def _document(result: _Profiles) -> dict[str, Any]:
    document: dict[str, Any] = {"well": result.well.name, "points": "hole-grid element midpoints",
                                "bottom_md_m": result.well.hole_bottom}
    document.update(result.profile.to_dict())
    document["friction"] = None if result.friction is None else result.friction.tolist()
    document["friction_at_formation_temperature"] = (
        None if result.friction_at_formation is None else result.friction_at_formation.tolist())
    ends = result.ends
    for index, name in enumerate(("surface", "bottom")):
        document[name] = {
            "md_m": float(ends.md[index]), "tvd_m": float(ends.tvd[index]),
            "pipe_C": float(ends.pipe[index]), "annulus_C": float(ends.annulus[index]),
            "formation_C": float(ends.formation[index]),
            "friction": None if result.ends_friction is None
            else float(result.ends_friction[index]),
        }
    return document


def _print(result: _Profiles, path: Path, step: float, units: UnitSystem) -> None:
    import numpy as np

    profile, ends = result.profile, result.ends
    depth, degrees, other = units.label("depth"), units.label("temperature"), units.other
    state = ("static mud at the formation temperature" if profile.model == "geothermal" else
             f"mud circulating with the bit at {units.depth(result.well.hole_bottom):.1f} "
             f"{depth} MD")
    print(f"{result.well.name or path}: temperature model '{profile.model}', {state}")
    coefficients = profile.coefficients
    if coefficients is not None:
        heat = coefficients.heat_transfer
        print(f"  A {coefficients.A:.4g} 1/m, B {coefficients.B:.4g} 1/m, theta1 "
              f"{coefficients.theta1:.4g} 1/m, theta2 {coefficients.theta2:.4g} 1/m, "
              f"U_p {heat.pipe:.1f} W/(m2 K), U_a {heat.annulus:.1f} W/(m2 K), "
              f"t_D {heat.dimensionless_time:.3g}, T_D {heat.dimensionless_temperature:.3g}")
    for index, name in enumerate(("surface", "bottom")):
        mu = "" if result.ends_friction is None else f", friction {result.ends_friction[index]:.3f}"
        annulus = float(ends.annulus[index])
        print(f"  {name:<8} annulus {units.temperature(annulus):.2f} {degrees} "
              f"({other.temperature(annulus):.2f} {other.label('temperature')}), formation "
              f"{units.temperature(float(ends.formation[index])):.2f} {degrees}{mu}")
    header = (f"{'MD ' + depth:>9}{'TVD ' + depth:>9}{'pipe ' + degrees:>11}"
              f"{'annulus ' + degrees:>14}{'formation ' + degrees:>16}")
    if result.friction is not None:
        header += f"{'friction':>10}"
    print(header)
    md = profile.md
    wanted = np.arange(0.0, md[-1] + step, step)
    rows = np.unique(np.append(np.searchsorted(md, wanted).clip(0, md.size - 1), md.size - 1))
    for i in rows:
        line = (f"{units.depth(md[i]):>9.1f}{units.depth(profile.tvd[i]):>9.1f}"
                f"{units.temperature(profile.pipe[i]):>11.2f}"
                f"{units.temperature(profile.annulus[i]):>14.2f}"
                f"{units.temperature(profile.formation[i]):>16.2f}")
        if result.friction is not None:
            line += f"{result.friction[i]:>10.4f}"
        print(line)
    print("(rows: hole-grid element midpoints about every "
          f"{units.depth(step):g} {depth}; --json gives all {md.size})")


def _plot(result: _Profiles, path: Path, units: UnitSystem) -> None:
    """Temperature (Figure 9) and friction factor (Figure 11) against TVD, depth down."""
    from tdmon.cli.plots import _figure, save

    profile = result.profile
    degrees = units.label("temperature")
    panels = 2 if result.friction is not None else 1
    figure = _figure(panels)
    axes = figure.subplots(1, panels, sharey=True, squeeze=False)[0]
    tvd = units.depth(profile.tvd)
    axes[0].plot(units.temperature(profile.pipe), tvd, color="C0", label="mud in drill pipe")
    axes[0].plot(units.temperature(profile.annulus), tvd, color="C3", label="mud in annulus")
    axes[0].plot(units.temperature(profile.formation), tvd, color="black", linestyle="--",
                 label="formation (geotherm)")
    axes[0].set_xlabel(f"temperature [{degrees}]")
    axes[0].set_ylabel(f"true vertical depth [{units.label('depth')}]")
    axes[0].invert_yaxis()
    if result.friction is not None and result.friction_at_formation is not None:
        axes[1].plot(result.friction, tvd, color="C3", label="at annulus temperature")
        axes[1].plot(result.friction_at_formation, tvd, color="black", linestyle="--",
                     label="at formation temperature")
        axes[1].set_xlabel("local friction factor [-]")
    for axis in axes:
        axis.grid(alpha=0.3)
        axis.legend(fontsize="small")
    figure.suptitle(f"{result.well.name or 'well'}: temperature model '{profile.model}'")
    save(figure, path)
