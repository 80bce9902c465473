"""``tdmon model ...``: modelled loads at one bit depth, broomsticks, temperature profiles."""

from __future__ import annotations

import argparse
import csv
import importlib
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tdmon.cli.arguments import add_units_option, display_units, output_file, quantity_arg
from tdmon.errors import ConfigError, TdmonError

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from tdmon.display import UnitSystem
    from tdmon.model.broomstick import Broomstick
    from tdmon.model.well import Well

METHODS = ("soft-string", "aadnoy")


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    model = subparsers.add_parser(
        "model",
        help="modelled hook load and torque: loads, broomsticks, temperature",
        description="Evaluate the torque-and-drag model of a well file.",
    )
    commands = model.add_subparsers(dest="model_command", metavar="COMMAND", required=True)

    loads = commands.add_parser(
        "loads",
        help="hook load and surface torque at one bit depth",
        description=(
            "Hook load (static, rotating off bottom, pick-up, slack-off) and surface torque at one "
            "bit depth. Hook load includes the well file's block weight. Output in kN and kN m "
            "(klbf and kft lbf with --units field), or SI with --json."
        ),
    )
    _add_common(loads)
    loads.add_argument("--mu", type=_friction, help="friction factor for every section "
                       "(default: the well file's friction per section)")
    loads.add_argument("--bit-depth", type=quantity_arg("m", "6500 ft"), metavar="DEPTH",
                       help="bit depth [m MD], or with a unit, e.g. '6500 ft' (default: the "
                       "string's length)")
    loads.add_argument("--wob", type=quantity_arg("N", "20 klbf"), default=0.0, metavar="FORCE",
                       help="weight on bit [N], or with a unit, e.g. '20 klbf' or '90 kN', for "
                       "the on-bottom case (default 0: off bottom)")
    loads.add_argument("--bit-torque", type=quantity_arg("N*m", "5 kft*lbf"), default=0.0,
                       metavar="TORQUE", help="torque at the bit [N m], or with a unit, e.g. "
                       "'5 kft*lbf' or '7 kN*m', for the on-bottom case")
    loads.add_argument("--json", action="store_true", help="print JSON (SI units in the keys)")
    add_units_option(loads, "the table")
    loads.set_defaults(func=_run_loads)

    broom = commands.add_parser(
        "broomstick",
        help="hook load and torque against bit depth for several friction factors",
        description=(
            "Pick-up, slack-off and rotating hook load and off-bottom torque against bit depth for "
            "a family of friction factors (the thesis's Figure 6), with the tensile and make-up "
            "torque limits."
        ),
    )
    _add_common(broom)
    broom.add_argument("--mu", type=_friction_list,
                       help="comma-separated friction factors, e.g. 0.1,0.2,0.3 (default: the "
                       "well file's friction, per section or mu(T), as one case)")
    broom.add_argument("--step", type=quantity_arg("m", "100 ft"), default=30.0,
                       metavar="LENGTH", help="bit-depth step [m], or with a unit, e.g. "
                       "'100 ft' (default 30 m)")
    broom.add_argument("--start", type=quantity_arg("m", "2000 m"), default=None,
                       metavar="LENGTH", help="shallowest bit depth [m], or with a unit, e.g. "
                       "'6500 ft' (default: one step)")
    add_units_option(broom, "the table and the figure")
    out = broom.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="print JSON (SI units in the keys)")
    out.add_argument("--csv", type=Path, metavar="FILE", help="write a CSV table")
    out.add_argument("--png", type=Path, metavar="FILE", help="draw hook load and torque "
                     "against depth")
    broom.set_defaults(func=_run_broomstick)

    warmup = commands.add_parser(
        "warmup",
        help="compile the model's kernels into numba's cache (the set-up scripts run it)",
        description=(
            "Compile the torque-and-drag model's kernels with numba and store them in numba's "
            "on-disk cache (a minute or two; seconds when they are there already), so that no "
            "later command or daemon compiles them. The cache is the package's "
            "tdmon/model/__pycache__, or numba's user-wide cache folder when that is not "
            "writable (NUMBA_CACHE_DIR overrides both): run it as the user that runs tdmon. "
            "scripts/demo.sh and scripts/test.sh run it after installing; run it again after "
            "changing tdmon/model/_kernels.py or upgrading numba."
        ),
    )
    warmup.set_defaults(func=_run_warmup)

    try:  # the temperature commands land with the temperature models' command line
        temperature = importlib.import_module("tdmon.cli.temperature")
    except ModuleNotFoundError:
        return
    temperature.register_model_commands(commands)


