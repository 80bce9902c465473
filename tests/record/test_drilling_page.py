"""The drilling page: the report's figure and the Rerun views' entities, from a real MCAP
recording of the monitor's own drilling frames, read back (docs/drilling.md)."""

from __future__ import annotations

import statistics
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from rerun.chunk import RrdReader

from tdmon.cli import main
from tdmon.daemon.pipeline import Frame
from tdmon.daemon.steps.monitor import GridLoadModel, MonitorStep
from tdmon.record.drilling_page import drilling_series
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import read_messages

ROTATING, TORQUE = 1.2e6, 20e3


def _messages() -> list[dict[str, Any]]:
    # 10 s off bottom then 40 drilling frames from 3000 m with 80 kN (the surface reading
    # 2 kN higher on every other frame), the hook load 1 kN above the drilling curve
    rows = [ROTATING, 1.0e6, ROTATING, TORQUE, ROTATING, 1.0e6]
    model = GridLoadModel(np.array([0.0, 5000.0]), np.array([[v, v] for v in rows]), (0.25,),
                          np.array([[-1.0, -1.0], [-0.02, -0.02]]))
    step = MonitorStep(model)
    out: list[dict[str, Any]] = []
    frames = [Frame(float(t), t * 10**9, {"hookload": ROTATING, "torque": TORQUE,
                                          "bit_depth": 2999.0, "hole_depth": 3000.0}, {},
                    state="rotating_off_bottom", steady=True) for t in range(0, 10, 2)]
    for i in range(40):
        wob = 80e3 + (2e3 if i % 2 else 0.0)
        frames.append(Frame(10.0 + i, (10 + i) * 10**9, {
            "hookload": ROTATING - wob + 1e3, "torque": TORQUE - 0.02 * wob + 2e3,
            "bit_depth": 3000.0 + 0.1 * i, "hole_depth": 3000.0 + 0.1 * i, "wob": wob}, {},
            state="drilling", steady=True))
    for frame in frames:
        step.on_frame(frame, lambda topic, message: out.append(message))
    return out


def _recording(tmp_path: Path) -> Path:
    with McapRecorder(tmp_path / "rec") as recorder:
        for message in _messages():
            recorder.write("/tdmon/model", round(message["t"] * 1e9), message)
    [mcap] = recorder.stats.files
    return Path(mcap)


def test_the_report_draws_the_drilling_page(tmp_path: Path) -> None:
    mcap = _recording(tmp_path)
    series = drilling_series([m.message for m in read_messages(mcap, ["/tdmon/model"])])
    assert series.t.size == 40
    # the hook load read against the drilling curve: 1 kN over it on every frame
    assert np.allclose(series.hookload_residual, 1e3)
    # from the hook load: the surface's 80 and 82 kN less the 1 kN it reads over the curve
    assert series.wob_estimated.tolist() == [79e3, 81e3] * 20
    assert statistics.median(series.wob_surface.tolist()) == 81e3
    out = tmp_path / "report"
    assert main(["report", str(mcap), "--out", str(out)]) == 0
    assert (out / "drilling.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    page = (out / "report.html").read_text()
    assert "40 drilling frames" in page
    assert "Median hook-load residual against the drilling curve: +1.0 kN" in page


def test_the_rerun_views_have_the_drilling_entities(tmp_path: Path) -> None:
    mcap = _recording(tmp_path)
    rrd = tmp_path / "views.rrd"
    assert main(["view", str(mcap), "--rrd", str(rrd), "--no-progress"]) == 0
    rows: dict[str, int] = defaultdict(int)
    for chunk in RrdReader(rrd).stream().to_chunks():
        if not chunk.is_static:
            rows[chunk.entity_path] += chunk.num_rows
    for name in ("surface", "estimated"):
        assert rows[f"/drilling/wob_kN/{name}"] == 40
        assert rows[f"/vs_depth/drilling/wob_kN/{name}"] == 40
    assert rows["/drilling/bit_torque_kNm"] == 40  # the tag's step from the first frame
    assert "/drilling/wob_kN/downhole" not in rows  # no MWD in this recording
    assert rows["/torque_kNm/model/drilling"] == 40
