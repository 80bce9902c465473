"""``tdmon lab fit``: mu(T) laws fitted to tribometer measurements, with their uncertainty.

The fitting and its statistics live in :mod:`tdmon.calib.labfit`, the reading of the CSV file
in :mod:`tdmon.ingest.lab`; this module parses the arguments, prints the ranked fits and draws
the thesis's Figure 15 with confidence bands.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    Array = NDArray[np.float64]

    from tdmon.calib.labfit import FrictionFit, TribometerData

_MODEL_NAMES = "linear, poly-2, poly-3 (any poly-m), power, exponential, saturation-growth"
#: What a tribometer CSV holds, for the message about a file that is none.
_LAYOUT = "a CSV with columns test, temperature_C, friction_coefficient (docs/lab-fit.md)"
#: How much of a file is looked at to tell text from a binary file [bytes].
_SNIFF_BYTES = 65536


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``tdmon lab`` and its ``fit`` command."""
    lab = subparsers.add_parser(
        "lab",
        help="laboratory friction data: fit mu(T) laws",
        description="Work with laboratory (tribometer) friction measurements.",
    )
    commands = lab.add_subparsers(dest="lab_command", metavar="COMMAND", required=True)
    fit = commands.add_parser(
        "fit",
        help="fit friction-versus-temperature laws to tribometer data and rank them",
        description=(
            "Fit mu(T) laws to tribometer runs (CSV with columns test, temperature_C, "
            "friction_coefficient; '#' lines are comments; an empty friction cell is a failed "
            "run) twice: on every run ('raw') and on the mean per temperature ('averages', as "
            "the thesis and Kaarstad et al. do). Each fit is reported with its coefficients and "
            "95 % confidence intervals, R^2, adjusted R^2, standard error, AICc and a verdict on "
            "whether the temperature effect is significant at all. Fits are ranked by AICc. "
            "The coefficients are those a well file's friction table takes "
            "({family = \"linear\", a = ..., b = ...}), T in degC."
        ),
    )
    fit.add_argument("data", type=Path, metavar="DATA.csv", help="tribometer runs (CSV)")
    fit.add_argument("--models", type=_model_list, default=None, metavar="LIST",
                     help=f"comma-separated laws to fit (default: all of {_MODEL_NAMES})")
    fit.add_argument("--averages", action="store_true",
                     help="the file's rows are already per-temperature averages (e.g. typed "
                     "from a publication): fit them once, labelled 'averages'")
    out = fit.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true",
                     help="print JSON: 'fits', a list of every fit with model, data ('raw' or "
                     "'averages'), coefficients, confidence_intervals, r2, adj_r2, stderr, "
                     "verdict, rank ...")
    out.add_argument("--png", type=Path, metavar="FILE",
                     help="draw the runs, the averages and the fitted laws with 95 %% confidence "
                     "bands (the thesis's Figure 15); the ranked fits are printed too")
    fit.set_defaults(func=_run_fit)


def _model_list(text: str) -> list[str]:
    from tdmon.calib.labfit import MODELS

    names = [part.strip() for part in text.split(",") if part.strip()]
    if not names:
        raise argparse.ArgumentTypeError("give at least one model name")
    for name in names:
        degree = name.removeprefix("poly-")
        if name not in MODELS and not (name != degree and degree.isdigit() and int(degree) > 0):
            raise argparse.ArgumentTypeError(f"unknown model '{name}' (expected {_MODEL_NAMES})")
    return names


@dataclass(frozen=True)
class _Fits:
    """The data and every fit of it, by data kind (raw runs, per-temperature averages)."""

    data: TribometerData
    levels: Array
    means: Array
    counts: NDArray[np.int64]
    raw: list[FrictionFit]
    averages: list[FrictionFit]


def _fits(path: Path, models: list[str] | None, given_averages: bool) -> _Fits:
    from tdmon.calib.labfit import DEFAULT_MODELS, fit_friction_models, temperature_averages
    from tdmon.ingest.lab import read_tribometer_csv

    chosen = tuple(models) if models is not None else DEFAULT_MODELS
    data = read_tribometer_csv(path)
    levels, means, counts = temperature_averages(data.temperature, data.friction)
    raw: list[FrictionFit] = []
    if not given_averages:
        raw = fit_friction_models(data.temperature, data.friction, chosen, data="raw")
        averages = fit_friction_models(levels, means, chosen, data="averages")
    else:
        averages = fit_friction_models(data.temperature, data.friction, chosen,
                                       data="averages")
    return _Fits(data, levels, means, counts, raw, averages)


def _run_fit(args: argparse.Namespace) -> int:
    check_text_file(args.data)
    fits = _fits(args.data, args.models, args.averages)
    if args.json:
        json.dump(_document(args.data, fits), sys.stdout, allow_nan=False)
        print()
    else:
        # the figure does not replace the numbers: the ranked fits with their coefficients
        _print(fits, args.data)
        if args.png is not None:
            _plot(fits, args.png, args.data)
            print(f"\nwrote {args.png}")
    return 0


