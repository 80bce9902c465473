"""Benchmark of one window's joint estimate update on a 6000-element string, with the hook-load
measurement in the state (block weight, zero offset, sheave efficiency) and without.

Run: ``.venv/bin/python benchmarks/bench_joint.py [--repeat 7] [--windows 50]``

Case: the 6000 m well of `bench_backcalc.py` (1 m elements, bit at 5990 m). Timed:
`tdmon.calib.joint.update_joint` on a pick-up, a slack-off, a rotating-off-bottom (hook load
and torque: two measurements) and a static window after rotation, each from the same prior
state with the drift step of a window a minute and 28 m later, 3 iterated-EKF linearisations
per measurement (each one adjoint march: value and gradient), and a connection's in-slips
readings (`update_joint_slips`). Two states side by side in the same run: the full one of a
rig with a deadline sensor (friction, weight factor, block weight, zero offset, sheave
efficiency: five parameters) and friction with the weight factor alone (two); and one window's
back-calculation (`back_calculate_window`) for scale. Best of ``--repeat`` runs of
``--windows`` windows each; the machine is shared, so expect noise of 10-20 %. The target
(issues 12 and 28) is <= 5 ms for one window's joint estimate with the larger state.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import replace

from bench_backcalc import best_of, long_well

from tdmon.calib.backcalc import back_calculate_window
from tdmon.calib.joint import (
    JointSettings,
    JointState,
    for_rig,
    initial_joint,
    slips_measurement,
    update_joint,
    update_joint_slips,
)
from tdmon.calib.parameters import FRICTION, WEIGHT_FACTOR, EstimatedParameters
from tdmon.calib.windows import Window
from tdmon.model.hookload_sensor import HookloadSensor, SensorLocation
from tdmon.model.torque_drag import WellModel


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--windows", type=int, default=50)
    args = parser.parse_args()

    deadline = HookloadSensor(SensorLocation.DEADLINE, lines=10, efficiency=0.9615)
    model = WellModel(replace(long_well(), hookload_sensor=deadline))
    depth = 5990.0
    block = model.well.block_weight
    states = {
        "5 parameters": for_rig(JointSettings(), model.well),
        "2 parameters": JointSettings(parameters=EstimatedParameters((FRICTION, WEIGHT_FACTOR))),
    }
    print(f"elements: {model.n_elements}")
    windows: dict[str, tuple[Window, str | None]] = {}
    for state, op in (("pick_up", "pick_up"), ("slack_off", "slack_off"),
                      ("rotating_off_bottom", "rotating"), ("static", "static")):
        hook, torque = model.evaluate(op, depth, 0.27)
        hook = block + 0.96 * (hook - block)  # a string 4 % lighter than modelled
        rotating = state == "rotating_off_bottom"
        windows[state] = (Window(state, 0.0, 60.0, 30, depth, depth, depth, hook, 5e3,
                                 torque=0.96 * torque if rotating else None,
                                 torque_se=200.0 if rotating else None,
                                 rpm=6.0 if rotating else None),
                          "rotating" if state == "static" else None)
    model.evaluate_gradient("pick_up", depth, 0.2)  # compile / load the cached kernels first
    slips = tuple(slips_measurement(block + 3e3 * m, 500.0, m) for m in (-1, 0, 1))
    for label, settings in states.items():
        prior = update_joint(initial_joint(settings), model,
                             Window("pick_up", -60.0, 0.0, 30, depth + 28.0, depth + 28.0,
                                    depth + 28.0, windows["pick_up"][0].hookload, 5e3),
                             block, {}, settings)  # a state one window earlier: drift applies
        print(f"{label} ({', '.join(settings.parameters.names)}):")
        for state, (window, motion) in windows.items():
            after = update_joint(prior, model, window, block, {}, settings, last_motion=motion)
            assert after.updates > prior.updates, state

            def run(w: Window = window, m: str | None = motion, p: JointState = prior,
                    s: JointSettings = settings) -> float:
                start = time.perf_counter()
                for _ in range(args.windows):
                    update_joint(p, model, w, block, {}, s, last_motion=m)
                return (time.perf_counter() - start) / args.windows

            print(f"  joint update, {state:<20s}: {1e3 * best_of(args.repeat, run):6.2f} ms")

        def in_slips(p: JointState = prior, s: JointSettings = settings) -> float:
            start = time.perf_counter()
            for _ in range(args.windows):
                update_joint_slips(p, model, slips, 60.0, block, s)
            return (time.perf_counter() - start) / args.windows

        print(f"  joint update, {'in slips (3 readings)':<20s}: "
              f"{1e3 * best_of(args.repeat, in_slips):6.2f} ms")

    pick_up = windows["pick_up"][0]

    def back_calculation() -> float:
        start = time.perf_counter()
        for _ in range(args.windows):
            back_calculate_window(model, pick_up)
        return (time.perf_counter() - start) / args.windows

    timed: Callable[[], float] = back_calculation
    print(f"back-calculation, pick_up (for scale): {1e3 * best_of(args.repeat, timed):6.2f} ms")


if __name__ == "__main__":
    main()
