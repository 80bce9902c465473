"""The element loops and their two engines: numba's compiled functions and the same functions as
plain Python give every model call the same numbers bit for bit; `pack_well` stores every array
under its own name, `kernel_well` converts dtypes and layouts, the entry points called by keyword
give the model's numbers, and several cases marched together equal marches one by one."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tdmon.errors import ModelError
from tdmon.model import _kernels, kernels
from tdmon.model.broomstick import broomstick_from_model
from tdmon.model.fluid_terms import NO_FLUID, FluidTerms
from tdmon.model.string import DrillString
from tdmon.model.survey import tangent_vectors
from tdmon.model.torque_drag import WellModel, torque_drag
from tdmon.model.well import Well

ROOT = Path(__file__).resolve().parents[2]

_FIELDS = ("node_md", "tangents", "dogleg", "curve_kind", "run_break", "element_kk",
           "element_ke", "element_ee", "element_dtvd", "component_top", "component_weight",
           "component_radius", "component_outside_sensitivity", "component_inside_sensitivity")


def _fields(packed: kernels.KernelWell) -> dict[str, np.ndarray]:
    """The views the loops read, by name (the plain `_unpack` reads either engine's buffers)."""
    return dict(zip(_FIELDS, _kernels._unpack(*packed), strict=True))


def _distinct_inputs(n_nodes: int) -> dict[str, np.ndarray]:
    """Arrays that differ from each other everywhere, so a field filled from the wrong one
    shows."""
    md = np.linspace(0.0, 100.0, n_nodes)
    inclination = np.linspace(0.0, 0.5, n_nodes)
    return {
        "node_md": md,
        "tangents": np.ascontiguousarray(tangent_vectors(inclination, 0.3 * inclination)),
        "dogleg": np.arange(1.0, n_nodes) * 1e-3,
        "curve_kind": np.arange(n_nodes - 1, dtype=np.int64) % 3,
        "run_break": np.arange(n_nodes) % 2 == 0,
        "component_top": np.array([10.0, 100.0]),
        "component_weight": np.array([3000.0, 300.0]),
        "component_radius": np.array([0.08, 0.0635]),
        "component_outside_sensitivity": np.array([-0.2, -0.12]),
        "component_inside_sensitivity": np.array([0.04, 0.09]),
    }


@pytest.mark.parametrize("engine", kernels.ENGINES)
def test_pack_well_stores_each_array_under_its_name(engine: str) -> None:
    inputs = _distinct_inputs(6)
    loaded = kernels.load(engine)
    by_name = _fields(kernels.KernelWell(*loaded.module.pack_well(**inputs)))
    for name, value in inputs.items():
        assert np.array_equal(by_name[name], value), name
    assert by_name["run_break"].tolist() == inputs["run_break"].astype(int).tolist()
    kk, ke, ee, dtvd = _kernels.element_geometry(inputs["node_md"], inputs["tangents"])
    for name, expected in (("element_kk", kk), ("element_ke", ke), ("element_ee", ee),
                           ("element_dtvd", dtvd)):
        assert np.array_equal(by_name[name], expected), name
    assert kk[0] > 0.0 and dtvd[0] > 0.0  # a bent, descending element


def test_kernel_well_converts_dtype_and_layout() -> None:
    inputs = _distinct_inputs(6)
    numba = kernels.load("numba")
    reference = _fields(kernels.kernel_well(numba, **inputs))
    converted = dict(inputs)
    converted["node_md"] = np.linspace(0.0, 100.0, 11)[::2]  # same values, strided
    converted["curve_kind"] = inputs["curve_kind"].astype(np.int32)
    converted["component_top"] = [10, 100]  # a list of ints
    converted["run_break"] = inputs["run_break"].astype(np.int8)
    got = _fields(kernels.kernel_well(numba, **converted))
    for name, expected in reference.items():
        assert np.array_equal(got[name], expected), name
        assert got[name].dtype == expected.dtype, name


def _everything(model: WellModel, method: str) -> list[np.ndarray]:
    """Every number the model's calls return, flattened, one array per call."""
    cases = np.stack([model.friction(mu) for mu in (0.0, 0.17, 0.41)])
    cases[1, 40:90] = 0.6
    out: list[np.ndarray] = []
    for depth in (350.0, 1777.7, 3000.0):
        for operation, extra in (("pick_up", {}), ("slack_off", {}), ("rotating", {}),
                                 ("on_bottom", {"wob": 9e4, "bit_torque": 3e3}),
                                 ("pick_up", {"psi": 0.3})):
            out.append(np.array(model.evaluate(operation, depth, 0.23, method=method, **extra)))
            out.append(np.concatenate(model.evaluate_cases(operation, depth, cases,
                                                           method=method, **extra)))
        for operation, index in (("rotating", 0), ("rotating", 1), ("slack_off", 0)):
            value, gradient = model.evaluate_gradient(operation, depth, cases[1],
                                                      quantity_index=index, method=method)
            out.append(np.append(gradient, value))
        loads = model.loads(depth, None, method=method)
        out.extend([loads.md, *loads.axial_force.values(), *loads.torque.values(),
                    loads.component.astype(float)])
    broom = broomstick_from_model(model, [500.0, 2000.0, 3000.0], [0.1, 0.3], method=method)
    out.extend([*broom.hookload.values(), *broom.surface_torque.values()])
    return out


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
def test_numba_and_plain_python_give_the_same_numbers(
        three_d: Well, example_71: Well, method: str) -> None:
    for well in (three_d, example_71):
        compiled = WellModel(well, engine="numba")
        plain = WellModel(well, engine="python")
        assert (compiled.kernels.engine, plain.kernels.engine) == ("numba", "python")
        assert plain.kernels.module is _kernels
        assert np.array_equal(compiled.kernel_well.real, plain.kernel_well.real)
        assert np.array_equal(compiled.kernel_well.integer, plain.kernel_well.integer)
        got, expected = _everything(compiled, method), _everything(plain, method)
        assert len(got) == len(expected) > 50
        for one, other in zip(got, expected, strict=True):
            assert one.tolist() == other.tolist()  # bit for bit


def test_the_engine_comes_from_the_argument_or_the_environment(
        three_d: Well, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(kernels.ENVIRONMENT, raising=False)
    assert kernels.default_engine() == "numba"
    monkeypatch.setenv(kernels.ENVIRONMENT, " Python ")
    assert WellModel(three_d).kernels.engine == "python"
    assert WellModel(three_d, engine="numba").kernels.engine == "numba"
    loads = torque_drag(three_d, 2000.0, 0.2)
    assert loads.hookload["pick_up"] == torque_drag(three_d, 2000.0, 0.2,
                                                    engine="numba").hookload["pick_up"]
    monkeypatch.setenv(kernels.ENVIRONMENT, "aot")  # the choice before pycc was dropped
    with pytest.raises(ModelError, match="TDMON_KERNELS='aot'"):
        WellModel(three_d)
    with pytest.raises(ModelError, match="unknown kernels engine 'jit'"):
        WellModel(three_d, engine="jit")


def test_the_plain_python_engine_imports_no_numba() -> None:
    """`tdmon model loads` runs the loops as plain Python: numba is not even imported."""
    script = (
        "import json, sys\n"
        "from tdmon.model.torque_drag import torque_drag\n"
        "sys.path.insert(0, 'tests/model')\n"
        "from conftest import example_71_well\n"
        "loads = torque_drag(example_71_well(), 4000.0, 0.15, engine='python')\n"
        "print(json.dumps([loads.hookload['pick_up'], sorted(sys.modules)]))\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=ROOT, timeout=120,
                          check=True)
    pick_up, modules = json.loads(done.stdout.strip().splitlines()[-1])
    assert 1.3e6 < pick_up < 1.6e6  # Example 7.1 near TD, mu 0.15
    assert "tdmon.model._kernels" in modules
    assert [m for m in modules if m.split(".")[0] in ("numba", "llvmlite")] == []


@pytest.mark.parametrize("method", [kernels.SOFT_STRING, kernels.AADNOY])
def test_entry_points_by_keyword_give_the_model_numbers(three_d: Well, method: int) -> None:
    model = WellModel(three_d, engine="numba")
    loops = model.kernels.module
    mu = model.friction(0.25)
    # pick-up, slack-off, rotating
    ops = {"bit_forces": np.zeros(3), "bit_torques": np.zeros(3),
           "axial_factors": np.array([1.0, -1.0, 0.0]), "torque_factors": np.array([0.0, 0.0, 1.0])}
    depth = 3000.0
    forces, torques = loops.march_cases(*model.kernel_well, method=method,
                                        mu_cases=mu[None, :], bit_depth=depth, **ops,
                                        fluid=NO_FLUID)
    force, torque = forces[0], torques[0]
    name = "soft-string" if method == kernels.SOFT_STRING else "aadnoy"
    for i, operation in enumerate(("pick_up", "slack_off", "rotating")):
        hookload, surface_torque = model.evaluate(operation, depth, mu, method=name)
        assert force[i] + three_d.block_weight == hookload
        assert torque[i] == surface_torque
    assert force[0] > force[2] > force[1]  # friction opposes the motion
    size = model.n_elements + len(three_d.string.components) + 2
    out = {"out_md": np.empty(size), "out_force": np.empty((3, size)),
           "out_torque": np.empty((3, size)), "out_comp": np.empty(size, dtype=np.int64),
           "out_tan": np.empty((size, 3))}
    count = loops.march_profile(*model.kernel_well, method=method, mu=mu,
                                bit_depth=depth, **ops, fluid=NO_FLUID, **out)
    assert out["out_md"][0] == depth and out["out_md"][count - 1] == model.node_md[0]
    assert np.array_equal(out["out_force"][:, count - 1], force)
    assert np.array_equal(out["out_torque"][:, count - 1], torque)
    swept_forces, swept_torques = loops.sweep(*model.kernel_well, method=method,
                                              mu_cases=mu[None, :],
                                              bit_depths=np.array([depth]), **ops)
    assert np.array_equal(swept_forces[0, 0], force)
    assert np.array_equal(swept_torques[0, 0], torque)
    value, _, gradient = loops.march_gradient(
        *model.kernel_well, method=method, mu=mu, bit_depth=depth, bit_force=0.0,
        bit_torque=0.0, axial_factor=1.0, torque_factor=0.0, fluid=NO_FLUID, force_seed=1.0,
        torque_seed=0.0)
    assert value == force[0]
    assert gradient.sum() > 0.0  # more friction, more pick-up


@pytest.mark.parametrize("method", [kernels.SOFT_STRING, kernels.AADNOY])
def test_cases_marched_together_equal_marches_one_by_one(three_d: Well, method: int) -> None:
    """`march_cases` of several cases, `march_one` and `sweep` give the numbers of one case
    marched alone bit for bit: the same steps in the same order, only interleaved across
    cases."""
    model = WellModel(three_d, engine="numba")
    loops = model.kernels.module
    rng = np.random.default_rng(7)
    cases = np.ascontiguousarray(rng.uniform(0.05, 0.45, (5, model.n_elements)))
    ops = {"bit_forces": np.array([0.0, 0.0, 0.0, -9e4]),
           "bit_torques": np.array([0.0, 0.0, 0.0, 4e3]),
           "axial_factors": np.array([1.0, -1.0, 0.0, 0.0]),
           "torque_factors": np.array([0.0, 0.0, 1.0, 1.0])}
    depths = np.array([350.0, 1234.5, 2999.0, 4100.0])
    swept_f, swept_t = loops.sweep(*model.kernel_well, method=method, mu_cases=cases,
                                   bit_depths=depths, **ops)
    for d, depth in enumerate(depths):
        together_f, together_t = loops.march_cases(*model.kernel_well, method, cases, depth,
                                                   *ops.values(), NO_FLUID)
        for c in range(cases.shape[0]):
            alone_f, alone_t = loops.march_cases(*model.kernel_well, method, cases[c:c + 1],
                                                 depth, *ops.values(), NO_FLUID)
            assert together_f[c].tolist() == alone_f[0].tolist()
            assert together_t[c].tolist() == alone_t[0].tolist()
            assert swept_f[c, d].tolist() == alone_f[0].tolist()
            assert swept_t[c, d].tolist() == alone_t[0].tolist()
            for o in range(4):
                terms = [ops[name][o] for name in ops]
                one = loops.march_one(*model.kernel_well, method, cases[c], depth, *terms,
                                      NO_FLUID)
                assert one == (alone_f[0, o], alone_t[0, o])
    assert len({tuple(row) for row in together_f.tolist()}) == cases.shape[0]  # cases differ


def test_evaluate_cases_equals_evaluate(three_d: Well) -> None:
    model = WellModel(three_d)
    cases = np.stack([model.friction(mu) for mu in (0.0, 0.1, 0.37)])
    cases[2, :50] = 0.6
    for operation in ("pick_up", "slack_off", "rotating"):
        hookloads, torques = model.evaluate_cases(operation, 2500.0, cases, method="aadnoy")
        for c in range(3):
            assert (hookloads[c], torques[c]) == model.evaluate(operation, 2500.0, cases[c],
                                                                method="aadnoy")
    with pytest.raises(ModelError, match="finite and >= 0"):
        model.evaluate_cases("pick_up", 2500.0, np.where(cases > 0.5, np.nan, cases))
    with pytest.raises(ModelError, match="n_cases"):
        model.evaluate_cases("pick_up", 2500.0, cases[0])


def _fluid_everything(model: WellModel, method: str) -> list[np.ndarray]:
    """Every call with fluid terms: random axial forces per element and operation, a pill
    inside and a heavier annulus, a jets' force at the bit."""
    rng = np.random.default_rng(3)
    n = model.n_elements
    outside = 1300.0 + rng.uniform(0.0, 200.0, n)
    inside = np.where(np.arange(n) % 50 < 20, 1800.0, 1300.0)
    terms = {op: FluidTerms(axial=rng.normal(0.0, 20.0, n), bit_force=-2500.0,
                            outside_density=outside, inside_density=inside)
             for op in ("pick_up", "slack_off", "rotating")}
    cases = np.stack([model.friction(mu) for mu in (0.1, 0.3)])
    out: list[np.ndarray] = []
    for depth in (777.0, 2999.0):
        for operation, fluid in terms.items():
            out.append(np.array(model.evaluate(operation, depth, 0.23, method=method,
                                               fluid=fluid)))
            out.append(np.concatenate(model.evaluate_cases(operation, depth, cases,
                                                           method=method, fluid=fluid)))
            value, gradient = model.evaluate_gradient(operation, depth, cases[1],
                                                      method=method, fluid=fluid)
            out.append(np.append(gradient, value))
        loads = model.loads(depth, 0.23, method=method, operations=list(terms), fluid=terms)
        out.extend([*loads.axial_force.values(), *loads.torque.values()])
    return out


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
def test_the_engines_agree_with_fluid_terms(three_d: Well, method: str) -> None:
    components = tuple(replace(c, buoyed_weight=None, weight_in_air=1.2 * c.buoyed_weight)
                       for c in three_d.string.components)
    well = replace(three_d, string=DrillString(components))
    compiled, plain = WellModel(well, engine="numba"), WellModel(well, engine="python")
    got, expected = _fluid_everything(compiled, method), _fluid_everything(plain, method)
    assert len(got) == len(expected) == 30
    for one, other in zip(got, expected, strict=True):
        assert one.tolist() == other.tolist()  # bit for bit
    without = compiled.evaluate("pick_up", 2999.0, 0.23, method=method)
    assert got[6][0] != without[0]  # the terms did something