def check_text_file(path: Path) -> None:
    """Refuse a file that is not text (an MCAP recording, a spreadsheet, an image) with one
    line saying what it is and what ``lab fit`` reads, instead of the CSV reader's decoding
    error. A missing or unreadable file is left to the reader, which names the cause.

    Raises
    ------
    FitError
        Naming the file.
    """
    import codecs

    from tdmon.errors import FitError

    try:
        with path.open("rb") as handle:
            head = handle.read(_SNIFF_BYTES)
    except OSError:
        return
    if head.startswith(b"\x89MCAP"):
        raise FitError(f"{path}: an MCAP recording, not tribometer data: lab fit reads "
                       f"{_LAYOUT}; a recording goes to tdmon report or tdmon view")
    try:
        # incremental: a character cut at the end of the sample is not a mistake
        codecs.getincrementaldecoder("utf-8")().decode(head, final=False)
        binary = b"\x00" in head
    except UnicodeDecodeError:
        binary = True
    if binary:
        raise FitError(f"{path}: not a text file (not UTF-8), so not tribometer data: lab fit "
                       f"reads {_LAYOUT}")


def _document(path: Path, fits: _Fits) -> dict[str, Any]:
    return {
        "file": str(path),
        "runs": int(fits.data.friction.size),
        "failed_runs": fits.data.failed_runs,
        "averages": {"temperature_C": fits.levels.tolist(), "friction": fits.means.tolist(),
                     "runs": fits.counts.tolist()},
        "fits": [fit.to_dict() for fit in fits.raw + fits.averages],
    }


def _coefficient_text(fit: FrictionFit) -> str:
    parts = []
    for name, value in fit.coefficients.items():
        interval = fit.confidence_intervals.get(name)
        if interval is None:
            parts.append(f"{name} {value:.5g}")
        else:
            parts.append(f"{name} {value:.5g} ± {(interval[1] - interval[0]) / 2:.2g}")
    return ", ".join(parts)


def _number(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def _print(fits: _Fits, path: Path) -> None:
    data = fits.data
    failed = f", {data.failed_runs} failed run(s) dropped" if data.failed_runs else ""
    what = "runs" if fits.raw else "averages as given"
    print(f"{path}: {data.friction.size} {what}{failed}; temperatures "
          f"{fits.levels.min():g}-{fits.levels.max():g} degC")
    sections = [("every run", fits.raw)] if fits.raw else []
    sections.append(("per-temperature averages", fits.averages))
    for title, group in sections:
        print()
        print(f"{title} (n = {group[0].n}), ranked by AICc; coefficients ± half the 95 % "
              "interval, T in degC:")
        print(f"  {'#':>2} {'model':<18}{'R^2':>8}{'adj R^2':>9}{'SE':>9}{'AICc':>9}  "
              "coefficients")
        for fit in group:
            print(f"  {fit.rank:>2} {fit.model:<18}{fit.r2:>8.4f}{_number(fit.adj_r2, '.4f'):>9}"
                  f"{_number(fit.stderr, '.5f'):>9}{_number(fit.aicc, '.2f'):>9}  "
                  f"{_coefficient_text(fit)}")
        for fit in group:
            print(f"  - {fit.verdict}")
    everything = fits.raw + fits.averages
    if not any(fit.temperature_significant for fit in everything):
        print()
        print("No fitted law shows a temperature effect distinguishable from zero at the 95 % "
              "level: with these data a constant friction factor explains them as well.")


def _plot(fits: _Fits, path: Path, source: Path) -> None:
    """Runs, averages, fitted laws and the 95 % bands of the best linear/polynomial fits."""
    import numpy as np

    from tdmon.calib.labfit import confidence_band
    from tdmon.cli.plots import _figure, save

    figure = _figure(2)
    axis = figure.subplots()
    data = fits.data
    if fits.raw:
        axis.scatter(data.temperature, data.friction, s=14, color="0.6", label="runs")
        axis.scatter(fits.levels, fits.means, s=50, marker="s", color="black", zorder=3,
                     label="mean per temperature")
        points = {"raw": data.temperature, "averages": fits.levels}
    else:
        axis.scatter(data.temperature, data.friction, s=50, marker="s", color="black",
                     zorder=3, label="averages (as given)")
        points = {"averages": data.temperature}
    low, high = float(fits.levels.min()), float(fits.levels.max())
    grid = np.linspace(low, high, 200)
    style = {"raw": "--", "averages": "-"}
    for kind, group in (("raw", fits.raw), ("averages", fits.averages)):
        banded = False
        for index, fit in enumerate(group):
            colour = f"C{index}"
            curve = fit.friction_model()(grid)
            axis.plot(grid, curve, color=colour, linestyle=style[kind],
                      label=f"{fit.model} ({kind}): {fit.friction_model().describe()}, "
                      f"R^2 {fit.r2:.3f}")
            band = None if banded else confidence_band(fit, points[kind], grid)
            if band is not None:
                axis.fill_between(grid, curve - band, curve + band, color=colour,
                                  alpha=0.15 if kind == "averages" else 0.08,
                                  label=f"95 % band of the mean, {fit.model} ({kind})")
                banded = True
    axis.set_xlabel("temperature [degC]")
    axis.set_ylabel("friction coefficient [-]")
    axis.grid(alpha=0.3)
    axis.legend(fontsize="x-small", loc="upper left")
    figure.suptitle(f"{source.name}: friction against temperature (solid: fits of the "
                    "averages, dashed: fits of every run)")
    save(figure, path)
