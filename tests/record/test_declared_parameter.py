"""A parameter added to the joint estimate's declaration reaches every output unedited.

A fresh interpreter adds a spare offset (a parameter with no measurement model yet) to
``tdmon.calib.parameters.JOINT_PARAMETERS``
before anything else of tdmon is imported, as a new row in that file would, and then runs the
real code: the estimator on pick-up and slack-off windows, the JSON Schema, an MCAP recording
and the report written from it, the Rerun views read back from their ``.rrd`` file, the
Foxglove layout and the replay expectations' keys. Nothing but the declaration changes."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

CHILD = """
import json, sys
from pathlib import Path

from tdmon.calib import parameters as declared

OFFSET = declared.EstimatedParameter(
    name="spare_offset", key="spare", unit="N", prior=0.0, prior_std=20e3,
    drift_per_hour=2e3, drift_per_100m=0.0, bounds=(-2e5, 2e5), label="spare offset",
    noun="spare offset", words="what the hook-load sensor reads with nothing on the hook",
    shown="force", reference=0.0,
    reading=("the hook load reads {} low", "the hook load reads {} high"),
    truth=("/truth/spare", "spare_N"))
declared.JOINT_PARAMETERS = declared.EstimatedParameters((*declared.JOINT_PARAMETERS, OFFSET))

import jsonschema
from rerun.chunk import RrdReader

from tdmon.calib.estimator import CalibrationSettings, FrictionEstimator
from tdmon.calib.joint import JointSettings
from tdmon.calib.windows import Window
from tdmon.config.expectations import JointExpectation
from tdmon.config.well import load_well_model
from tdmon.model.torque_drag import WellModel
from tdmon.record.foxglove_layout import layout
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.report import write_report
from tdmon.record.rerun_views import build_rrd
from tdmon.record.schemas import TOPIC_SCHEMAS

out = Path(sys.argv[1])
model = WellModel(load_well_model("config/wells/volve-f4.toml"))
three = declared.EstimatedParameters((declared.FRICTION, declared.WEIGHT_FACTOR, OFFSET))
estimator = FrictionEstimator(model, CalibrationSettings(joint=JointSettings(parameters=three)))
state = estimator.initial_state()
joint, recorded = [], []
for k in range(6):
    for name, mu in (("pick_up", 0.22), ("slack_off", 0.33)):
        depth = 2400.0 - 2.5 * k
        t = 1.6e9 + 120.0 * k + (60.0 if name == "slack_off" else 0.0)
        hook = model.evaluate(name, depth, mu)[0]
        window = Window(name, t - 30.0, t, 30, depth, depth, depth, hook, 3e3)
        state, outputs = estimator.update(state, window)
        joint += [m for _, m in outputs if m.get("kind") == "joint"]
        recorded += [(f"/tdmon/{topic}", int(m["t"] * 1e9), m) for topic, m in outputs]
last = joint[-1]
schema = TOPIC_SCHEMAS["/tdmon/estimate"]
for message in joint:
    jsonschema.validate(message, schema)

recording = out / "joint.mcap"
with McapRecorder(path=recording, overwrite=True) as recorder:
    for topic, log_time_ns, message in recorded:
        recorder.write(topic, log_time_ns, message)
report = write_report([recording], out / "report")
summary = json.loads(report.summary.read_text())

rows, views = {}, set()
build_rrd([("/tdmon/estimate", int(m["t"] * 1e9), m) for m in joint], out / "joint.rrd")
reader = RrdReader(out / "joint.rrd")
for chunk in reader.stream().to_chunks():
    batch = chunk.to_record_batch()
    if "Scalars:scalars" in batch.schema.names:
        rows.setdefault(chunk.entity_path, []).extend(
            v[0] for v in batch.column("Scalars:scalars").to_pylist())
for chunk in reader.stream(store=reader.blueprints()[0]).to_chunks():
    batch = chunk.to_record_batch()
    for column in batch.schema.names:
        if column.endswith(":display_name"):
            views.update(str(v[0]) for v in batch.column(column).to_pylist() if v)

print(json.dumps({
    "message": {k: last[k] for k in last if k not in ("windows", "residuals", "scatter",
                                                       "mu_single")},
    "fields": list(last),
    "schema": {k: schema["properties"].get(k) for k in (
        "spare_offset", "spare_offset_std", "correlation_weight_spare",
        "mu_at_prior_spare", "spare_variance_ratio")},
    "summary": summary["joint"],
    "page": (out / "report" / "report.html").read_text(),
    "rows": rows, "views": sorted(views),
    "layout": layout()["configById"].get("Plot!joint_spare_offset"),
    "expectation_keys": sorted(JointExpectation.model_fields),
}))
"""


def test_a_declared_parameter_reaches_every_output(
        run_child: Callable[..., dict[str, Any]], tmp_path: Path) -> None:
    result = run_child(CHILD, str(tmp_path), timeout=300.0)
    message = result["message"]
    # the message: the offset's fields beside the weight factor's, in the declaration's order,
    # valid against the schema (checked in the child) whose properties describe them
    fields = result["fields"]
    assert fields[6:13] == ["weight_factor", "weight_factor_std", "spare_offset",
                            "spare_offset_std", "correlation", "correlation_mu_spare",
                            "correlation_weight_spare"]
    assert {"mu_at_prior_spare", "mu_at_prior_spare_std",
            "spare_variance_ratio"} <= set(fields)
    assert message["spare_offset"] == 0.0 and message["spare_offset_std"] > 20e3
    assert not message["identifiable"]
    assert message["identifiability"].startswith("weakly identifiable: the spare offset")
    schema = result["schema"]
    assert schema["spare_offset"] == {
        "type": "number",
        "description": "joint: spare offset: what the hook-load sensor reads with nothing "
                       "on the hook [N]"}
    assert all(s is not None and s["type"] == "number" for s in schema.values())
    # the report and its summary: the offset's numbers, in its words
    summary = result["summary"]
    assert summary["spare_offset"] == 0.0
    assert summary["spare_offset_std"] == round(message["spare_offset_std"], 4)
    assert summary["correlation_weight_spare"] == 0.0
    assert summary["words"].startswith("Friction, string weight and spare offset could not "
                                       "be separated (12 updates): weakly identifiable: the "
                                       "spare offset rests mostly on its prior")
    assert summary["words"].endswith("assume the modelled string weight and spare offset.")
    assert summary["words"] in result["page"].replace("&#x27;", "'")
    # the Rerun views: its own entity in kN and its own view
    rows = result["rows"]
    assert rows["/spare_offset_kN"] == [0.0] * 12
    assert len(rows["/friction/joint"]) == len(rows["/weight_factor"]) == 12
    assert any(v.startswith("Spare offset [kN] (joint estimate") for v in result["views"])
    # the Foxglove layout plots it; the replay expectations take its keys
    assert result["layout"]["paths"][0]["value"] == (
        '/tdmon/estimate{kind=="joint"}.spare_offset')
    assert {"spare_offset", "spare_truth_abs", "spare_truth_rel"} <= set(
        result["expectation_keys"])
