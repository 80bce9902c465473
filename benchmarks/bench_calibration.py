"""The calibration's per-window work, method by method, on the windows of one replay.

A simulated session (``--hours`` of rig time, `bench_replay`'s programme: trips out and in
with connections) is replayed once through the whole pipeline, in one process; every call of
the friction estimator's per-window methods (`FrictionEstimator._update` and the steps it
runs: the window's root solve, the joint estimate, the load-limit check, the friction profile
and mu(T) filters) is kept with its arguments. Each method is then run again on all its calls,
``--repeat`` times, and the best time per call is printed; the whole replay's best of
``--replays`` beside it. The estimator's state is a value (its filters are copied before an
update), so a call can be run again on the same arguments.

The rig-state detector is timed the same way (the line ``rig-state``): every sample the
rig-state step gave `tdmon.calib.rigstate.detect` during the replay is kept with its
thresholds, and the detector is run again over all of them in order from a fresh state; the
best time per frame is printed.

To compare two trees, run it with ``PYTHONPATH`` on each, alternately, on the same session
(``--session``): only ratios taken in the same minutes mean much on a shared machine.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. .venv/bin/python benchmarks/bench_calibration.py \\
        --session /tmp/session.mcap --hours 3.3
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. .venv/bin/python benchmarks/bench_calibration.py \\
        --session /tmp/session.mcap --rig-state-only --replays 0

Not part of the test suite.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

#: the estimator's per-window methods timed (`_update` runs the others)
METHODS = ("_update", "_solve", "_joint", "_limits", "_feed_profile", "_feed_mu_t")
#: the key of the rig-state detector's calls (one per frame)
RIG_STATE = "rig-state"


def replay_once(src: Path, dst: Path) -> float:
    """One replay of ``src`` in this process [s]."""
    from bench_replay import CONFIG

    from tdmon.config.daemon import load_daemon_config
    from tdmon.replay.driver import replay

    config = load_daemon_config(CONFIG)
    started = time.perf_counter()
    asyncio.run(replay(src, config, dst, separate_writer=False))
    return time.perf_counter() - started


def kept_calls(src: Path, dst: Path) -> dict[str, list[tuple[Any, ...]]]:
    """The arguments of every call of `METHODS` during one replay of ``src``."""
    from tdmon.calib.estimator import FrictionEstimator

    calls: dict[str, list[tuple[Any, ...]]] = {name: [] for name in METHODS}
    originals = {name: getattr(FrictionEstimator, name) for name in METHODS}

    def keeping(name: str) -> Any:
        def method(*args: Any) -> Any:
            calls[name].append(args)
            return originals[name](*args)
        return method

    for name in METHODS:
        setattr(FrictionEstimator, name, keeping(name))
    try:
        with keeping_rig_samples(calls):
            replay_once(src, dst)
    finally:
        for name, original in originals.items():
            setattr(FrictionEstimator, name, original)
    return calls


@contextlib.contextmanager
def keeping_rig_samples(calls: dict[str, list[tuple[Any, ...]]]) -> Iterator[None]:
    """Keep the (sample, thresholds) of every call of the rig-state step's detector in
    ``calls["rig-state"]``."""
    from tdmon.daemon.steps import rig_state

    original = rig_state.detect
    kept = calls.setdefault(RIG_STATE, [])

    def detect(prior: Any, sample: Any, thresholds: Any) -> Any:
        kept.append((sample, thresholds))
        return original(prior, sample, thresholds)

    rig_state.detect = detect
    try:
        yield
    finally:
        rig_state.detect = original


def time_rig_state(calls: list[tuple[Any, ...]], repeat: int) -> float:
    """Best total time of the detector over the kept samples, in order, from a fresh
    state [s]."""
    from tdmon.calib.rigstate import DetectorState, detect

    best = float("inf")
    for _ in range(repeat):
        prior = DetectorState()
        started = time.perf_counter()
        for sample, thresholds in calls:
            prior, _ = detect(prior, sample, thresholds)
        best = min(best, time.perf_counter() - started)
    return best


def time_calls(name: str, calls: list[tuple[Any, ...]], repeat: int) -> float:
    """Best total time of running ``name`` on all ``calls`` [s]."""
    from tdmon.calib.estimator import FrictionEstimator
    from tdmon.errors import FitError, ModelError

    method = getattr(FrictionEstimator, name)
    best = float("inf")
    for _ in range(repeat):
        started = time.perf_counter()
        for args in calls:
            # a window the solve rejects costs what it costs in the replay
            with contextlib.suppress(FitError, ModelError):
                method(*args)
        best = min(best, time.perf_counter() - started)
    return best


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--hours", type=float, default=3.3,
                        help="rig time simulated when the session file does not exist [h]")
    parser.add_argument("--session", type=Path,
                        help="session MCAP (made here when missing; a temporary one if not given)")
    parser.add_argument("--repeat", type=int, default=9, help="runs of each method's calls")
    parser.add_argument("--replays", type=int, default=3, help="whole replays timed (0: none)")
    parser.add_argument("--rig-state-only", action="store_true",
                        help="time the rig-state detector alone, not the estimator's methods")
    args = parser.parse_args(argv)
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from bench_replay import make_session

    with tempfile.TemporaryDirectory() as folder:
        src = args.session or Path(folder) / "session.mcap"
        if not src.exists():
            make_session(src, args.hours * 3600)
        dst = Path(folder) / "replayed.mcap"
        calls = kept_calls(src, dst)
        replays = [replay_once(src, dst) for _ in range(args.replays)]
    if replays:
        print(f"replay in one process: {min(replays):.3f} s (best of {args.replays})")
    for name in METHODS:
        if not calls[name] or args.rig_state_only:
            continue
        total = time_calls(name, calls[name], args.repeat)
        print(f"{name:14s} {len(calls[name]):5d} calls  {total * 1e3:8.2f} ms  "
              f"{total / len(calls[name]) * 1e6:7.0f} us per call")
    frames = calls.get(RIG_STATE, [])
    if frames:
        total = time_rig_state(frames, args.repeat)
        print(f"{RIG_STATE:14s} {len(frames):5d} frames {total * 1e3:8.2f} ms  "
              f"{total / len(frames) * 1e6:7.1f} us per frame")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
