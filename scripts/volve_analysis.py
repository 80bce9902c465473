"""Back-calculation on the real Volve F-4 trips: figures and figures of merit for
docs/back-calculation.md.

Usage::

    .venv/bin/python scripts/volve_analysis.py [--data DIR] [--out docs/figures]

Reads the trip-out (2016-10-04, 7" tubing) and trip-in (2016-10-05, 7" tubing below 5-1/2" drill
pipe) CSV files of the Volve data set (Equinor Open Data Licence; attribution: "Equinor and the
former Volve licence partners"), runs the rig-state detector, the window builder, the block
weight and the per-window back-calculation of `tdmon.calib`, and prints the figures of merit as
JSON. Without the CSV folder (``--data``, or ``TDMON_VOLVE_DATA``) it reads the same records
from the project's imported replays, replays/volve-f4-trip-*.mcap. The functions are imported
by tests/calib/test_volve.py, so the test and the documented numbers come from the same code.
"""

from __future__ import annotations

import argparse
import json
import math
import os
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from tdmon.calib.backcalc import FrictionEstimate, back_calculate_window
from tdmon.calib.blockweight import BlockWeightEstimate, block_weight_from_samples
from tdmon.calib.rigstate import DetectorState, RigSample, RigStateThresholds, detect
from tdmon.calib.windows import Window, WindowAccumulator, WindowSettings, add_sample, close
from tdmon.config.well import load_well_model
from tdmon.errors import FitError, ModelError
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Well

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("TDMON_VOLVE_DATA", str(ROOT / "data" / "volve-f4")))
WELL_FILE = ROOT / "config" / "wells" / "volve-f4.toml"
TRIP_OUT = "trip-out-2016-10-04.csv"
TRIP_IN = "trip-in-2016-10-05.csv"

# Configured block weight is a starting point only: the detector needs one to tell in-slips
# samples; the estimate from those samples replaces it.
THRESHOLDS = RigStateThresholds(block_weight=655e3, in_slips_margin=200e3, settle_time=5.0)
# At 15 s sampling a joint's steady pull is one or two samples.
WINDOWS = WindowSettings(min_samples=1, max_travel=15.0)

# rig_activity_code of the Volve logs (README): base activity, +10 circulating, +100 rotation
# flag. The flag is set on a string turning at 0.23 rev/min, i.e. not rotating: it is ignored.
COMPATIBLE: dict[int, frozenset[str]] = {
    1: frozenset({"drilling"}),
    2: frozenset({"reaming", "back_reaming"}),
    3: frozenset({"static", "circulating", "rotating_off_bottom"}),
    4: frozenset({"in_slips"}),
    6: frozenset({"slack_off", "static", "circulating"}),
    7: frozenset({"pick_up", "static", "circulating"}),
    8: frozenset({"in_slips"}),
}


def load_record(path: Path) -> pd.DataFrame:
    """A Volve CSV in SI: t [s], hookload [N], bit/hole depth [m], block [m], rpm [rad/s],
    flow [m3/s], spp [Pa], torque [N m], code."""
    raw = pd.read_csv(path)
    stamps = pd.to_datetime(raw["time_utc"], utc=True)
    # seconds since the epoch whatever resolution pandas picked for the timestamps
    t = ((stamps - pd.Timestamp(0, tz="UTC")) / pd.Timedelta(seconds=1)).to_numpy(float)
    return pd.DataFrame({
        "t": t,
        "hookload": raw["hookload_kN"].to_numpy(float) * 1e3,
        "bit_depth": raw["bit_depth_m"].to_numpy(float),
        "hole_depth": raw["hole_depth_m"].to_numpy(float),
        "block_position": raw["block_pos_comp_m"].to_numpy(float),
        "rpm": raw["surface_rpm"].to_numpy(float) * 2 * math.pi / 60,
        "flow": raw["flow_in_Lpm"].to_numpy(float) / 60_000,
        "spp": raw["spp_bar"].to_numpy(float) * 1e5,
        "torque": raw["surface_torque_kNm"].to_numpy(float) * 1e3,
        "code": raw["rig_activity_code"].to_numpy(int),
        "time_utc": raw["time_utc"],
    })


