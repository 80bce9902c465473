"""The compiled kernels' packed arguments: `pack_well` stores every array under its own name,
`kernel_well` converts dtypes and layouts, and the entry points called by keyword give the
model's numbers (whichever kernels the model loaded: the JIT's equal them)."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from tdmon.errors import ModelError
from tdmon.model import _kernels, kernels
from tdmon.model.survey import tangent_vectors
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Well


@njit
def _fields(real, index):  # the views the loops read, by name
    well = _kernels._unpack(real, index)
    return (well.node_md, well.tangents, well.dogleg, well.curve_kind, well.run_break,
            well.element_kk, well.element_ke, well.element_ee, well.element_dtvd,
            well.component_top, well.component_weight, well.component_radius)


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
    }


def test_pack_well_stores_each_array_under_its_name() -> None:
    inputs = _distinct_inputs(6)
    stored = _fields(*_kernels.pack_well(**inputs))
    names = ("node_md", "tangents", "dogleg", "curve_kind", "run_break", "element_kk",
             "element_ke", "element_ee", "element_dtvd", "component_top", "component_weight",
             "component_radius")
    by_name = dict(zip(names, stored, strict=True))
    for name, value in inputs.items():
        assert np.array_equal(by_name[name], value), name
    assert by_name["run_break"].tolist() == inputs["run_break"].astype(int).tolist()
    kk, ke, ee, dtvd = _kernels.element_geometry(inputs["node_md"], inputs["tangents"])
    for name, expected in (("element_kk", kk), ("element_ke", ke), ("element_ee", ee),
                           ("element_dtvd", dtvd)):
        assert np.array_equal(by_name[name], expected), name


def test_kernel_well_converts_dtype_and_layout() -> None:
    inputs = _distinct_inputs(6)
    jit = kernels.Kernels("jit", _kernels, "numba's JIT")
    reference = _fields(*kernels.kernel_well(jit, **inputs))
    converted = dict(inputs)
    converted["node_md"] = np.linspace(0.0, 100.0, 11)[::2]  # same values, strided
    converted["curve_kind"] = inputs["curve_kind"].astype(np.int32)
    converted["component_top"] = [10, 100]  # a list of ints
    converted["run_break"] = inputs["run_break"].astype(np.int8)
    for got, expected in zip(_fields(*kernels.kernel_well(jit, **converted)), reference,
                             strict=True):
        assert np.array_equal(got, expected)
        assert got.dtype == expected.dtype


@pytest.mark.parametrize("method", [kernels.SOFT_STRING, kernels.AADNOY])
def test_entry_points_by_keyword_give_the_model_numbers(three_d: Well, method: int) -> None:
    model = WellModel(three_d)
    mu = model.friction(0.25)
    # pick-up, slack-off, rotating
    ops = {"bit_forces": np.zeros(3), "bit_torques": np.zeros(3),
           "axial_factors": np.array([1.0, -1.0, 0.0]), "torque_factors": np.array([0.0, 0.0, 1.0])}
    depth = 3000.0
    force, torque = _kernels.march(*model.kernel_well, method=method, mu=mu,
                                   bit_depth=depth, **ops)
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
    count = _kernels.march_profile(*model.kernel_well, method=method, mu=mu,
                                   bit_depth=depth, **ops, **out)
    assert out["out_md"][0] == depth and out["out_md"][count - 1] == model.node_md[0]
    assert np.array_equal(out["out_force"][:, count - 1], force)
    assert np.array_equal(out["out_torque"][:, count - 1], torque)
    forces, torques = _kernels.sweep(*model.kernel_well, method=method, mu_cases=mu[None, :],
                                     bit_depths=np.array([depth]), **ops)
    assert np.array_equal(forces[0, 0], force) and np.array_equal(torques[0, 0], torque)
    value, _, gradient = _kernels.march_gradient(
        *model.kernel_well, method=method, mu=mu, bit_depth=depth, bit_force=0.0,
        bit_torque=0.0, axial_factor=1.0, torque_factor=0.0, force_seed=1.0, torque_seed=0.0)
    assert value == force[0]
    assert gradient.sum() > 0.0  # more friction, more pick-up


@pytest.mark.parametrize("method", [kernels.SOFT_STRING, kernels.AADNOY])
def test_cases_marched_together_equal_marches_one_by_one(three_d: Well, method: int) -> None:
    """`march_cases`, `march_one` and `sweep` give `march`'s numbers bit for bit: the same
    steps in the same order, only interleaved across cases."""
    model = WellModel(three_d)
    rng = np.random.default_rng(7)
    cases = np.ascontiguousarray(rng.uniform(0.05, 0.45, (5, model.n_elements)))
    ops = {"bit_forces": np.array([0.0, 0.0, 0.0, -9e4]),
           "bit_torques": np.array([0.0, 0.0, 0.0, 4e3]),
           "axial_factors": np.array([1.0, -1.0, 0.0, 0.0]),
           "torque_factors": np.array([0.0, 0.0, 1.0, 1.0])}
    depths = np.array([350.0, 1234.5, 2999.0, 4100.0])
    swept_f, swept_t = _kernels.sweep(*model.kernel_well, method=method, mu_cases=cases,
                                      bit_depths=depths, **ops)
    for d, depth in enumerate(depths):
        together_f, together_t = _kernels.march_cases(*model.kernel_well, method, cases, depth,
                                                      *ops.values())
        for c in range(cases.shape[0]):
            alone_f, alone_t = _kernels.march(*model.kernel_well, method=method,
                                              mu=cases[c], bit_depth=depth, **ops)
            assert together_f[c].tolist() == alone_f.tolist()
            assert together_t[c].tolist() == alone_t.tolist()
            assert swept_f[c, d].tolist() == alone_f.tolist()
            assert swept_t[c, d].tolist() == alone_t.tolist()
            for o in range(4):
                terms = [ops[name][o] for name in ops]
                one = _kernels.march_one(*model.kernel_well, method, cases[c], depth, *terms)
                assert one == (alone_f[o], alone_t[o])


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
