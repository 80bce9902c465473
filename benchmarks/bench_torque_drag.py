"""Torque-and-drag benchmark: tdmon against welleng 0.30 and torque_drag 0.1.1, in one run.

The case (docs/reference-values.md §6): a 6000 m well, vertical to 1000 m, build 3 deg/30 m to
80 deg, then tangent; 5" x 4.276" drill pipe only (eq 41 weight, 262.1 N/m in air), 8.5" hole,
1.2 s.g. mud, friction 0.25; survey and elements every 1 m; 20 bit depths. At each depth:
pick-up and slack-off hook load and rotating off-bottom torque.

With the fluid terms (docs/hydraulics.md): the same well with a 65/40 Fann mud, its fluid
forces for a trip out at 0.5 m/s and densities on every element (a pill in the string); one
pick-up evaluation at TD and one of the kernel's fixed cost (the bit one element deep), each
with the terms on and off. ``--fluid-only`` runs just these (no peers needed):

    benchmarks/.venv/bin/python benchmarks/bench_torque_drag.py --fluid-only --steps 1

Run it in the benchmark's own virtualenv (see benchmarks/README.md):

    benchmarks/setup.sh
    benchmarks/.venv/bin/python benchmarks/bench_torque_drag.py [--repeat 5] [--json out.json]

The peers are never imported by tdmon; they live only in benchmarks/.venv.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from tdmon.model.broomstick import broomstick, broomstick_from_model
from tdmon.model.fluid_force import HydraulicModel
from tdmon.model.fluid_terms import FluidTerms
from tdmon.model.hydraulics import WellHydraulics
from tdmon.model.rheology import from_fann
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.survey import minimum_curvature
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Fluid, HoleSection, Well

INCH = 0.0254
PIPE_OD_IN, PIPE_ID_IN, HOLE_IN = 5.0, 4.276, 8.5
MUD_SG, STEEL_SG = 1.2, 7.85
FRICTION = 0.25
TOTAL_DEPTH = 6000.0
N_DEPTHS = 20


def trajectory(step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stations every ``step`` m (plus the end of build at 1800 m): MD, inclination, azimuth."""
    md = np.union1d(np.arange(0.0, TOTAL_DEPTH + 0.5 * step, step), [1000.0, 1800.0])
    inclination = np.clip((md - 1000.0) * 3.0 / 30.0, 0.0, 80.0)
    return md, inclination, np.zeros_like(md)


def bit_depths() -> np.ndarray:
    return np.linspace(TOTAL_DEPTH / N_DEPTHS, TOTAL_DEPTH, N_DEPTHS)


def pipe_weight_in_air() -> float:
    area = math.pi / 4 * ((PIPE_OD_IN * INCH) ** 2 - (PIPE_ID_IN * INCH) ** 2)
    return area * STEEL_SG * 1000.0 * 9.80665