REPLAYS = ROOT / "replays"
MCAP_FOR = {TRIP_OUT: "volve-f4-trip-out.mcap", TRIP_IN: "volve-f4-trip-in.mcap"}
_MCAP_CHANNELS = {"hookload": "hookload", "bit_depth": "bit_depth", "hole_depth": "hole_depth",
                  "block_position": "block_position", "rpm": "rpm", "flow_in": "flow",
                  "spp": "spp", "torque": "torque"}


def load_record_mcap(path: Path) -> pd.DataFrame:
    """The same record from the project's imported replay (replays/volve-f4-*.mcap): the
    ``/tdmon/raw`` samples (SI) and the rig's codes on ``/reference/rig_activity``."""
    from mcap.reader import make_reader

    rows: dict[float, dict[str, float]] = {}
    with open(path, "rb") as stream:
        for _, channel, message in make_reader(stream).iter_messages(
                topics=["/tdmon/raw", "/reference/rig_activity"]):
            record = json.loads(message.data)
            if channel.topic == "/reference/rig_activity":
                rows.setdefault(float(record["t"]), {})["code"] = float(record["code"])
                continue
            name = _MCAP_CHANNELS.get(record["topic"].rsplit("/", 1)[-1])
            if name is None:
                continue
            payload = json.loads(record["payload"])
            rows.setdefault(float(payload["t"]), {})[name] = float(payload["value"])
    frame = pd.DataFrame.from_dict(rows, orient="index").sort_index()
    frame = frame.reindex(columns=[*_MCAP_CHANNELS.values(), "code"])
    frame.insert(0, "t", frame.index.to_numpy(float))
    frame = frame[frame["code"].notna()].reset_index(drop=True)
    frame["code"] = frame["code"].astype(int)
    return frame


def load(name: str, data: Path = DATA) -> pd.DataFrame:
    """A record by file name: the CSV in ``data`` when there, else the committed replay."""
    csv = data / name
    return load_record(csv) if csv.exists() else load_record_mcap(REPLAYS / MCAP_FOR[name])


def trip_out_well() -> Well:
    """The configured Volve F-4 well: 2574 m of 7" tubing."""
    return load_well_model(WELL_FILE)


def trip_in_well() -> Well:
    """The string run on 2016-10-05: 2054 m of 7" tubing below 562 m of 5-1/2" drill pipe.

    The drill pipe's weight (21.9 lb/ft nominal, about 36 kg/m with tool joints) and its tool
    joints (7 in OD) are nominal values; the tubing is the well file's.
    """
    well = trip_out_well()
    tubing = replace(well.string.components[0], length=2054.0)
    pipe = StringComponent("5-1/2 in drill pipe, 21.9 lb/ft", 562.0, 0.1397, 0.12136,
                           weight_in_air=36.0 * 9.80665, tool_joint_diameter=0.1778,
                           yield_strength=931e6, makeup_torque=38e3)
    return replace(well, string=DrillString((tubing, pipe)),
                   name="Volve 15/9-F-4 (7 in tubing + 5-1/2 in DP, 2016-10-05)")


@dataclass
class Analysis:
    """What one record gives."""

    record: pd.DataFrame
    states: list[str]
    steady: list[bool]
    windows: list[Window]
    block_weight: BlockWeightEstimate
    estimates: list[tuple[Window, FrictionEstimate]]
    rejected: Counter[str]


