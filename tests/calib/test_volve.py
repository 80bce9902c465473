"""Real rig data, Volve 15/9-F-4 (Equinor Open Data Licence; "Equinor and the former Volve
licence partners"): detected states against the rig's activity codes, block weight, per-joint
pick-up friction, the modelled band around the measured loads, and the trip-in depth-tracking
artefact. The numbers come from scripts/volve_analysis.py, the code behind
docs/back-calculation.md; the data folder is TDMON_VOLVE_DATA (default
data/volve-f4 in the repository), and without it the committed replays/volve-f4-*.mcap."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("volve_analysis",
                                                  ROOT / "scripts" / "volve_analysis.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["volve_analysis"] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def volve() -> ModuleType:
    return _script()


@pytest.fixture(scope="module")
def runs(volve: Any) -> Any:
    return volve.run()


def test_states_agree_with_rig_activity_codes(volve: Any, runs: Any) -> None:
    out_analysis, in_analysis, _, _ = runs
    share_out, compared_out, table = volve.agreement(out_analysis.record, out_analysis.states)
    share_in, compared_in, _ = volve.agreement(in_analysis.record, in_analysis.states)
    assert compared_out > 1200 and compared_in > 400
    assert share_out >= 0.92  # measured 93.7 %
    assert share_in >= 0.95  # measured 96.6 %
    # the rig's in-slips code (104 with the idle rotation flag) is in slips for us too
    assert table.loc[104, "in_slips"] / table.loc[104].sum() >= 0.97


def test_block_weight_from_in_slips(runs: Any) -> None:
    out_analysis, in_analysis, _, _ = runs
    for analysis in (out_analysis, in_analysis):
        block = analysis.block_weight
        assert 650e3 <= block.value <= 665e3
        assert block.n >= 100
        assert block.std < 2e3


def test_pick_up_friction_per_joint_is_cased_hole_and_stable(volve: Any, runs: Any) -> None:
    out_analysis, _, _, _ = runs
    joints = volve.per_joint(out_analysis, "pick_up")
    # ~38 joints of 12 m pulled from 2574 to 2118 m; one steady window each (15 s sampling)
    assert len(joints) >= 28
    assert not out_analysis.rejected
    median = float(joints["mu"].median())
    spread = float(joints["mu"].std())
    assert 0.05 <= median <= 0.30  # measured 0.111
    assert spread <= 0.05  # measured 0.033
    assert float(joints["mu_std"].median()) <= 0.02
    assert all(math.isfinite(x) for x in joints["mu"])


def test_modelled_band_brackets_the_trip_out(volve: Any, runs: Any) -> None:
    out_analysis, _, out_model, _ = runs
    inside = volve.bracketing(out_analysis, out_model, 0.0, 0.35)
    assert inside["pick_up_samples"] >= 40
    assert inside["pick_up"] >= 0.95


def test_trip_in_weight_check_and_band(volve: Any, runs: Any) -> None:
    _, in_analysis, _, in_model = runs
    # with one fluid the string is modelled too heavy: slack-off loads fall below the band
    plain = volve.bracketing(in_analysis, in_model, 0.0, 0.35)
    assert plain["slack_off"] < 0.5
    density, depth, weight = volve.inside_density_from_static(in_analysis, in_model)
    assert depth == pytest.approx(2054.2, abs=1.0)  # the long hang at the start of the run
    assert 550e3 < weight < 700e3
    assert 600.0 < density < in_model.well.fluid.density
    checked_model = volve.weight_checked_model(in_model, density)
    checked = volve.analyse(in_analysis.record, checked_model)
    inside = volve.bracketing(checked, checked_model, 0.0, 0.35)
    assert inside["slack_off"] >= 0.8
    joints = volve.per_joint(checked, "slack_off")
    assert len(joints) >= 15
    assert float(np.median(joints["mu"])) < float(np.median(
        volve.per_joint(in_analysis, "slack_off")["mu"]))


def test_depth_tracking_artefact_is_kept_out(volve: Any, runs: Any) -> None:
    _, in_analysis, _, _ = runs
    check = volve.artefact_check(in_analysis)
    assert check["artefact_samples"] >= 3
    assert check["artefact_samples_in_slips"] == check["artefact_samples"]
    assert check["artefact_samples_in_windows"] == 0
    # bit-depth jumps with a still block (01:53-01:54Z, 2336 -> 2373 m) make no slack-off
    record = in_analysis.record
    states = np.array(in_analysis.states)
    jump = (np.diff(record["bit_depth"].to_numpy(), prepend=np.nan) > 20.0) & (
        np.abs(np.diff(record["block_position"].to_numpy(), prepend=np.nan)) < 0.1)
    assert jump.any()
    assert not np.isin(states[jump], ["slack_off", "pick_up"]).any()


def test_committed_replays_give_the_same_numbers(volve: Any, runs: Any,
                                                 tmp_path: Path) -> None:
    # without the CSV folder the script reads replays/volve-f4-*.mcap (the imported records)
    out_csv, in_csv, _, _ = runs
    out_mcap, in_mcap, _, _ = volve.run(tmp_path)
    for csv, mcap in ((out_csv, out_mcap), (in_csv, in_mcap)):
        assert mcap.states == csv.states
        assert mcap.block_weight.value == pytest.approx(csv.block_weight.value)
        assert [e.mu for _, e in mcap.estimates] == pytest.approx(
            [e.mu for _, e in csv.estimates], abs=1e-5)  # root tolerance 1e-6