def best_of(function: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    """Smallest wall time of ``repeat`` calls [s] (the least disturbed by other load on the
    machine) and the last result."""
    times = []
    result = None
    for _ in range(repeat):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return min(times), result


# --- tdmon ---------------------------------------------------------------------------------


def tdmon_well(step: float, hydraulics: WellHydraulics | None = None) -> Well:
    md, inc, azi = trajectory(step)
    string = DrillString((StringComponent("5in DP", TOTAL_DEPTH, PIPE_OD_IN * INCH,
                                          PIPE_ID_IN * INCH),))
    return Well(minimum_curvature(md, inc, azi), string,
                (HoleSection(0.0, TOTAL_DEPTH, HOLE_IN * INCH, "open", FRICTION),),
                Fluid(MUD_SG * 1000.0), element_length=step,
                hydraulics=hydraulics or WellHydraulics())


def per_call(function: Callable[[], Any], repeat: int, calls: int = 200) -> float:
    """Smallest mean wall time of one call over ``repeat`` batches of ``calls`` [s]."""
    best = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(calls):
            function()
        best = min(best, (time.perf_counter() - start) / calls)
    return best


def run_fluid(step: float, repeat: int) -> dict[str, Any]:
    """One pick-up evaluation with the fluid terms off and on, at TD and at the shallowest
    depth (the kernel's fixed cost), interleaved off, on, off, on (the best of each kept)."""
    well = tdmon_well(step, WellHydraulics(rheology=from_fann(65.0, 40.0)))
    model = WellModel(well)
    n = model.n_elements
    inside = np.where((model.node_md[:-1] > 500.0) & (model.node_md[:-1] < 800.0), 1800.0,
                      MUD_SG * 1000.0)
    hydraulic = HydraulicModel(well, model.grid)
    hydraulic.forces(TOTAL_DEPTH, -0.5, inside_density=inside)  # imports scipy
    hydraulics_s, forces = best_of(
        lambda: hydraulic.forces(TOTAL_DEPTH, -0.5, inside_density=inside), repeat)
    terms = FluidTerms(axial=forces.terms.axial, bit_force=forces.terms.bit_force,
                       outside_density=np.full(n, MUD_SG * 1000.0), inside_density=inside)
    shallow = float(model.node_md[1])
    calls = {
        "td_off": lambda: model.evaluate("pick_up", TOTAL_DEPTH, FRICTION),
        "td_on": lambda: model.evaluate("pick_up", TOTAL_DEPTH, FRICTION, fluid=terms),
        "fixed_off": lambda: model.evaluate("pick_up", shallow, FRICTION),
        "fixed_on": lambda: model.evaluate("pick_up", shallow, FRICTION, fluid=terms),
    }
    for call in calls.values():
        call()  # loads the kernels
    best = dict.fromkeys(calls, math.inf)
    for _ in range(2):  # A B A B
        for name, call in calls.items():
            best[name] = min(best[name], per_call(call, max(repeat // 2, 1)))
    off, _ = model.evaluate("pick_up", TOTAL_DEPTH, FRICTION)
    on, _ = model.evaluate("pick_up", TOTAL_DEPTH, FRICTION, fluid=terms)
    return {"n_elements": n, "hydraulics_s": hydraulics_s, "swab_at_bit_Pa": forces.surge_at_bit,
            "pick_up_off_N": off, "pick_up_on_N": on, **{f"{k}_s": v for k, v in best.items()}}


def fluid_report(result: dict[str, Any]) -> str:
    td = result["td_on_s"] / result["td_off_s"]
    fixed = result["fixed_on_s"] / result["fixed_off_s"]
    return "\n".join([
        f"Fluid terms ({result['n_elements']} elements; trip out at 0.5 m/s, 65/40 Fann mud, "
        f"a 1800 kg/m3 pill inside; swab at the bit {result['swab_at_bit_Pa'] / 1e5:.2f} bar, "
        f"pick-up at TD {result['pick_up_off_N'] / 1e3:.1f} kN off, "
        f"{result['pick_up_on_N'] / 1e3:.1f} kN on):",
        "",
        "| one pick-up evaluation | terms off | terms on | on / off |",
        "|---|---|---|---|",
        f"| bit at TD | {result['td_off_s'] * 1e3:.3f} ms | {result['td_on_s'] * 1e3:.3f} ms | "
        f"{td:.2f} |",
        f"| bit one element deep (fixed cost) | {result['fixed_off_s'] * 1e6:.1f} us | "
        f"{result['fixed_on_s'] * 1e6:.1f} us | {fixed:.2f} |",
        "",
        f"The fluid forces themselves (HydraulicModel.forces, once per sample, not per "
        f"evaluation): {result['hydraulics_s'] * 1e3:.1f} ms. A FluidTerms is packed for the "
        f"loop once (WellModel keeps the last): the fixed cost above is that of the march."])


def run_tdmon(step: float, repeat: int) -> dict[str, Any]:
    well = tdmon_well(step)
    depths = bit_depths()
    start = time.perf_counter()
    broomstick(well, depths[:1], [FRICTION])  # loads or compiles the numba kernels
    warm_up = time.perf_counter() - start
    cold, _ = best_of(lambda: broomstick(well, depths, [FRICTION]), repeat)
    model = WellModel(well)
    warm, result = best_of(lambda: broomstick_from_model(model, depths, [FRICTION]), repeat)
    single = []
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(200):
            model.evaluate("pick_up", TOTAL_DEPTH, FRICTION)
        single.append((time.perf_counter() - start) / 200)
    return {
        "time_s": cold,
        "time_prepared_s": warm,
        "first_call_s": warm_up,
        "single_depth_s": min(single),
        "n_elements": model.n_elements,
        "pick_up_N": result.hookload["pick_up"][0].tolist(),
        "slack_off_N": result.hookload["slack_off"][0].tolist(),
        "rotating_N": result.hookload["rotating"][0].tolist(),
        "torque_Nm": result.surface_torque["rotating"][0].tolist(),
    }


# --- welleng 0.30 ----------------------------------------------------------------------------


def run_welleng(step: float, repeat: int) -> dict[str, Any]:
    from welleng.architecture import BHA, WellBore
    from welleng.survey import Survey, SurveyHeader
    from welleng.torque_drag import TorqueDrag

    md, inc, azi = trajectory(step)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # grid-convergence notice: irrelevant here
        survey = Survey(md=md, inc=inc, azi=azi, header=SurveyHeader())
    hole = WellBore("hole", top=0, bottom=TOTAL_DEPTH, method="top_down")
    hole.add_section(id=HOLE_IN * INCH, coeff_friction_sliding=FRICTION, bottom=TOTAL_DEPTH)
    string = BHA("string", top=0, bottom=TOTAL_DEPTH)
    string.add_section(od=PIPE_OD_IN * INCH, id=PIPE_ID_IN * INCH,
                       unit_weight=pipe_weight_in_air(), length=TOTAL_DEPTH,
                       density=STEEL_SG)

    def sweep() -> list[Any]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return [TorqueDrag(survey, hole, string.depth(float(depth)), fluid_density=MUD_SG)
                    for depth in bit_depths()]

    elapsed, results = best_of(sweep, repeat)
    return {
        "time_s": elapsed,
        "pick_up_N": [float(r.tension["pickup"][0]) for r in results],
        "slack_off_N": [float(r.tension["slackoff"][0]) for r in results],
        "rotating_N": [float(r.tension["rotating"][0]) for r in results],
        "torque_Nm": [float(r.torque["rotating"][0]) for r in results],
    }


# --- torque_drag 0.1.1 -----------------------------------------------------------------------


def run_torque_drag(step: float, repeat: int) -> dict[str, Any]:
    import torque_drag

    md, inc, azi = trajectory(step)
    # the well_profile-style trajectory it expects: dicts with the change from the station above
    points = []
    for i in range(md.size):
        delta = ({"md": 0.0, "inc": 0.0, "azi": 0.0} if i == 0 else
                 {"md": md[i] - md[i - 1], "inc": inc[i] - inc[i - 1],
                  "azi": azi[i] - azi[i - 1]})
        points.append({"md": float(md[i]), "inc": float(inc[i]), "azi": float(azi[i]),
                       "delta": delta})
    # a scalar friction factor is silently replaced by 0.24 in 0.1.1: pass one per station
    friction = [FRICTION] * len(points)

    def sweep() -> list[Any]:
        return [torque_drag.calc(points, {"pipe": {"od": PIPE_OD_IN, "id": PIPE_ID_IN,
                                                   "shoe": float(depth)},
                                          "odAnn": HOLE_IN},
                                 densities={"rhof": MUD_SG, "rhod": STEEL_SG}, case="all",
                                 fric=friction, torque_calc=True)
                for depth in bit_depths()]

    elapsed, results = best_of(sweep, repeat)
    return {
        "time_s": elapsed,
        "pick_up_N": [r.force["hoisting"][0] * 1e3 for r in results],
        "slack_off_N": [r.force["lowering"][0] * 1e3 for r in results],
        "rotating_N": [r.force["static"][0] * 1e3 for r in results],
        "torque_Nm": [r.torque["static"][0] * 1e3 for r in results],
    }


PEERS: dict[str, Callable[[float, int], dict[str, Any]]] = {
    "welleng 0.30.0": run_welleng,
    "torque_drag 0.1.1": run_torque_drag,
}


def run(step: float, repeat: int) -> dict[str, Any]:
    results: dict[str, Any] = {"tdmon": run_tdmon(step, repeat)}
    for name, runner in PEERS.items():
        try:
            results[name] = runner(step, repeat)
        except Exception as exc:  # report precisely, keep the other results
            results[name] = {"error": f"{type(exc).__name__}: {exc}"}
    return results


def report(step: float, results: dict[str, Any]) -> str:
    tdmon = results["tdmon"]
    lines = [f"### Survey and elements every {step:g} m ({tdmon['n_elements']} elements at TD)",
             "",
             "| tool | 20 depths x (pick-up, slack-off, torque) | tdmon speed-up | "
             "pick-up at TD [kN] | slack-off at TD [kN] | rotating at TD [kN] | "
             "torque at TD [kN m] |",
             "|---|---|---|---|---|---|---|"]
    peer_times = []
    for name, result in results.items():
        if "error" in result:
            lines.append(f"| {name} | failed: {result['error']} | | | | | |")
            continue
        speedup = "" if name == "tdmon" else f"{result['time_s'] / tdmon['time_s']:.0f}x"
        if name != "tdmon":
            peer_times.append(result["time_s"])
        lines.append(
            f"| {name} | {result['time_s'] * 1e3:.1f} ms | {speedup} | "
            f"{result['pick_up_N'][-1] / 1e3:.1f} | {result['slack_off_N'][-1] / 1e3:.1f} | "
            f"{result['rotating_N'][-1] / 1e3:.1f} | {result['torque_Nm'][-1] / 1e3:.2f} |")
    lines.append("")
    for name, result in results.items():
        if name == "tdmon" or "error" in result:
            continue
        worst = {key: max(abs(p / t - 1.0) for p, t in zip(result[key], tdmon[key], strict=True)
                          if t != 0.0)
                 for key in ("pick_up_N", "slack_off_N", "rotating_N", "torque_Nm")}
        lines.append(f"{name} vs tdmon, largest relative difference over the 20 depths: "
                     + ", ".join(f"{key.rsplit('_', 1)[0]} {value:.2%}"
                                 for key, value in worst.items()) + ".")
    lines.append("")
    if peer_times:
        fastest = min(peer_times)
        lines.append(f"Speed-up over the faster peer: {fastest / tdmon['time_s']:.0f}x "
                     f"(tdmon with the well prepared once: "
                     f"{fastest / tdmon['time_prepared_s']:.0f}x).")
    lines.append(f"tdmon: {tdmon['time_prepared_s'] * 1e3:.2f} ms with a prepared WellModel; "
                 f"one single-depth pick-up evaluation of the {tdmon['n_elements']}-element "
                 f"string at TD: {tdmon['single_depth_s'] * 1e3:.3f} ms; first call "
                 f"(kernel load/compile + grid): {tdmon['first_call_s']:.2f} s.")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=5, help="timed repetitions (best kept)")
    parser.add_argument("--steps", default="1,30", help="survey/element spacings [m]")
    parser.add_argument("--json", help="write all numbers to this file")
    parser.add_argument("--fluid-only", action="store_true",
                        help="only the fluid terms' cost, without the peers")
    args = parser.parse_args()
    print(f"Python {platform.python_version()} on {platform.machine()}, "
          f"numpy {np.__version__}; best of {args.repeat} runs\n")
    everything: dict[str, Any] = {}
    for step in (float(s) for s in args.steps.split(",")):
        results = {} if args.fluid_only else run(step, args.repeat)
        results["tdmon fluid terms"] = run_fluid(step, args.repeat)
        everything[f"{step:g}"] = results
        if not args.fluid_only:
            print(report(step, {k: v for k, v in results.items() if k != "tdmon fluid terms"}))
        print(fluid_report(results["tdmon fluid terms"]), "\n")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(everything, handle, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
