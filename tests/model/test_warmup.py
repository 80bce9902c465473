"""`tdmon model warmup` prepares what the model's callers use: on numba's JIT the real calls add
no signature after it (each new one would be compiled in the first real command), and the
ahead-of-time module holds exactly those signatures (it converts nothing: a call with other
types would read its arrays wrongly)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from numba.core.sigutils import normalize_signature

from tdmon.calib.backcalc import back_calculate
from tdmon.model import _kernels, aot, kernels, warmup
from tdmon.model.broomstick import broomstick_from_model
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Well


def _signatures() -> list[list[object]]:
    return [list(getattr(_kernels, name).signatures) for name in kernels.ENTRY_POINTS]


@pytest.fixture
def jit(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """New `WellModel`s run numba's JIT kernels."""
    monkeypatch.setenv(kernels.ENVIRONMENT, "jit")
    kernels.forget()
    yield
    monkeypatch.undo()
    kernels.forget()


@pytest.mark.usefixtures("jit")
def test_the_model_calls_only_signatures_the_warmup_compiled(three_d: Well) -> None:
    warmup.compile_kernels()
    compiled = _signatures()
    assert all(compiled)  # each entry point has machine code
    model = WellModel(three_d)  # a well file's shapes: sections' friction, two components
    assert model.kernels.kind == "jit"
    for method in ("soft-string", "aadnoy"):
        model.evaluate("pick_up", 3000.0, None, method=method)
        model.evaluate("rotating", 3000, 0.3, method=method, psi=0.2)
        model.evaluate("on_bottom", 3000.0, model.friction(0.2), method=method, wob=9e4,
                       bit_torque=3e3)
        model.evaluate_cases("slack_off", 3000.0, np.full((3, model.n_elements), 0.2),
                             method=method)
        model.evaluate_gradient("rotating", 3000.0, 0.25, quantity_index=1, method=method)
        model.loads(3000.0, None, method=method)
        broomstick_from_model(model, np.arange(500.0, 3001.0, 500.0), [0.1, 0.2],
                              method=method)
        measured = model.evaluate("pick_up", 2500.0, 0.22, method=method)[0]
        back_calculate(model, "pick_up", 2500.0, measured, 1e3, method=method)
    assert _signatures() == compiled
    # one signature per entry point, and it is the ahead-of-time module's
    assert set(aot.SIGNATURES) == set(kernels.ENTRY_POINTS)
    for name in kernels.ENTRY_POINTS:
        dispatcher = getattr(_kernels, name)
        (signature,) = dispatcher.nopython_signatures
        arguments, returned = normalize_signature(aot.SIGNATURES[name])
        assert (signature.args, signature.return_type) == (arguments, returned), name
