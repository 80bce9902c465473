"""Synthetic rig sessions with known friction, generated from the torque-and-drag model.

Trips made here, small and fast, for the claims that need many sessions or a particular truth:
stands pulled or run at a set speed with accelerations, a break-over peak at the start of each
pull, a static hang, connections in slips while the empty block travels back; hook load =
model + block weight + noise. Every sample carries the state the generator put the rig in, the
truth the detector is scored against. The simulator's scenario files (tdmon/replay) run through
the daemon's steps in tests/replay/test_scenario_steps.py.

Helpers are exposed as fixtures (a module named conftest cannot be imported safely when several
test folders have one).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from numpy.typing import NDArray

from tdmon.calib.rigstate import DetectorState, RigSample, RigStateThresholds, detect
from tdmon.calib.windows import Window, WindowAccumulator, WindowSettings, add_sample, close
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.survey import minimum_curvature
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Fluid, HoleSection, Well

Array = NDArray[np.float64]

KOP = 1500.0
END_OF_BUILD = KOP + 500.0 * math.radians(60.0)
TOTAL_DEPTH = END_OF_BUILD + 2200.0
BLOCK_WEIGHT = 400e3
# geothermal profile of docs/reference-values.md §2: 15.3 degC at surface, 85.5 degC at 3033 m TVD
SURFACE_TEMPERATURE = 15.3
GEOTHERMAL_GRADIENT = (85.5 - 15.3) / 3033.0


def example_71(shoe: float | None = None, block_weight: float = BLOCK_WEIGHT,
               element_length: float = 10.0) -> Well:
    """Example 7.1 (Aadnoy) with a travelling block; optionally cased down to ``shoe`` [m]."""
    survey = minimum_curvature([0.0, KOP, END_OF_BUILD, TOTAL_DEPTH], [0.0, 0.0, 60.0, 60.0],
                               [0.0, 0.0, 0.0, 0.0])
    string = DrillString((
        StringComponent("BHA", 200.0, 0.16, 0.07, buoyed_weight=3000.0),
        StringComponent("drill pipe", TOTAL_DEPTH - 200.0, 0.127, 0.108, buoyed_weight=300.0,
                        tool_joint_diameter=0.16),
    ))
    if shoe is None:
        sections: tuple[HoleSection, ...] = (HoleSection(0.0, TOTAL_DEPTH, 0.2159, "open"),)
    else:
        sections = (HoleSection(0.0, shoe, 0.2245, "cased"),
                    HoleSection(shoe, TOTAL_DEPTH, 0.2159, "open"))
    return Well(survey=survey, string=string, sections=sections, fluid=Fluid(1200.0),
                block_weight=block_weight, element_length=element_length, name="Ex 7.1 + block")


def element_temperature(model: WellModel) -> Array:
    """Geothermal temperature at each element's mid TVD [degC]."""
    tvd = 0.5 * (model.grid.tvd[:-1] + model.grid.tvd[1:])
    return np.asarray(SURFACE_TEMPERATURE + GEOTHERMAL_GRADIENT * tvd)


@dataclass(frozen=True)
class Session:
    """A synthetic record at 1 Hz; ``truth`` is the state the generator put the rig in."""

    t: Array
    hookload: Array
    bit_depth: Array
    block_position: Array
    rpm: Array
    flow: Array
    torque: Array
    hole_depth: Array
    truth: NDArray[np.str_]


class _Curves:
    """Model loads tabulated every metre of bit depth (np.interp between)."""

    def __init__(self, model: WellModel, mu: Array, top: float, bottom: float) -> None:
        self.depths = np.arange(math.floor(top) - 1.0, math.ceil(bottom) + 2.0, 1.0)
        self.depths = self.depths[(self.depths > 0) & (self.depths <= model.grid.md[-1])]
        ops = ("pick_up", "slack_off", "static", "rotating")
        table = {op: [model.evaluate(op, d, mu) for d in self.depths] for op in ops}
        self.hookload = {op: np.array([v[0] for v in table[op]]) for op in ops}
        self.torque = np.array([v[1] for v in table["rotating"]])

    def __call__(self, op: str, depth: float) -> float:
        return float(np.interp(depth, self.depths, self.hookload[op]))