def analyse(record: pd.DataFrame, model: WellModel,
            thresholds: RigStateThresholds = THRESHOLDS,
            settings: WindowSettings = WINDOWS) -> Analysis:
    """Detect states, build windows, take the block weight, back-calculate every window."""
    prior = DetectorState()
    acc = WindowAccumulator()
    states: list[str] = []
    steady: list[bool] = []
    windows: list[Window] = []
    in_slips: list[float] = []
    names = ("hookload", "bit_depth", "block_position", "rpm", "flow", "spp", "hole_depth",
             "torque")
    columns = [record[name].to_numpy(float) for name in names]
    times = record["t"].to_numpy(float)
    for i in range(times.size):
        values = [float(column[i]) for column in columns]
        sample = RigSample(float(times[i]), *(v if math.isfinite(v) else None for v in values))
        prior, detection = detect(prior, sample, thresholds)
        states.append(detection.state)
        steady.append(detection.steady)
        if detection.state == "in_slips" and detection.steady and sample.hookload is not None:
            in_slips.append(sample.hookload)
        acc, window = add_sample(acc, sample, detection, settings)
        if window is not None:
            windows.append(window)
    acc, window = close(acc, settings)
    if window is not None:
        windows.append(window)
    block = block_weight_from_samples(in_slips)
    # the model's block weight is replaced by the one measured in slips
    measured_model = WellModel(replace(model.well, block_weight=block.value))
    estimates: list[tuple[Window, FrictionEstimate]] = []
    rejected: Counter[str] = Counter()
    for w in windows:
        if w.state not in ("pick_up", "slack_off"):
            continue
        if w.rejected is not None:
            rejected[w.rejected.split(":")[0]] += 1
            continue
        try:
            estimates.append((w, back_calculate_window(measured_model, w)))
        except FitError as exc:
            rejected["not_bracketed" if "bracketed" in str(exc) else "model"] += 1
    return Analysis(record, states, steady, windows, block, estimates, rejected)


def agreement(record: pd.DataFrame, states: list[str]) -> tuple[float, int, pd.DataFrame]:
    """Share of samples (code not 0) whose detected state fits the rig's activity code, the
    number of samples compared, and the confusion table (code x state)."""
    base = record["code"].to_numpy() % 100
    circulating = base >= 10
    base = base % 10
    hits = 0
    compared = 0
    for code, circ, state in zip(base, circulating, states, strict=True):
        if code == 0:
            continue
        allowed = COMPATIBLE.get(int(code), frozenset())
        if circ and code in (6, 7, 3):
            allowed = allowed | {"circulating"}
        compared += 1
        hits += state in allowed
    table = pd.crosstab(record["code"], pd.Series(states, name="state"))
    return hits / max(compared, 1), compared, table


def per_joint(analysis: Analysis, operation: str) -> pd.DataFrame:
    """One friction factor per joint (the windows of one pull or run), with its std."""
    rows = [(w.t_start, w.bit_depth, e.mu, e.mu_std, w.hookload, w.n, bool(w.flags))
            for w, e in analysis.estimates if w.state == operation]
    frame = pd.DataFrame(rows, columns=["t", "bit_depth", "mu", "mu_std", "hookload", "n",
                                        "flagged"])
    return frame


def model_curves(model: WellModel, depths: np.ndarray, mus: tuple[float, ...]
                 ) -> dict[str, dict[float, np.ndarray]]:
    """Modelled pick-up, slack-off and static hook loads [N] at ``depths`` for each mu."""
    out: dict[str, dict[float, np.ndarray]] = {"pick_up": {}, "slack_off": {}, "static": {}}
    for op in out:
        for mu in (mus if op != "static" else (0.0,)):
            out[op][mu] = np.array([model.evaluate(op, d, mu)[0] for d in depths])
    return out


