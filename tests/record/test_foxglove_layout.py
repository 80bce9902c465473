"""The Foxglove layout beside the Rerun blueprint (config/foxglove/tdmon-layout.json): the
file is what `tdmon.record.foxglove_layout` makes of the estimated parameters' declaration,
valid JSON of Foxglove's layout shape, every panel placed once, and every message path it plots
resolving to a number (or the rig state's text) in messages the daemon records."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from tdmon.calib.joint import JointSettings, initial_joint, joint_fields
from tdmon.calib.parameters import JOINT_PARAMETERS
from tdmon.messages import estimate_message
from tdmon.record.foxglove_layout import layout, layout_text
from tdmon.record.reader import RecordedMessage
from tdmon.record.schemas import TOPIC_SCHEMAS
from tdmon.vocabulary import EstimateKind, Operation

LAYOUT = Path(__file__).resolve().parents[2] / "config" / "foxglove" / "tdmon-layout.json"
_PATH = re.compile(r"(?P<topic>/[\w/]+)(?P<filters>(\{\w+==\"\w+\"\})*)(?P<fields>(\.\w+)*)")


def _leaves(node: Any) -> Iterator[str]:
    if isinstance(node, str):
        yield node
    else:
        assert set(node) >= {"direction", "first", "second"}
        assert node["direction"] in ("row", "column")
        yield from _leaves(node["first"])
        yield from _leaves(node["second"])


def _resolve(path: str, messages: list[RecordedMessage]) -> list[Any]:
    match = _PATH.fullmatch(path)
    assert match, f"not a message path: {path}"
    filters = re.findall(r"\{(\w+)==\"(\w+)\"\}", match["filters"])
    fields = [f for f in match["fields"].split(".") if f]
    values = []
    for topic, _, message in messages:
        if topic != match["topic"] or any(str(message.get(k)) != v for k, v in filters):
            continue
        value: Any = message
        for name in fields:
            value = value.get(name) if isinstance(value, dict) else None
        values.append(value)
    return values


def _joint_estimate() -> RecordedMessage:
    """A joint estimate as the estimator makes it (its prior state), with every declared
    parameter (a deadline sensor's rig)."""
    settings = JointSettings(parameters=JOINT_PARAMETERS)
    fields = joint_fields(initial_joint(settings), settings)
    message = estimate_message(1.7e9, EstimateKind.JOINT, Operation.PICK_UP, fields.pop("mu"),
                               fields.pop("mu_std"), bit_depth_m=2400.0, **fields)
    return RecordedMessage("/tdmon/estimate", 1_700_000_000_000_000_000, message)


def test_the_file_is_made_from_the_declaration() -> None:
    # written again with: python -m tdmon.record.foxglove_layout config/foxglove/...
    assert LAYOUT.read_text() == layout_text()
    panels = layout()["configById"]
    joint = [p["value"] for p in panels["Plot!friction"]["paths"] if '"joint"' in p["value"]]
    assert joint == ['/tdmon/estimate{kind=="joint"}.mu']
    for parameter in JOINT_PARAMETERS.others:
        [path] = panels[f"Plot!joint_{parameter.name}"]["paths"]
        assert path["value"] == f'/tdmon/estimate{{kind=="joint"}}.{parameter.name}'
    assert panels["Plot!joint_weight_factor"]["title"].startswith("Weight factor [-]")


def test_layout_panels_and_paths(stream: list[RecordedMessage]) -> None:
    stream = [*stream, _joint_estimate()]
    document = json.loads(LAYOUT.read_text())
    assert set(document) >= {"configById", "layout", "globalVariables", "userNodes"}
    panels = document["configById"]
    placed = list(_leaves(document["layout"]))
    assert sorted(placed) == sorted(panels)  # each panel placed exactly once
    kinds = {name.split("!")[0] for name in panels}
    assert kinds == {"Plot", "StateTransitions", "Table", "RawMessages"}
    for name, config in panels.items():
        assert config.get("title"), name
        if "topicPath" in config:
            assert config["topicPath"] in TOPIC_SCHEMAS
            continue
        for entry in config["paths"]:
            path = entry["value"]
            assert _PATH.fullmatch(path)["topic"] in TOPIC_SCHEMAS, path  # type: ignore[index]
            filters = dict(re.findall(r"\{(\w+)==\"(\w+)\"\}", path))
            assert filters.get("kind", EstimateKind.WINDOW) in set(EstimateKind)
            assert filters.get("operation", Operation.PICK_UP) in set(Operation)
            values = _resolve(path, stream)
            if filters.get("operation") == Operation.ROTATING:
                continue  # the synthetic string never rotates; same fields as pick-up
            assert values, f"{name}: {path} matches no recorded message"
            if name.startswith("StateTransitions"):
                assert all(isinstance(v, str) for v in values), path
            else:
                assert all(isinstance(v, float | int) for v in values), path
    # the units in the plot titles are those of the plotted fields
    assert "[N]" in panels["Plot!hookload"]["title"]
    assert all(p["value"].endswith(("_N", "pick_up", "slack_off", "rotating"))
               for p in panels["Plot!hookload"]["paths"])
