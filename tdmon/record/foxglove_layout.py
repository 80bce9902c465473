"""The Foxglove layout of tdmon's recordings (``config/foxglove/tdmon-layout.json``).

The layout is made here, not written by hand, so that its plots of the joint estimate follow
the estimated parameters' declaration (:mod:`tdmon.calib.parameters`): the joint friction
beside the window frictions, and one plot per parameter estimated beside it.
``tests/record/test_foxglove_layout.py`` fails when the file is not what :func:`layout`
makes; write it again with::

    python -m tdmon.record.foxglove_layout config/foxglove/tdmon-layout.json

The plots show the recorded values (SI) against each message's log time (Foxglove's "receive
time"); docs/recording.md, "Foxglove layout", lists the panels.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Final

from tdmon.calib.parameters import JOINT_PARAMETERS, EstimatedParameter, EstimatedParameters
from tdmon.vocabulary import EstimateKind

__all__ = ["layout", "layout_text", "main"]

#: Every plot's display options (Foxglove's Plot panel), the same for all.
_PLOT: Final[dict[str, Any]] = {
    "showXAxisLabels": True, "showYAxisLabels": True, "showLegend": True,
    "legendDisplay": "floating", "showPlotValuesInLegend": True, "isSynced": True,
    "xAxisVal": "timestamp", "sidebarDimension": 240,
}


def _path(value: str, label: str) -> dict[str, Any]:
    return {"value": value, "enabled": True, "timestampMethod": "receiveTime", "label": label}


def _plot(title: str, paths: Sequence[dict[str, Any]]) -> dict[str, Any]:
    return {"title": title, "paths": list(paths), **_PLOT}


def _split(direction: str, first: Any, second: Any, percentage: float) -> dict[str, Any]:
    return {"direction": direction, "first": first, "second": second,
            "splitPercentage": percentage}


def _stack(panels: Sequence[str]) -> Any:
    """Panels one above the other, each the same height."""
    if len(panels) == 1:
        return panels[0]
    return _split("column", panels[0], _stack(panels[1:]), round(100 / len(panels), 1))


def _joint(field: str) -> str:
    return f'/tdmon/estimate{{kind=="{EstimateKind.JOINT.value}"}}.{field}'


def _parameter_panel(parameter: EstimatedParameter) -> dict[str, Any]:
    unit = "-" if parameter.unit == "1" else parameter.unit
    return _plot(f"{parameter.label.capitalize()} [{unit}]: joint estimate ({parameter.words})",
                 [_path(_joint(parameter.name), parameter.label)])


def layout(parameters: EstimatedParameters = JOINT_PARAMETERS) -> dict[str, Any]:
    """The layout document: hook load, torque, friction (window, mu(T) and joint estimates),
    a plot per parameter estimated beside the friction, bit depth; rig state, the latest alarm
    and the daemon's status beside them."""
    window = '/tdmon/estimate{kind=="window"}'
    panels: dict[str, dict[str, Any]] = {
        "Plot!hookload": _plot("Hook load [N]: measured and modelled", [
            _path("/tdmon/model.measured.hookload_N", "measured"),
            _path("/tdmon/model.hookload_N.pick_up", "pick-up (model)"),
            _path("/tdmon/model.hookload_N.slack_off", "slack-off (model)"),
            _path("/tdmon/model.hookload_N.rotating", "rotating (model)"),
        ]),
        "Plot!torque": _plot("Surface torque [N m]: measured and modelled", [
            _path("/tdmon/model.measured.torque_Nm", "measured"),
            _path("/tdmon/model.torque_Nm.rotating", "rotating off bottom (model)"),
        ]),
        "Plot!friction": _plot("Friction factor [-]: window estimates, mu(T) and joint", [
            _path(f'{window}{{operation=="pick_up"}}.mu', "pick-up windows"),
            _path(f'{window}{{operation=="slack_off"}}.mu', "slack-off windows"),
            _path(f'{window}{{operation=="rotating"}}.mu', "rotating windows"),
            _path('/tdmon/estimate{kind=="mu_T"}.mu', "mu(T) at mid temperature"),
            _path(_joint(parameters.friction.name),
                  f"joint with the {parameters.nouns()}"),
        ]),
    }
    beside = []
    for parameter in parameters.others:
        name = f"Plot!joint_{parameter.name}"
        panels[name] = _parameter_panel(parameter)
        beside.append(name)
    panels |= {
        "Plot!depth": _plot("Bit depth [m MD]", [_path("/tdmon/model.bit_depth_m", "bit depth")]),
        "StateTransitions!rigstate": {
            "title": "Rig state",
            "paths": [{"value": "/tdmon/state.state", "timestampMethod": "receiveTime",
                       "label": "rig state"}],
            "isSynced": True,
        },
        "Table!alarms": {"title": "Latest alarm", "topicPath": "/tdmon/alarm"},
        "RawMessages!status": {
            "title": "Daemon status", "topicPath": "/tdmon/status", "diffEnabled": False,
            "diffMethod": "custom", "diffTopicPath": "", "showFullMessageForDiff": False,
            "expansion": "all",
        },
    }
    plots = _split("column",
                   _split("column", "Plot!hookload", "Plot!torque", 55),
                   _split("column", "Plot!friction", _stack([*beside, "Plot!depth"]), 60),
                   55)
    side = _split("column", "StateTransitions!rigstate",
                  _split("column", "Table!alarms", "RawMessages!status", 50), 25)
    return {
        "configById": panels,
        "globalVariables": {},
        "userNodes": {},
        "linkedGlobalVariables": [],
        "playbackConfig": {"speed": 1},
        "layout": _split("row", plots, side, 68),
    }


def layout_text(parameters: EstimatedParameters = JOINT_PARAMETERS) -> str:
    """The layout file's text (JSON, two-space indent, one final newline)."""
    return json.dumps(layout(parameters), indent=2) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """Write the layout to the path given (else print it)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args:
        Path(args[0]).write_text(layout_text(), encoding="utf-8")
    else:
        sys.stdout.write(layout_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
