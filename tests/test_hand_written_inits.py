"""Value classes built once per message or frame have a hand-written ``__init__`` (fields set
through their slots' setters, cheaper than the frozen dataclass's ``object.__setattr__``):
each takes its fields in order, with the dataclass's defaults. Their behaviour as dataclasses
(frozen, compared, copied, pickled) is tested beside each class."""

from __future__ import annotations

import dataclasses
import inspect

import pytest

from tdmon.daemon.steps.monitor import ModelledLoads
from tdmon.ingest.types import RawMessage, Sample


@pytest.mark.parametrize("cls", [RawMessage, Sample, ModelledLoads])
def test_init_takes_the_fields_in_order_with_their_defaults(cls: type) -> None:
    parameters = list(inspect.signature(cls).parameters.values())
    assert [p.name for p in parameters] == [f.name for f in dataclasses.fields(cls)]
    for parameter, field in zip(parameters, dataclasses.fields(cls), strict=True):
        expected = (inspect.Parameter.empty if field.default is dataclasses.MISSING
                    else field.default)
        assert parameter.default == expected, field.name
    assert "__dict__" not in dir(cls)  # slots: nothing set beside the fields