def bracketing(analysis: Analysis, model: WellModel, low_mu: float, high_mu: float
               ) -> dict[str, float]:
    """Share of steady pick-up and slack-off samples inside the modelled band
    [slack-off(high_mu), pick-up(high_mu)] and between static and pick-up/slack-off(high)."""
    rec = analysis.record
    block = analysis.block_weight.value
    mmodel = WellModel(replace(model.well, block_weight=block))
    inside = {"pick_up": [0, 0], "slack_off": [0, 0]}
    for i, (state, steady) in enumerate(zip(analysis.states, analysis.steady, strict=True)):
        if state not in inside or not steady:
            continue
        depth, hook = float(rec["bit_depth"].iloc[i]), float(rec["hookload"].iloc[i])
        try:
            up = mmodel.evaluate("pick_up", depth, high_mu)[0]
            down = mmodel.evaluate("slack_off", depth, high_mu)[0]
        except ModelError:  # a depth the model does not reach is not counted
            continue
        inside[state][1] += 1
        inside[state][0] += down <= hook <= up
    return {k: v[0] / v[1] if v[1] else math.nan for k, v in inside.items()} | {
        f"{k}_samples": float(v[1]) for k, v in inside.items()}


def artefact_check(analysis: Analysis) -> dict[str, float]:
    """The trip-in depth-tracking artefact (01:35-02:20Z): samples where the bit depth
    advances while the hook load is at in-slips level; how many became windows."""
    rec = analysis.record
    depth_step = np.diff(rec["bit_depth"].to_numpy(), prepend=np.nan)
    near_block = rec["hookload"].to_numpy() < analysis.block_weight.value + 100e3
    artefact = (depth_step > 0.5) & near_block
    in_windows = 0
    for w in analysis.windows:
        if w.state not in ("pick_up", "slack_off"):
            continue
        mask = (rec["t"] >= w.t_start) & (rec["t"] <= w.t_end)
        in_windows += int((artefact & mask.to_numpy()).sum())
    states = np.array(analysis.states)
    return {"artefact_samples": float(artefact.sum()),
            "artefact_samples_in_windows": float(in_windows),
            "artefact_samples_in_slips": float((states[artefact] == "in_slips").sum())}


def inside_density_from_static(analysis: Analysis, model: WellModel, *,
                               min_samples: int = 5) -> tuple[float, float, float]:
    """Inside fluid density that makes the model's static weight match the longest static
    hang of the record (eq 36 with the outside fluid kept): (density [kg/m3], bit depth [m],
    measured string weight [N]).

    The trip-in string hangs ~14 % lighter than modelled with one fluid: a tubing run without
    being filled up is the usual reason, and eq 36 with a lighter inside fluid is the simplest
    model of it.
    """
    from scipy.optimize import brentq

    from tdmon.model.well import Fluid

    hangs = [w for w in analysis.windows
             if w.state == "static" and w.rejected is None and w.n >= min_samples]
    if not hangs:
        raise FitError("no static hang long enough for a weight check")
    hang = max(hangs, key=lambda w: w.n)
    block = analysis.block_weight.value
    outside = model.well.fluid.density

    def misfit(inside: float) -> float:
        well = replace(model.well, fluid=Fluid(outside, inside), block_weight=block)
        return WellModel(well).evaluate("static", hang.bit_depth, 0.0)[0] - hang.hookload

    density = float(brentq(misfit, 0.0, 2.0 * outside))
    return density, hang.bit_depth, hang.hookload - block


