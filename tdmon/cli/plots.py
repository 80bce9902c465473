"""Figures drawn by the command line (matplotlib, off-screen)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tdmon.errors import TdmonError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from tdmon.display import UnitSystem
    from tdmon.model.broomstick import Broomstick
    from tdmon.model.well import Well


def _figure(columns: int) -> Figure:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    return Figure(figsize=(5.0 * columns, 6.5), layout="constrained")


def save(figure: Figure, path: Path) -> None:
    """Write a figure (PNG), creating missing parent folders."""
    from tdmon.cli.arguments import output_file

    try:
        figure.savefig(output_file(path), dpi=120)
    except OSError as exc:
        raise TdmonError(f"cannot write {path}: {exc.strerror}") from exc


def plot_broomstick(well: Well, result: Broomstick, path: Path, method: str,
                    units: UnitSystem | None = None) -> None:
    """Hook load and off-bottom torque against bit depth (depth down), as the thesis's Figure 6,
    with the tensile limit of the joint at surface and the lowest make-up torque in the hole.
    Axes in ``units`` (default SI: kN, kN m, m)."""
    from tdmon.display import unit_system

    units = units or unit_system("si")
    figure = _figure(2)
    hook_axes, torque_axes = figure.subplots(1, 2, sharey=True)
    depth = units.depth(result.bit_depth)
    colours = [f"C{index}" for index in range(len(result.mu))]
    for index, mu in enumerate(np.asarray(result.mu)):
        colour = colours[index]
        hook_axes.plot(units.force(result.hookload["pick_up"][index]), depth, color=colour,
                       label=f"pick-up, mu {mu:g}")
        hook_axes.plot(units.force(result.hookload["slack_off"][index]), depth, color=colour,
                       linestyle="--", label=f"slack-off, mu {mu:g}")
        torque_axes.plot(units.torque(result.surface_torque["rotating"][index]), depth,
                         color=colour, label=f"mu {mu:g}")
    rotating = np.atleast_2d(result.hookload["rotating"])[0]
    hook_axes.plot(units.force(rotating), depth, color="black", label="rotating off bottom")

    hook_top = _axis_end(hook_axes)
    torque_top = _axis_end(torque_axes)
    _limit(hook_axes, units.force(result.hookload_limit), depth, hook_top,
           f"tensile limit + block (SF {well.limits.safety_factor:g})", units.label("force"))
    _limit(torque_axes, units.torque(result.makeup_torque_limit), depth, torque_top,
           "make-up torque", units.label("torque"))

    hook_axes.set_xlabel(f"hook load [{units.label('force')}]")
    hook_axes.set_ylabel(f"bit depth [{units.label('depth')} MD]")
    hook_axes.invert_yaxis()
    hook_axes.grid(alpha=0.3)
    torque_axes.set_xlabel(f"off-bottom rotating torque [{units.label('torque')}]")
    torque_axes.grid(alpha=0.3)
    for axes in (hook_axes, torque_axes):  # below the axes, where they cover no curve
        axes.legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.09),
                    ncol=2)
    figure.suptitle(f"{well.name or 'well'}: broomstick ({method}, block weight "
                    f"{units.force(well.block_weight):.0f} {units.label('force')})")
    save(figure, path)


def _axis_end(axes: Any) -> float:
    """The right end of an axis that shows the load curves drawn so far, with a margin."""
    ends = [np.nanmax(np.asarray(line.get_xdata(), dtype=float)) for line in axes.get_lines()
            if np.isfinite(np.asarray(line.get_xdata(), dtype=float)).any()]
    return 1.1 * max(ends) if ends else 1.0


def _limit(axes: Any, limit: Any, depth: Any, end: float, label: str, unit: str) -> None:
    """A limit line over the load curves, the axis kept to the loads (a limit far beyond
    them, e.g. the BHA's tensile limit at shallow bit depth, would squeeze the curves into a
    fraction of the plot); the part beyond the axis is named in the legend."""
    limit = np.asarray(limit, dtype=float)
    if not np.isfinite(limit).any():
        return
    lowest = float(np.nanmin(limit))
    if lowest > end:
        axes.plot([], [], color="red", linewidth=1.5,
                  label=f"{label}: {lowest:.0f} {unit} or more, beyond the axis")
    else:
        axes.plot(limit, depth, color="red", linewidth=1.5, label=label)
    axes.set_xlim(right=end)