def _run_warmup(args: argparse.Namespace) -> int:
    from tdmon.model.warmup import warm_up

    done = warm_up()
    print(f"model kernels: {done.compiled} compiled by numba and stored, {done.loaded} already "
          f"in its cache, in {done.seconds:.1f} s (numba cache: {done.cache_folder})")
    return 0


def _add_common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--well", type=Path, required=True, metavar="W.toml",
                        help="well file (survey, hole sections, string, fluid)")
    parser.add_argument("--method", choices=METHODS, default="soft-string",
                        help="'soft-string': 3D Johancsik soft string, consistent signs "
                        "(default); 'aadnoy': the thesis's formulas as published")


def _friction(text: str) -> float:
    from tdmon.config.common import check_friction  # the rule of the well and daemon files

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    try:
        return check_friction(value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _friction_list(text: str) -> list[float]:
    values = [_friction(part) for part in text.split(",") if part.strip()]
    if not values:
        raise argparse.ArgumentTypeError("give at least one friction factor")
    return values


def _load(path: Path) -> tuple[Well, NDArray[np.float64]]:
    """The well and its per-element friction from the file (a number or mu(T) per section)."""
    from tdmon.config.well import load_well_with_friction

    return load_well_with_friction(path)


def _check_bit_depth(path: Path, well: Well, bit_depth: float) -> None:
    if not bit_depth > 0:
        raise ConfigError(str(path), "--bit-depth", f"{bit_depth:g} m must be positive")
    if bit_depth > well.string.length + 1e-6:
        raise ConfigError(
            str(path), "string",
            f"the string is {well.string.length:.1f} m long, shorter than the bit depth "
            f"{bit_depth:.1f} m",
        )
    hole_bottom = well.sections[-1].bottom
    if bit_depth > hole_bottom + 1e-6:
        raise ConfigError(
            str(path), "hole",
            f"bit depth {bit_depth:.1f} m is below the bottom of the hole ({hole_bottom:.1f} m)",
        )


def _run_loads(args: argparse.Namespace) -> int:
    from tdmon.model.kernels import ENVIRONMENT
    from tdmon.model.torque_drag import torque_drag

    well, file_friction = _load(args.well)
    bit_depth = args.bit_depth if args.bit_depth is not None else well.string.length
    _check_bit_depth(args.well, well, bit_depth)
    mu = args.mu if args.mu is not None else file_friction
    # one march: as plain Python it is done long before numba would have loaded (unless
    # TDMON_KERNELS chooses; the numbers are the same)
    engine = None if os.environ.get(ENVIRONMENT) else "python"
    loads = torque_drag(well, bit_depth, mu, method=args.method, wob=args.wob,
                        bit_torque=args.bit_torque, engine=engine)
    if args.json:
        document = {
            "well": well.name,
            "bit_depth_m": loads.bit_depth,
            "method": loads.method,
            "mu": args.mu,
            "block_weight_N": well.block_weight,
            "hookload_N": dict(loads.hookload),
            "torque_Nm": dict(loads.surface_torque),
        }
        json.dump(document, sys.stdout, indent=2)
        print()
        return 0
    units = display_units(args)
    force, torque, depth = units.label("force"), units.label("torque"), units.label("depth")
    friction = f"mu {args.mu:g}" if args.mu is not None else "friction from the well file"
    print(f"{well.name or args.well}: bit at {units.depth(loads.bit_depth):.1f} {depth} MD, "
          f"method {loads.method}, {friction}, block weight "
          f"{units.force(well.block_weight):.1f} {force}")
    on_bottom = args.wob != 0.0 or args.bit_torque != 0.0
    shown = ["static", "rotating", "pick_up", "slack_off"] + (["on_bottom"] if on_bottom else [])
    print(f"  {'hook load':<24}{force:>10}")
    for operation in shown:
        print(f"  {operation.replace('_', ' '):<24}{units.force(loads.hookload[operation]):>10.1f}")
    print(f"  {'surface torque':<24}{torque:>10}")
    for operation in ("rotating", "on_bottom") if on_bottom else ("rotating",):
        value = loads.surface_torque[operation]
        print(f"  {operation.replace('_', ' '):<24}{units.torque(value):>10.2f}")
    return 0


def _run_broomstick(args: argparse.Namespace) -> int:
    import numpy as np

    from tdmon.model.broomstick import broomstick

    well, file_friction = _load(args.well)
    mus = args.mu if args.mu is not None else file_friction[np.newaxis, :]
    if not args.step > 0:
        raise ConfigError(str(args.well), "--step", "must be positive")
    units = display_units(args)
    deepest = min(well.string.length, well.sections[-1].bottom)
    start = args.step if args.start is None else args.start
    if not 0.0 < start <= deepest:
        raise ConfigError(str(args.well), "--start",
                          f"{start:g} m is not between 0 and the deepest bit depth "
                          f"({deepest:g} m)")
    bit_depths = np.arange(start, deepest + 1e-9, args.step)
    if bit_depths.size == 0 or bit_depths[-1] < deepest - 1e-6:
        bit_depths = np.append(bit_depths, deepest)
    result = broomstick(well, bit_depths, mus, method=args.method)
    if args.json:
        json.dump(_broomstick_document(well, result, args.method), sys.stdout)
        print()
    elif args.csv is not None:
        _write_csv(args.csv, result)
        print(f"wrote {args.csv} ({result.bit_depth.size} bit depths x {result.mu.size} friction "
              "cases)")
    elif args.png is not None:
        from tdmon.cli.plots import plot_broomstick

        plot_broomstick(well, result, args.png, args.method, units)
        print(f"wrote {args.png}")
    else:
        _print_broomstick(result, units)
    return 0


def _broomstick_document(well: Well, result: Broomstick, method: str) -> dict[str, Any]:
    import numpy as np

    return {
        "well": well.name,
        "method": method,
        "mu": np.asarray(result.mu).tolist(),
        "bit_depth_m": result.bit_depth.tolist(),
        "block_weight_N": well.block_weight,
        "hookload_N": {op: values.tolist() for op, values in result.hookload.items()},
        "torque_Nm": {op: values.tolist() for op, values in result.surface_torque.items()},
    }


def _columns(result: Broomstick) -> tuple[list[str], list[np.ndarray[Any, Any]]]:
    import numpy as np

    names = ["bit_depth_m"]
    columns = [result.bit_depth]
    for key, table, unit in (
        [(op, values, "hookload_N") for op, values in result.hookload.items()]
        + [(op, values, "torque_Nm") for op, values in result.surface_torque.items()]
    ):
        rows = np.atleast_2d(table)
        for index, mu in enumerate(np.asarray(result.mu)):
            names.append(f"{key}_{unit}_mu{mu:g}")
            columns.append(rows[min(index, rows.shape[0] - 1)])
    return names, columns


def _write_csv(path: Path, result: Broomstick) -> None:
    import numpy as np

    names, columns = _columns(result)
    try:
        with output_file(path, "--csv").open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(names)
            writer.writerows(np.column_stack(columns).tolist())
    except OSError as exc:
        raise TdmonError(f"cannot write {path}: {exc.strerror}") from exc


def _print_broomstick(result: Broomstick, units: UnitSystem) -> None:
    import numpy as np

    mus = np.asarray(result.mu)
    header = f"{'bit depth ' + units.label('depth'):>12}" + "".join(
        f"{'PU ' + label:>10}{'SO ' + label:>10}{'T ' + label:>9}"
        for label in (format(mu, ".3g") for mu in mus)
    )
    print(f"hook load in {units.label('force')} (PU pick-up, SO slack-off), off-bottom torque "
          f"T in {units.label('torque')}")
    print(header + f"{'ROT':>10}")
    rotating = units.force(np.atleast_2d(result.hookload["rotating"])[0])
    pick_up = units.force(np.atleast_2d(result.hookload["pick_up"]))
    slack_off = units.force(np.atleast_2d(result.hookload["slack_off"]))
    torque = units.torque(np.atleast_2d(result.surface_torque["rotating"]))
    for j, depth in enumerate(units.depth(result.bit_depth)):
        row = f"{depth:>12.1f}"
        for i in range(mus.size):
            row += f"{pick_up[i, j]:>10.1f}{slack_off[i, j]:>10.1f}{torque[i, j]:>9.2f}"
        print(row + f"{rotating[j]:>10.1f}")
