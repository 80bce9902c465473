"""Ahead-of-time kernels built for several processor targets against numba's JIT, in one run.

Builds the model's entry points (`tdmon.model.aot.SIGNATURES`) with numba's pycc for each
``--targets`` value (pycc's ``target_cpu``: "" is the architecture's generic processor, "host"
this processor's own model, or an LLVM name such as ``x86-64-v3``) into a scratch folder, then
times, interleaved and best of each, on the `bench_torque_drag.py` well at 1 m elements (6000
elements, bit at 6000 m): one pick-up march (`march_one`) and 8 friction cases in one march
(`march_cases`), soft string and Aadnoy. Every build's numbers are checked against the JIT's.
Project virtualenv (about 20 s per build):

    .venv/bin/python benchmarks/bench_aot_targets.py [--targets ,x86-64-v3,x86-64-v4,host]

docs/benchmarks.md ("Kernels compiled ahead of time") has the figures that chose
`tdmon.model.kernels.target_cpu`.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import timeit
import warnings
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _build(target: str, folder: Path, index: int) -> Any:
    from numba.pycc import CC

    from tdmon.model import _kernels, aot, kernels

    name = f"bench_kernels_{index}"
    compiler = CC(name)
    compiler.output_dir = str(folder)
    compiler.verbose = False
    compiler.target_cpu = target
    for entry, signature in aot.SIGNATURES.items():
        compiler.export(entry, signature)(getattr(_kernels, entry).py_func)
    compiler.compile()
    return kernels.load_aot(folder / compiler.output_file)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--targets", default=",x86-64-v3,x86-64-v4,host",
                        help="comma-separated pycc target_cpu values ('' = generic)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_torque_drag import TOTAL_DEPTH, tdmon_well

    from tdmon.model import _kernels, kernels
    from tdmon.model.torque_drag import WellModel

    modules: dict[str, Any] = {"jit": _kernels}
    with tempfile.TemporaryDirectory() as scratch, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pycc is pending deprecation in numba
        for index, target in enumerate(args.targets.split(",")):
            modules[f"aot {target or 'generic'}"] = _build(target, Path(scratch), index)
        model = WellModel(tdmon_well(1.0))
        real, integer = model.kernel_well
        n = model.n_elements
        mu = np.full(n, 0.25)
        cases = np.ascontiguousarray(np.linspace(0.1, 0.4, 8)[:, None] * np.ones(n))
        zero, one = np.zeros(1), np.ones(1)
        best: dict[str, dict[str, float]] = {label: {} for label in modules}
        for method in (kernels.SOFT_STRING, kernels.AADNOY):
            expected = _kernels.march_cases(real, integer, method, cases, TOTAL_DEPTH, zero,
                                            zero, one, zero)
            for label, module in modules.items():
                got = module.march_cases(real, integer, method, cases, TOTAL_DEPTH, zero, zero,
                                         one, zero)
                assert all(np.array_equal(a, b) for a, b in zip(got, expected, strict=True)), label
        for _ in range(args.rounds):  # rounds over every build: all see the same moments
            for label, module in modules.items():
                for method, method_name in ((kernels.SOFT_STRING, "soft-string"),
                                            (kernels.AADNOY, "aadnoy")):
                    calls = {
                        f"one_{method_name}_us": lambda m=module, k=method: m.march_one(
                            real, integer, k, mu, TOTAL_DEPTH, 0.0, 0.0, 1.0, 0.0),
                        f"cases8_{method_name}_us": lambda m=module, k=method: m.march_cases(
                            real, integer, k, cases, TOTAL_DEPTH, zero, zero, one, zero),
                    }
                    for name, call in calls.items():
                        seconds = min(timeit.repeat(call, number=30, repeat=3)) / 30
                        best[label][name] = min(best[label].get(name, np.inf), seconds * 1e6)
    result = {"target_cpu_here": kernels.target_cpu(), "best_us": best}
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