def make_trip(model: WellModel, mu: Array, *, start: float, end: float, stand: float = 28.0,  # noqa: C901  (complex today; simplify when next touched)
              speed: float = 0.5, noise: float = 0.01, seed: int = 1,
              rotate_every: int = 0, t0: float = 1.6e9) -> Session:
    """A trip from ``start`` to ``end`` bit depth [m] by stands, out when end < start.

    Per stand: 40 s in slips with the empty block travelling back, 3 s to take the weight,
    a 2 s break-over peak (+4 % on a pull), accelerate over 4 s, steady at ``speed``,
    decelerate over 4 s, hang 10 s. Every ``rotate_every`` stands a 60 s rotating-off-bottom
    period is added before the slips are set (0: never).
    """
    rng = np.random.default_rng(seed)
    out = end < start
    moving = "pick_up" if out else "slack_off"
    curves = _Curves(model, mu, min(start, end), max(start, end))
    bw = model.well.block_weight
    rows: list[tuple[float, float, float, float, float, float, str]] = []
    depth = start
    block = 1.0 if out else 1.0 + stand

    def add(hook: float, state: str, rpm: float = 0.0, torque: float = 0.0) -> None:
        rows.append((hook, depth, block, rpm, torque, 0.0, state))

    count = 0
    while (depth - end > 1e-6) if out else (end - depth > 1e-6):
        length = min(stand, abs(depth - end))
        # connection: in slips, the empty block goes back to where the next stand starts
        target = 1.0 if out else 1.0 + length
        for k in range(40):
            block += (target - block) / max(1, 40 - k) if k >= 10 else 0.0
            add(bw, "in_slips")
        for k in range(3):  # taking the weight off the slips
            add(bw + (k + 1) / 3 * (curves("static", depth) - bw), "static")
        ramp = 4.0
        steady_time = max(0.0, (length - speed * ramp) / speed)
        total = 2 * ramp + steady_time
        steps = round(total)
        travelled = 0.0
        for k in range(steps):
            tk = k + 1.0
            v = speed * min(1.0, tk / ramp, (total - tk + 1.0) / ramp)
            step = min(v, length - travelled)
            travelled += step
            depth = depth - step if out else depth + step
            block = block + step if out else block - step
            hook = curves(moving, depth)
            if k < 2 and out:
                hook *= 1.04  # break-over: static friction and gel strength
            add(hook, moving if v > 0.06 else "static")
        if travelled < length:
            depth = (depth - (length - travelled)) if out else depth + (length - travelled)
        for _ in range(10):
            add(curves("static", depth), "static")
        count += 1
        if rotate_every and count % rotate_every == 0:
            for k in range(60):
                rpm = 120.0 * 2 * math.pi / 60 * min(1.0, (k + 1) / 5)
                torque = float(np.interp(depth, curves.depths, curves.torque))
                add(curves("rotating", depth), "rotating_off_bottom" if k >= 1 else "static",
                    rpm, torque * min(1.0, (k + 1) / 5))
    for _ in range(40):
        add(bw, "in_slips")
    n = len(rows)
    hook_values = np.array([r[0] for r in rows])
    torque_values = np.array([r[4] for r in rows])
    return Session(
        t=t0 + np.arange(n, dtype=np.float64),
        hookload=hook_values * (1.0 + noise * rng.standard_normal(n)),
        bit_depth=np.array([r[1] for r in rows]),
        block_position=np.array([r[2] for r in rows]),
        rpm=np.array([r[3] for r in rows]),
        flow=np.zeros(n),
        torque=(torque_values * (1.0 + noise * rng.standard_normal(n))
                + 50.0 * rng.standard_normal(n)),
        hole_depth=np.full(n, TOTAL_DEPTH),
        truth=np.array([r[6] for r in rows]),
    )


@pytest.fixture(scope="session")
def well_open() -> Well:
    return example_71()


@pytest.fixture(scope="session")
def model_open(well_open: Well) -> WellModel:
    return WellModel(well_open)


@pytest.fixture(scope="session")
def model_cased() -> WellModel:
    return WellModel(example_71(shoe=3000.0))


@pytest.fixture(scope="session")
def trip() -> Callable[..., Session]:
    return make_trip


@pytest.fixture(scope="session")
def temperatures() -> Callable[[WellModel], Array]:
    return element_temperature


@pytest.fixture(scope="session")
def make_well() -> Callable[..., Well]:
    return example_71


def session_windows(session: Session, thresholds: RigStateThresholds,
                    settings: WindowSettings) -> tuple[list[str], list[Window]]:
    """Run the detector and the window builder over a session: states and closed windows."""
    prior = DetectorState()
    acc = WindowAccumulator()
    states: list[str] = []
    windows: list[Window] = []
    for i in range(session.t.size):
        sample = RigSample(float(session.t[i]), float(session.hookload[i]),
                           float(session.bit_depth[i]), float(session.block_position[i]),
                           float(session.rpm[i]), float(session.flow[i]), None,
                           float(session.hole_depth[i]), float(session.torque[i]))
        prior, detection = detect(prior, sample, thresholds)
        states.append(detection.state)
        acc, window = add_sample(acc, sample, detection, settings)
        if window is not None:
            windows.append(window)
    acc, window = close(acc, settings)
    if window is not None:
        windows.append(window)
    return states, windows


@pytest.fixture(scope="session")
def windows_of() -> Callable[..., tuple[list[str], list[Window]]]:
    def run(session: Session, thresholds: RigStateThresholds | None = None,
            settings: WindowSettings | None = None) -> tuple[list[str], list[Window]]:
        return session_windows(session, thresholds or RigStateThresholds(block_weight=BLOCK_WEIGHT),
                               settings or WindowSettings(min_samples=5))

    return run