def figures_of_merit(out_analysis: Analysis, in_analysis: Analysis, out_model: WellModel,
                     in_model: WellModel) -> dict[str, Any]:
    merit: dict[str, Any] = {}
    for name, analysis, model in (("trip_out", out_analysis, out_model),
                                  ("trip_in", in_analysis, in_model)):
        share, compared, _ = agreement(analysis.record, analysis.states)
        op = "pick_up" if name == "trip_out" else "slack_off"
        joints = per_joint(analysis, op)
        merit[name] = {
            "agreement": share,
            "samples_compared": compared,
            "block_weight_kN": analysis.block_weight.value / 1e3,
            "block_weight_se_kN": analysis.block_weight.std / 1e3,
            "in_slips_samples": analysis.block_weight.n,
            "windows": len(analysis.windows),
            "friction_windows": len(joints),
            "rejected": dict(analysis.rejected),
            "mu_median": float(joints["mu"].median()) if len(joints) else math.nan,
            "mu_mean": float(joints["mu"].mean()) if len(joints) else math.nan,
            "mu_spread_std": float(joints["mu"].std()) if len(joints) > 1 else math.nan,
            "mu_iqr": (float(joints["mu"].quantile(0.75) - joints["mu"].quantile(0.25))
                       if len(joints) else math.nan),
            "mu_std_median": float(joints["mu_std"].median()) if len(joints) else math.nan,
            "band_mu_0.35": bracketing(analysis, model, 0.0, 0.35),
        }
    merit["trip_in"]["artefact"] = artefact_check(in_analysis)
    density, depth, weight = inside_density_from_static(in_analysis, in_model)
    checked_model = weight_checked_model(in_model, density)
    checked = analyse(in_analysis.record, checked_model)
    joints = per_joint(checked, "slack_off")
    merit["trip_in_weight_checked"] = {
        "inside_density_kg_m3": density,
        "static_hang_bit_depth_m": depth,
        "static_hang_weight_kN": weight / 1e3,
        "mu_median": float(joints["mu"].median()),
        "mu_spread_std": float(joints["mu"].std()),
        "mu_iqr": float(joints["mu"].quantile(0.75) - joints["mu"].quantile(0.25)),
        "band_mu_0.35": bracketing(checked, checked_model, 0.0, 0.35),
    }
    return merit


def weight_checked_model(model: WellModel, inside_density: float) -> WellModel:
    """The model with the inside fluid density of the weight check."""
    from tdmon.model.well import Fluid

    return WellModel(replace(model.well, fluid=Fluid(model.well.fluid.density, inside_density)))


