"""Start-up benchmark: commands in fresh processes, an idle daemon's memory, the first command
after set-up, and the model's fixed cost per call (issues 15 and 27).

Every command runs in a new interpreter, alternately with this tree (``this``: ``tdmon model
loads`` runs the model's loops as plain Python), this tree with ``TDMON_KERNELS=numba``
(``this_numba``: the same command on numba's kernels, loaded from its cache) and, given
``--baseline``, another copy of tdmon (e.g. ``git archive main | tar -x -C /tmp/main``), so that
all see the same load; the best of ``--repeat`` runs is kept. Project virtualenv, no peers:

    .venv/bin/python benchmarks/bench_startup.py [--baseline /tmp/main] [--repeat 5] \
        [--skip-cold] [--json out.json]

Parts (docs/benchmarks.md, "Start-up"):

- ``tdmon --help`` and ``tdmon model loads --well config/wells/aadnoy-example-7-1.toml``: wall
  time of the whole process, after ``tdmon model warmup``;
- ``tdmon run`` idle: a Zenoh peer on a free loopback port with nothing publishing, recorder
  on, Rerun off; resident memory (VmRSS) once it listens and has settled;
- first command after set-up: the package copied to a new folder (a fresh clone: no numba
  cache) with its own numba cache folder and an empty user cache folder (``XDG_CACHE_HOME``: no
  pint store), ``tdmon model warmup`` timed as the set-up step, then the first ``model loads``
  and the first ``tdmon replay`` of ``replays/trip-out-tight-spot.mcap``, against the same
  commands in another fresh copy without the warm-up (``--skip-cold`` leaves these out);
- in this process, on numba's kernels: ``WellModel.evaluate`` on 201 and 6000 elements, the
  fixed cost per call (the 201-element time less 201 times the per-element slope, and
  directly: the bit in the first element, one piece marched), and 8 friction cases marched
  together (``evaluate_cases``) against one ``evaluate`` per case; and one ``evaluate`` on 201
  elements as plain Python.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
WELL = ROOT / "config" / "wells" / "aadnoy-example-7-1.toml"
REPLAY = ROOT / "replays" / "trip-out-tight-spot.mcap"
REPLAY_CONFIG = ROOT / "config" / "daemon" / "replay-sim-trip-out.toml"
IDLE_WELL = ROOT / "replays" / "scenarios" / "wells" / "example-7-1-glydril.toml"


def _env(tree: Path, **extra: str) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(tree), **extra}


def _wall(tree: Path, args: list[str], **extra: str) -> float:
    """Wall time [s] of ``python -m tdmon ARGS`` run in ``tree`` (``-m`` puts the working
    folder first on the path, before PYTHONPATH and an editable install)."""
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "tdmon", *args], env=_env(tree, **extra), cwd=tree,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True, timeout=600)
    return time.perf_counter() - start


#: A tree and the environment its commands run with.
Variant = tuple[Path, dict[str, str]]


def _best_commands(variants: dict[str, Variant], repeat: int) -> dict[str, dict[str, float]]:
    commands = {"help": ["--help"], "model_loads": ["model", "loads", "--well", str(WELL)]}
    for tree, extra in variants.values():  # fill each tree's caches and pint store first
        _wall(tree, ["model", "warmup"], **extra)
        _wall(tree, commands["model_loads"], **extra)
    best: dict[str, dict[str, float]] = {name: {} for name in variants}
    for _ in range(repeat):
        for name, (tree, extra) in variants.items():
            for command, args in commands.items():
                seconds = _wall(tree, args, **extra)
                best[name][command] = min(best[name].get(command, np.inf), seconds)
    return best


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _idle_rss(tree: Path, folder: Path, settle: float, **extra: str) -> float:
    """VmRSS [MB] of an idle ``tdmon run`` once it listens and ``settle`` seconds passed."""
    port = _free_port()
    config = folder / f"idle-{port}.toml"
    config.write_text(
        f'prefix = "bench/idle"\nwell = "{IDLE_WELL}"\n'
        f'[sources.zenoh]\nmode = "peer"\nlisten = ["tcp/127.0.0.1:{port}"]\nconnect = []\n'
        f'scouting = false\n'
        f'[recorder]\nenabled = true\noutput = "{folder / f"rec-{port}"}"\n'
        f'[monitor]\nmu = 0.25\nband_mu = [0.1, 0.2, 0.3, 0.4]\ngrid_step = "10 m"\n'
        f'[calibration]\nenabled = true\n')
    daemon = subprocess.Popen([sys.executable, "-m", "tdmon", "run", "--config", str(config),
                               "--log-level", "warning"], env=_env(tree, **extra), cwd=tree,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if daemon.poll() is not None:
                raise RuntimeError(f"tdmon run stopped: {daemon.stderr.read().decode()[-500:]}"
                                   if daemon.stderr else "tdmon run stopped")
            with socket.socket() as sock:
                if sock.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.2)
        time.sleep(settle)
        status = Path(f"/proc/{daemon.pid}/status").read_text()
        rss_kb = next(int(line.split()[1]) for line in status.splitlines()
                      if line.startswith("VmRSS"))
        children = subprocess.run(["ps", "-o", "rss=", "--ppid", str(daemon.pid)],
                                  capture_output=True, text=True).stdout.split()
        return (rss_kb + sum(int(c) for c in children)) / 1024
    finally:
        daemon.send_signal(signal.SIGINT)
        try:
            daemon.wait(timeout=60)
        except subprocess.TimeoutExpired:
            daemon.kill()
            daemon.wait()


def _fresh_copy(tree: Path, folder: Path) -> Path:
    """The tdmon package alone, without any __pycache__ (numba's cache lives there)."""
    shutil.copytree(tree / "tdmon", folder / "tdmon",
                    ignore=shutil.ignore_patterns("__pycache__"))
    return folder


def _first_commands(tree: Path, folder: Path) -> dict[str, float]:
    """A fresh copy with the set-up's warm-up, and another without, first commands timed."""
    cache = folder / "cache"  # its own numba cache folder and user cache folder

    def fresh(name: str) -> dict[str, str]:
        return {"NUMBA_CACHE_DIR": str(cache / name / "numba"),
                "XDG_CACHE_HOME": str(cache / name / "user")}

    warmed = _fresh_copy(tree, folder / "warmed")
    cold = _fresh_copy(tree, folder / "cold")
    replay_out = folder / "replay.mcap"
    replay = ["replay", str(REPLAY), "--config", str(REPLAY_CONFIG), "--out", str(replay_out)]
    loads = ["model", "loads", "--well", str(WELL)]
    figures = {
        "setup_warmup_s": _wall(warmed, ["model", "warmup"], **fresh("w")),
        "first_model_loads_s": _wall(warmed, loads, **fresh("w")),
        "first_replay_s": _wall(warmed, replay, **fresh("w")),
        "second_replay_s": _wall(warmed, replay, **fresh("w")),
    }
    figures["cold_model_loads_s"] = _wall(cold, loads, **fresh("c"))
    shutil.rmtree(cold / "tdmon")
    cold = _fresh_copy(tree, folder / "cold2")
    figures["cold_replay_s"] = _wall(cold, replay, **fresh("c2"))
    return figures


def _per_call(function: Any, number: int, repeat: int = 7) -> float:
    return min(timeit.repeat(function, number=number, repeat=repeat)) / number


def _fixed_cost() -> dict[str, Any]:
    """The model's timings on numba's kernels, and one call on the plain Python ones."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_torque_drag import TOTAL_DEPTH, tdmon_well

    from tdmon.model.torque_drag import WellModel

    figures: dict[str, Any] = {}
    plain = WellModel(tdmon_well(30.0), engine="python")
    figures["evaluate_python_201_us"] = _per_call(
        lambda: plain.evaluate("pick_up", TOTAL_DEPTH, 0.25), 20, repeat=5) * 1e6
    models = {30.0: WellModel(tdmon_well(30.0), engine="numba"),
              1.0: WellModel(tdmon_well(1.0), engine="numba")}
    calls: dict[str, tuple[Any, int]] = {}
    for model in models.values():
        n = model.n_elements
        mu = model.friction(0.25)
        model.evaluate("pick_up", TOTAL_DEPTH, mu)
        number = 3000 if n < 1000 else 200
        # the bit in the first element: one piece marched, the rest is the call's fixed cost
        shallow = 0.5 * float(model.node_md[0] + model.node_md[1])
        calls[f"evaluate_{n}_us"] = (
            lambda m=model: m.evaluate("pick_up", TOTAL_DEPTH, 0.25), number)
        calls[f"evaluate_one_element_{n}_us"] = (
            lambda m=model, d=shallow: m.evaluate("pick_up", d, 0.25), 3000)
        calls[f"evaluate_array_{n}_us"] = (
            lambda m=model, f=mu: m.evaluate("pick_up", TOTAL_DEPTH, f), number)
    for _ in range(5):  # rounds over every call, best of each: all see the same moments
        for name, (function, number) in calls.items():
            seconds = _per_call(function, number, repeat=3)
            figures[name] = min(figures.get(name, np.inf), seconds * 1e6)
    (n1, t1), (n2, t2) = sorted((m.n_elements, figures[f"evaluate_{m.n_elements}_us"])
                                for m in models.values())
    slope = (t2 - t1) / (n2 - n1)
    figures["per_element_ns"] = slope * 1e3
    figures["fixed_cost_us"] = t1 - slope * n1
    for model in models.values():
        n = model.n_elements
        number = 3000 if n < 1000 else 200
        cases = np.ascontiguousarray(np.linspace(0.1, 0.4, 8)[:, None] * np.ones(n))
        for method in ("soft-string", "aadnoy"):
            model.evaluate_cases("pick_up", TOTAL_DEPTH, cases, method=method)

            def together(m: Any = model, me: str = method, c: Any = cases) -> None:
                m.evaluate_cases("pick_up", TOTAL_DEPTH, c, method=me)

            def alone(m: Any = model, me: str = method, c: Any = cases) -> None:
                for row in c:
                    m.evaluate("pick_up", TOTAL_DEPTH, row, method=me)

            # interleaved, best of each: both sides see the same moments of the machine's load
            best_together = best_alone = np.inf
            k = max(number // 8, 10)
            for _ in range(15):
                best_together = min(best_together, timeit.timeit(together, number=k) / k)
                best_alone = min(best_alone, timeit.timeit(alone, number=k) / k)
            figures[f"cases8_{method}_{n}_together_us"] = best_together * 1e6
            figures[f"cases8_{method}_{n}_one_by_one_us"] = best_alone * 1e6
            figures[f"cases8_{method}_{n}_speedup"] = best_alone / best_together
    return figures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--baseline", type=Path, help="another tdmon tree to run side by side")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--settle", type=float, default=5.0,
                        help="seconds the idle daemon runs before its memory is read")
    parser.add_argument("--skip-cold", action="store_true",
                        help="leave out the fresh-copy compile runs (about a minute)")
    parser.add_argument("--model-only", action="store_true",
                        help="only the in-process model timings (a few seconds)")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    if args.model_only:
        print(json.dumps({"model": _fixed_cost()}, indent=2))
        return 0
    variants: dict[str, Variant] = {"this": (ROOT, {}),
                                    "this_numba": (ROOT, {"TDMON_KERNELS": "numba"})}
    if args.baseline is not None:
        variants["baseline"] = (args.baseline.resolve(), {})
    result: dict[str, Any] = {"commands": _best_commands(variants, args.repeat)}
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        result["idle_run_rss_MB"] = {  # the daemon runs numba's kernels either way
            name: min(_idle_rss(tree, folder, args.settle, **extra) for _ in range(2))
            for name, (tree, extra) in variants.items() if name != "this_numba"}
        if not args.skip_cold:
            result["first_commands"] = _first_commands(ROOT, folder / "fresh")
    result["model"] = _fixed_cost()
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
