"""`tdmon model warmup` compiles what the model's callers use: after it, the real calls add no
signature to any kernel (each new signature would be compiled in the first real command)."""

from __future__ import annotations

import numpy as np

from tdmon.calib.backcalc import back_calculate
from tdmon.model import warmup
from tdmon.model.broomstick import broomstick_from_model
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Well


def _signatures() -> list[list[object]]:
    return [list(dispatcher.signatures) for dispatcher in warmup.ENTRY_POINTS]


def test_the_model_calls_only_signatures_the_warmup_compiled(three_d: Well) -> None:
    warmup.compile_kernels()
    compiled = _signatures()
    assert all(compiled)  # each entry point has machine code
    model = WellModel(three_d)  # a well file's shapes: sections' friction, two components
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