def plot(out_analysis: Analysis, in_analysis: Analysis, out_model: WellModel,
         in_model: WellModel, folder: Path,
         checked: tuple[Analysis, WellModel, float] | None = None) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    colours = {"in_slips": "0.6", "pick_up": "tab:red", "slack_off": "tab:blue",
               "static": "tab:green", "circulating": "tab:cyan", "unknown": "k",
               "rotating_off_bottom": "tab:purple", "reaming": "tab:orange",
               "back_reaming": "tab:brown", "drilling": "tab:pink"}

    # 1. states over time
    fig, axes = plt.subplots(2, 1, figsize=(11, 7))
    for ax, analysis, title in ((axes[0], out_analysis, "trip out 2016-10-04 (7 in tubing)"),
                                (axes[1], in_analysis, "trip in 2016-10-05 (tubing + DP)")):
        rec = analysis.record
        hours = (rec["t"] - rec["t"].iloc[0]) / 3600
        states = np.array(analysis.states)
        for state, colour in colours.items():
            mask = states == state
            if mask.any():
                ax.scatter(hours[mask], rec["hookload"][mask] / 1e3, s=6, c=colour, label=state)
        steady = np.array(analysis.steady) & np.isin(states, ["pick_up", "slack_off"])
        ax.scatter(hours[steady], rec["hookload"][steady] / 1e3, s=30, facecolors="none",
                   edgecolors="k", label="steady (window)")
        share, _, _ = agreement(rec, analysis.states)
        ax.set_title(f"{title}: detected state, {100 * share:.1f} % agree with rig codes")
        ax.set_ylabel("hook load [kN]")
        ax.legend(fontsize=7, ncol=4, loc="center right")
    axes[1].set_xlabel("hours from start of record")
    fig.tight_layout()
    path = folder / "volve-states.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path)

    # 2. per-joint friction
    fig, ax = plt.subplots(figsize=(9, 5))
    series = [(out_analysis, "pick_up", "tab:red", "trip out"),
              (in_analysis, "slack_off", "tab:blue", "trip in, one fluid")]
    if checked is not None:
        series.append((checked[0], "slack_off", "tab:cyan",
                       f"trip in, inside fluid {checked[2]:.0f} kg/m3 (weight check)"))
    for analysis, op, colour, label in series:
        joints = per_joint(analysis, op)
        if len(joints):
            ax.errorbar(joints["bit_depth"], joints["mu"], yerr=joints["mu_std"], fmt="o",
                        ms=3, c=colour, label=f"{op}, {label}: median "
                        f"{joints['mu'].median():.3f}, std {joints['mu'].std():.3f} "
                        f"({len(joints)} windows)")
    ax.axhspan(0.16, 0.20, color="0.9", label="Table 24 cased, oil-based")
    ax.axhspan(0.25, 0.35, color="0.8", alpha=0.5, label="Table 24 cased, water-based")
    ax.set_xlabel("bit depth [m MD]")
    ax.set_ylabel("back-calculated friction factor [-]")
    ax.set_title("Volve F-4: friction per steady window (cased hole), 1 sigma from noise")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = folder / "volve-friction.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path)

    # 3. measured against modelled (broomstick)
    panels = [(out_analysis, out_model, "trip out"), (in_analysis, in_model, "trip in, one fluid")]
    if checked is not None:
        panels.append((checked[0], checked[1], f"trip in, inside {checked[2]:.0f} kg/m3"))
    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 6), sharey=False)
    for ax, (analysis, model, title) in zip(axes, panels, strict=True):
        rec = analysis.record
        block = analysis.block_weight.value
        mmodel = WellModel(replace(model.well, block_weight=block))
        depth = rec["bit_depth"].to_numpy()
        valid = depth[np.isfinite(depth) & (depth > 100)]
        lo, hi = float(valid.min()), min(float(valid.max()), model.well.string.length)
        grid = np.linspace(lo, hi, 40)
        curves = model_curves(mmodel, grid, (0.1, 0.2, 0.3))
        for mu, style in ((0.1, ":"), (0.2, "--"), (0.3, "-")):
            ax.plot(curves["pick_up"][mu] / 1e3, grid, "r" + style, lw=1,
                    label=f"pick-up mu={mu}")
            ax.plot(curves["slack_off"][mu] / 1e3, grid, "b" + style, lw=1,
                    label=f"slack-off mu={mu}")
        ax.plot(curves["static"][0.0] / 1e3, grid, "g-", lw=1, label="static")
        states = np.array(analysis.states)
        for state, colour in (("pick_up", "tab:red"), ("slack_off", "tab:blue"),
                              ("static", "tab:green")):
            mask = (states == state) & np.array(analysis.steady)
            ax.scatter(rec["hookload"][mask] / 1e3, depth[mask], s=10, c=colour,
                       edgecolors="k", linewidths=0.3, label=f"measured {state} (steady)")
        ax.invert_yaxis()
        ax.set_xlabel("hook load [kN]")
        ax.set_ylabel("bit depth [m MD]")
        ax.set_title(f"{title}: block {block / 1e3:.0f} kN (in slips)", fontsize=10)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path = folder / "volve-broomstick.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path)
    return written


def run(data: Path = DATA) -> tuple[Analysis, Analysis, WellModel, WellModel]:
    out_model = WellModel(trip_out_well())
    in_model = WellModel(trip_in_well())
    out_analysis = analyse(load(TRIP_OUT, data), out_model)
    in_analysis = analyse(load(TRIP_IN, data), in_model)
    return out_analysis, in_analysis, out_model, in_model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "figures")
    args = parser.parse_args()
    out_analysis, in_analysis, out_model, in_model = run(args.data)
    merit = figures_of_merit(out_analysis, in_analysis, out_model, in_model)
    print(json.dumps(merit, indent=2, default=float))
    density = merit["trip_in_weight_checked"]["inside_density_kg_m3"]
    checked_model = weight_checked_model(in_model, density)
    checked = (analyse(in_analysis.record, checked_model), checked_model, density)
    for name, analysis in (("trip out", out_analysis), ("trip in", in_analysis)):
        print(f"\nconfusion table, {name} (rows: rig_activity_code, columns: detected state)")
        print(agreement(analysis.record, analysis.states)[2].to_string())
    for path in plot(out_analysis, in_analysis, out_model, in_model, args.out, checked):
        print("wrote", path)


if __name__ == "__main__":
    main()
