"""Aligner, rig state, monitor and pipeline without any transport."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest
from daemon_support import CollectSink, linear_model
from hypothesis import given, settings
from hypothesis import strategies as st

from tdmon.calib.rigstate import classify
from tdmon.config.daemon import RigStateConfig
from tdmon.daemon.aligner import Aligner
from tdmon.daemon.pipeline import Emit, Frame, Pipeline, Sink, Step
from tdmon.daemon.steps.monitor import GridLoadModel, ModelledLoads, MonitorStep
from tdmon.daemon.steps.rig_state import RigStateStep, rig_state_thresholds
from tdmon.ingest.decode import ChannelSpec, Decoder
from tdmon.ingest.types import RawMessage, Sample


def s(channel: str, t: float, value: float) -> Sample:
    return Sample(channel, t, value, "mqtt", f"rig/{channel}", "N", t)


class TestAligner:
    def test_frame_waits_for_bit_depth_of_the_same_instant(self) -> None:
        aligner = Aligner(wait_for=("bit_depth",))
        assert aligner.push(s("bit_depth", 0.0, 100.0), 0.0) == []
        assert [f.t for f in aligner.push(s("hookload", 0.0, 1e6), 0.0)] == [0.0]
        assert aligner.push(s("hookload", 1.0, 2e6), 0.0) == []  # waits for bit depth at 1.0
        frames = aligner.push(s("bit_depth", 1.0, 101.0), 0.01)
        assert len(frames) == 1 and frames[0].values == {"hookload": 2e6, "bit_depth": 101.0}

    def test_expiry_and_flush(self) -> None:
        aligner = Aligner(wait_for=("bit_depth",), max_wait=0.25)
        aligner.push(s("bit_depth", 0.0, 100.0), 0.0)
        aligner.push(s("hookload", 0.0, 1e6), 0.0)
        aligner.push(s("hookload", 1.0, 1e6), 10.0)
        assert aligner.expire(10.1) == []
        [frame] = aligner.expire(10.3)
        assert frame.t == 1.0 and frame.ages["bit_depth"] == 1.0
        # the bit depth no longer keeps pace with the hook load: not waited for any more
        assert [f.t for f in aligner.push(s("hookload", 2.0, 1e6), 11.0)] == [2.0]
        aligner.push(s("bit_depth", 2.0, 101.0), 11.0)
        aligner.push(s("hookload", 3.0, 1e6), 12.0)  # waits: the bit depth is back in step
        assert [f.t for f in aligner.flush()] == [3.0]

    def test_expected_channels_are_awaited_at_start_up_only(self) -> None:
        aligner = Aligner(expected=("bit_depth",), stale_timeout=5.0)
        assert aligner.push(s("hookload", 0.0, 1e6), 0.0) == []
        [frame] = aligner.push(s("bit_depth", 0.0, 100.0), 0.0)
        assert frame.values["bit_depth"] == 100.0
        quiet = Aligner(expected=("torque",), stale_timeout=5.0)
        quiet.push(s("hookload", 0.0, 1e6), 0.0)
        assert [f.t for f in quiet.push(s("hookload", 10.0, 1e6), 0.0)] == [0.0, 10.0]

    def test_stale_channel_is_left_out_and_not_waited_for(self) -> None:
        aligner = Aligner(wait_for=("bit_depth",), stale_timeout=5.0)
        aligner.push(s("bit_depth", 0.0, 100.0), 0.0)
        aligner.push(s("hookload", 0.0, 1e6), 0.0)
        [frame] = aligner.push(s("hookload", 10.0, 1e6), 0.0)
        assert "bit_depth" not in frame.values and frame.stale == ("bit_depth",)

    def test_duplicates_and_out_of_order(self) -> None:
        aligner = Aligner(wait_for=())
        frames = []
        for t in (1.0, 2.0, 2.0, 3.0, 1.5, 2.5, 2.5, -1.0):
            frames += aligner.push(s("hookload", t, t), 0.0)
        assert [f.t for f in frames] == [1.0, 2.0, 3.0]  # never backwards
        assert aligner.duplicates == 2
        assert aligner.out_of_order == 3  # 1.5, 2.5 (kept in history) and -1.0 (too old)

    def test_late_bit_depth_completes_the_pending_frame(self) -> None:
        aligner = Aligner(wait_for=("bit_depth",))
        aligner.push(s("bit_depth", 0.0, 100.0), 0.0)
        aligner.push(s("bit_depth", 2.0, 102.0), 0.0)
        aligner.push(s("hookload", 0.0, 1.0), 0.0)
        [frame] = aligner.push(s("hookload", 1.0, 1.0), 0.0)  # bit depth already past 1.0
        assert frame.values["bit_depth"] == 100.0  # the value at or before t, not after

    def test_frame_comes_with_the_last_channel_whatever_the_order(self) -> None:
        # the aligner looks first at the channel that held the last frame back; the order the
        # channels come in changes from frame to frame here, and each frame must still come
        # exactly with the last of its channels, never before
        others = ["bit_depth", "torque", "rpm", "spp"]
        orders = [others, others[::-1], ["rpm", "spp", "bit_depth", "torque"], others]
        aligner = Aligner(expected=["hookload", *others])
        emitted: list[float] = []
        for k, order in enumerate(orders * 3):
            t = float(k)
            emitted += [f.t for f in aligner.push(s("hookload", t, 1e6), t)]
            for index, channel in enumerate(order):
                frames = aligner.push(s(channel, t, 1.0), t)
                assert [f.t for f in frames] == ([t] if index == len(order) - 1 else [])
                emitted += [f.t for f in frames]
        assert emitted == [float(k) for k in range(12)]

    def test_a_frame_held_back_by_a_channel_never_seen_comes_when_it_is_no_longer_awaited(
            self) -> None:
        # the pending frame is held back by "ghost" (expected, never seen); the aligner does not
        # look again until that channel sends, unless a new channel comes: once more channels
        # are seen than expected, the expected ones are no longer awaited and the frame is due
        aligner = Aligner(expected=("bit_depth", "ghost"), stale_timeout=1.0)
        assert aligner.push(s("block_position", 1001.0, 5.0), 0.0) == []
        assert aligner.push(s("hookload", 998.0, 1e6), 0.0) == []  # waits for ghost
        assert aligner.push(s("block_position", 1002.0, 5.0), 0.0) == []  # still
        [frame] = aligner.push(s("bit_depth", 1001.0, 100.0), 0.0)
        assert frame.t == 998.0 and frame.stale == ("block_position", "bit_depth")


class _LooksOnEverySample(Aligner):
    """The aligner without its shortcut: whether the pending frame is complete is looked at
    on every sample, not only on those of the channel that held it back."""

    def push(self, sample: Sample, now: float) -> list[Frame]:
        self._held_by = None
        return super().push(sample, now)


@settings(max_examples=300, deadline=None)
@given(stream=st.lists(st.tuples(st.sampled_from(["hookload", "bit_depth", "torque", "rpm"]),
                                 st.sampled_from([0.0, 1e-7, 0.2, -0.5, -3.0, -40.0]),
                                 st.sampled_from([0.0, 0.0, 1.0, 7.0])), max_size=60),
       expected=st.sampled_from([(), ("bit_depth", "ghost"), ("torque",)]))
def test_the_aligner_emits_what_looking_on_every_sample_emits(
        stream: list[tuple[str, float, float]], expected: tuple[str, ...]) -> None:
    # in and out of order, duplicates, stale and never-seen channels, expiry
    fast = Aligner(expected=expected, stale_timeout=5.0)
    slow = _LooksOnEverySample(expected=expected, stale_timeout=5.0)
    t = now = 1000.0
    for channel, jitter, step in stream:
        t += step
        sample = s(channel, t + jitter, t)
        assert fast.push(sample, now) == slow.push(sample, now)
        now += 0.1
        assert fast.expire(now) == slow.expire(now)
    assert fast.flush() == slow.flush()
    assert (fast.duplicates, fast.out_of_order) == (slow.duplicates, slow.out_of_order)


def _rig_frames(rows: list[tuple[float, dict[str, float]]]) -> list[Frame]:
    return [Frame(t, 0, values, {}) for t, values in rows]


class TestRigState:
    """The detector of `tdmon.calib.rigstate` with ``[rig_state]``'s plain thresholds (the
    daemon without calibration)."""

    thresholds = rig_state_thresholds(RigStateConfig())

    @pytest.mark.parametrize(("args", "state"), [
        ((None, 0.0, 0.0, False, False), "unknown"),
        ((1e5, 0.0, 0.0, False, False), "in_slips"),
        ((399.9e3, -0.5, 0.0, False, False), "in_slips"),
        ((400e3, -0.5, 0.0, False, False), "pick_up"),
        ((1e6, -0.5, 0.0, False, False), "pick_up"),
        ((1e6, 0.5, 0.0, False, False), "slack_off"),
        ((1e6, 0.04, 0.0, False, False), "static"),
        ((1e6, 0.0, 10.0, False, False), "rotating_off_bottom"),
        ((1e6, 0.5, 10.0, False, False), "reaming"),
        ((1e6, -0.5, 10.0, False, False), "back_reaming"),
        ((1e6, 0.01, 10.0, False, True), "drilling"),
        ((1e6, 0.0, 0.0, True, False), "circulating"),
        ((1e6, 0.0, 0.0, False, False), "static"),
    ])
    def test_classify(self, args: tuple[Any, ...], state: str) -> None:
        # in slips below [rig_state] in_slips_hookload (400 kN), as the plain thresholds had it
        assert classify(*args, self.thresholds) == state

    def test_plain_thresholds_are_mapped(self) -> None:
        config = RigStateConfig(in_slips_hookload=800e3, moving_speed=0.1, rotating_rpm=1.0,
                                circulating_flow=0.002, on_bottom=2.0, steady_frames=4)
        t = rig_state_thresholds(config)
        assert t.block_weight + t.in_slips_margin == 800e3
        assert (t.moving_speed, t.rotating_speed, t.circulating_flow, t.on_bottom,
                t.settle_samples, t.settle_time) == (0.1, 1.0, 0.002, 2.0, 4, 0.0)

    def test_step_emits_on_change_and_marks_steady(self) -> None:
        step = RigStateStep(rig_state_thresholds(RigStateConfig(steady_frames=2)), every=100.0)
        sent: list[dict[str, Any]] = []
        frames = _rig_frames([(t, {"hookload": 1e6, "bit_depth": 1000.0 - t})
                              for t in range(5)])
        for frame in frames:
            step.on_frame(frame, lambda name, m: sent.append(m))
        assert [f.state for f in frames] == ["static", "pick_up", "pick_up", "pick_up",
                                             "pick_up"]
        assert [f.steady for f in frames] == [False, False, True, True, True]
        assert [(m["state"], m["steady"]) for m in sent] == [
            ("static", False), ("pick_up", False), ("pick_up", True)]
        assert sent[-1]["bit_depth_m"] == 998.0

    def test_no_glitch_speed_gap_or_hookload_step_limits(self) -> None:
        # 5 m/s, a 120 s gap and a 300 kN step: the plain thresholds took them as they came
        step = RigStateStep(rig_state_thresholds(RigStateConfig(steady_frames=1)))
        frames = _rig_frames([(0.0, {"hookload": 1e6, "bit_depth": 2000.0}),
                              (0.1, {"hookload": 1e6, "bit_depth": 1999.5}),
                              (120.1, {"hookload": 1.3e6, "bit_depth": 1900.0}),
                              (120.2, {"hookload": 1.3e6, "bit_depth": 1900.0, "spp": 50e5})])
        for frame in frames:
            step.on_frame(frame, lambda name, m: None)
        assert [f.state for f in frames] == ["static", "pick_up", "pick_up", "static"]
        # standpipe pressure alone does not mean circulating, as before
        assert [f.steady for f in frames] == [False, True, True, True]

    def test_the_channel_own_time_gives_the_velocity(self) -> None:
        # deliberate change from the plain step: a frame repeating the last bit-depth sample
        # (aligned at the hook load's rate) keeps the velocity instead of reading zero
        step = RigStateStep(rig_state_thresholds(RigStateConfig(steady_frames=1)))
        frames = [Frame(0.0, 0, {"hookload": 1e6, "bit_depth": 1000.0}, {}),
                  Frame(1.0, 0, {"hookload": 1e6, "bit_depth": 999.0}, {}),
                  Frame(1.5, 0, {"hookload": 1e6, "bit_depth": 999.0}, {"bit_depth": 0.5})]
        for frame in frames:
            step.on_frame(frame, lambda name, m: None)
        assert [f.state for f in frames] == ["static", "pick_up", "pick_up"]


class TestMonitor:
    def test_grid_interpolation_matches_closed_form(self) -> None:
        model = linear_model()
        loads = model.loads(1234.5)
        assert loads is not None
        weight = 300 * 1234.5 + 500e3
        assert loads.pick_up == pytest.approx(weight * 1.25)
        assert loads.band_slack_off == pytest.approx(tuple(weight * (1 - m)
                                                           for m in (0.1, 0.2, 0.3)))
        assert model.loads(-1.0) is None and model.loads(6000.0) is None

    def test_grid_rejects_bad_shapes(self) -> None:
        with pytest.raises(ValueError):
            GridLoadModel(np.array([0.0, 0.0]), np.zeros((4, 2)), [])
        with pytest.raises(ValueError):
            GridLoadModel(np.array([0.0, 1.0]), np.zeros((5, 2)), [])

    @settings(max_examples=200, deadline=None)
    @given(seed=st.integers(0, 2**32 - 1), start=st.floats(min_value=-10.0, max_value=1010.0),
           moves=st.lists(st.one_of(st.just(0.0), st.floats(-2.0, 2.0),
                                    st.floats(-500.0, 500.0)), min_size=1, max_size=12))
    def test_grid_loads_are_numpy_interpolation_exactly_also_when_reused(
            self, seed: int, start: float, moves: list[float]) -> None:
        depths = np.cumsum([start, *moves]).tolist()  # standing still, creeping, jumping
        rng = np.random.default_rng(seed)
        grid = np.cumsum(rng.uniform(1.0, 100.0, 20))  # uneven, from ~1 m to ~1000 m
        band = (0.1, 0.2, 0.3)
        curves = rng.uniform(-1e6, 3e6, (4 + 2 * len(band), grid.size))
        model = GridLoadModel(grid, curves, band)
        for depth in [*depths, depths[-1], *depths[::-1]]:  # repeats: the reused result
            loads = model.loads(depth)
            fresh = GridLoadModel(grid, curves, band).loads(depth)
            assert loads == fresh  # the same numbers, bit for bit
            if not grid[0] <= depth <= grid[-1]:
                assert loads is None
                continue
            assert loads is not None
            # the NumPy interpolation the grid model was written with
            i = min(int(np.searchsorted(grid, depth, side="right")) - 1, grid.size - 2)
            w = (depth - grid[i]) / (grid[i + 1] - grid[i])
            column = (curves[:, i] * (1.0 - w) + curves[:, i + 1] * w).tolist()
            assert (loads.pick_up, loads.slack_off, loads.rotating,
                    loads.torque_rotating) == tuple(column[:4])
            assert loads.band_pick_up == tuple(column[4:7])
            assert loads.band_slack_off == tuple(column[7:10])
            assert loads.bit_depth == depth and loads.band_mu == band
        assert model.loads(math.nan) is None

    def test_modelled_loads_init_is_the_dataclass_one(self) -> None:
        # the hand-written __init__ (its signature: tests/test_hand_written_inits.py): frozen,
        # compared, copied like the dataclass
        import dataclasses

        names = [f.name for f in dataclasses.fields(ModelledLoads)]
        args = (1.0, 2.0, 3.0, 4.0, 5.0, (0.1,), (6.0,), (7.0,), -0.98, -0.02)
        loads = ModelledLoads(*args)
        assert dataclasses.astuple(loads) == args
        # without the on-bottom slopes: the rotating model's (docs/drilling.md)
        assert dataclasses.astuple(ModelledLoads(*args[:8]))[8:] == (-1.0, 0.0)
        assert loads == ModelledLoads(**dict(zip(names, args, strict=True)))
        assert hash(loads) == hash(dataclasses.replace(loads))
        with pytest.raises(dataclasses.FrozenInstanceError):
            loads.pick_up = 0.0  # type: ignore[misc]

    def test_same_depth_reuses_the_evaluation(self) -> None:
        model = linear_model()
        first = model.loads(1234.5)
        assert model.loads(1234.5) is first  # in slips: nothing to interpolate again
        other = model.loads(1234.6)
        assert other is not first and other is not None
        assert other.pick_up != first.pick_up
        again = model.loads(1234.5)
        assert again == first and again is not first
        by_int = model.loads(1234)  # an int depth stays an int in the message
        assert by_int is not None and type(by_int.bit_depth) is int
        assert type(model.loads(1234.0).bit_depth) is float  # type: ignore[union-attr]

    def test_message_shape_and_residuals(self) -> None:
        step = MonitorStep(linear_model())
        sent: dict[str, Any] = {}
        frame = Frame(5.0, 0, {"hookload": 1e6, "bit_depth": 1000.0, "torque": 9000.0}, {},
                      state="reaming")
        step.on_frame(frame, lambda name, m: sent.update({name: m}))
        model = sent["model"]
        assert set(model) == {"t", "bit_depth_m", "hookload_N", "torque_Nm", "band",
                              "measured", "residual"}
        assert model["residual"]["hookload_N"] == pytest.approx(1e6 - 800e3 * 0.75)
        assert model["residual"]["torque_Nm"] == pytest.approx(9000 - 20 * 1000 * 0.25)
        json.dumps(model, allow_nan=False)
        step.on_frame(Frame(6.0, 0, {"hookload": 1e6}, {}), lambda n, m: None)
        assert step.skipped_no_depth == 1


class OrderCheck:
    """A step asserting that the sinks already hold the sample that made the frame."""

    name = "order-check"

    def __init__(self, sink: CollectSink) -> None:
        self.sink = sink
        self.frames = 0
        self.closed = False

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        assert any(m["t"] == frame.t and m["channel"] == "hookload"
                   for m in self.sink["sample"])
        assert any(json.loads(m["payload"])["t"] == frame.t for m in self.sink["raw"])
        assert "model" in frame.results  # an earlier step's result is visible
        self.frames += 1

    def close(self, emit: Emit) -> None:
        self.closed = True


class Exploding:
    name = "exploding"

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        raise RuntimeError("bug in a step")

    def close(self, emit: Emit) -> None:
        pass


def test_pipeline_records_before_steps_and_survives_a_failing_step() -> None:
    sink = CollectSink()
    check = OrderCheck(sink)
    steps: list[Step] = [RigStateStep(), MonitorStep(linear_model()), Exploding(), check]
    decoder = Decoder("rig", [ChannelSpec("hookload", "hookload", "N"),
                              ChannelSpec("bit_depth", "bit_depth", "m")])
    sinks: list[Sink] = [sink]
    pipeline = Pipeline(decoder, Aligner(wait_for=("bit_depth",)), steps, sinks)
    for i in range(5):
        for channel, value in (("bit_depth", 1000.0 + i), ("hookload", 1e6)):
            body = json.dumps({"t": float(i), "value": value}).encode()
            pipeline.process(RawMessage("mqtt", f"rig/{channel}", body, 100.0 + i))
    pipeline.process(RawMessage("mqtt", "rig/hookload", b"nope", 200.0))
    pipeline.flush()
    pipeline.close_sinks()
    assert check.frames == 5 and check.closed and sink.closed
    assert pipeline.stats.step_errors == 5
    assert pipeline.stats.rejected == 1 and pipeline.stats.rejected_reasons == {
        "malformed JSON": 1}
    # raw first, then the decoded sample: for every message, in arrival order
    assert sink.order[:2] == ["/tdmon/raw", "/tdmon/sample"]
    assert sink.order.count("/tdmon/raw") == 11
    status = pipeline.status_message({"mqtt": "connected"}, now=10.0)
    assert status["samples_in"] == 10 and status["rejected"] == 1 and status["lag_s"] == 6.0


class _Emits:
    """Emits ``state`` and ``model`` on every frame, and ``summary`` when closing."""

    name = "emits"

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        emit("state", {"t": frame.t})
        emit("model", {"t": frame.t, "seen": sorted(frame.results)})

    def close(self, emit: Emit) -> None:
        emit("summary", {"done": True})


class _Failing(CollectSink):
    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        raise OSError("disk full")


class _StateOnly(CollectSink):
    topics = frozenset({"/tdmon/state"})


def test_step_messages_reach_the_sinks_that_want_them_and_the_frame_results(
        caplog: pytest.LogCaptureFixture) -> None:
    kept, failing, state_only, late = CollectSink(), _Failing(), _StateOnly(), CollectSink()
    sinks: list[Sink] = [failing, kept, state_only]
    pipeline = Pipeline(Decoder("rig", [ChannelSpec("hookload", "hookload", "N")]),
                        Aligner(), [_Emits()], sinks)
    frames = [Frame(float(i), 1000 + i, {"hookload": 1e6}, {"hookload": 0.0})
              for i in range(3)]
    pipeline._run_steps(frames[0])
    pipeline.add_sink(late)  # routes worked out again
    for frame in frames[1:]:
        pipeline._run_steps(frame)
    pipeline.flush()
    assert kept.order == ["/tdmon/state", "/tdmon/model"] * 3 + ["/tdmon/summary"]
    assert [m["t"] for m in kept.messages["/tdmon/model"]] == [0.0, 1.0, 2.0]
    assert kept.messages["/tdmon/model"][0]["seen"] == ["state"]
    assert state_only.order == ["/tdmon/state"] * 3
    assert late.order == ["/tdmon/state", "/tdmon/model"] * 2 + ["/tdmon/summary"]
    assert [sorted(frame.results) for frame in frames] == [["model", "state"]] * 3
    assert frames[2].results["state"] is kept.messages["/tdmon/state"][2]
    assert pipeline.stats.sink_errors == 7 and pipeline.stats.step_errors == 0
    assert caplog.text.count("failed writing 1 message(s) on /tdmon/") == 7


class TestStaleAfterAGap:
    """Every channel silent for 45 s (1 Hz, stale timeout 5 s): one ``sensor_stale`` alarm names
    the channels that went stale, stamped when they went stale, and none when data resumes."""

    CHANNELS = ("hookload", "bit_depth", "torque", "rpm", "flow_in", "spp", "block_position",
                "hole_depth", "wob")

    def _run(self, resume_missing: tuple[str, ...] = ()) -> list[dict[str, Any]]:
        from tdmon.daemon.steps.alarms import AlarmStep

        sink = CollectSink()
        step = AlarmStep()
        aligner = Aligner(stale_timeout=5.0)
        times = [float(k) for k in range(20)] + [65.0 + k for k in range(20)]
        for t in times:
            for channel in self.CHANNELS:
                if t >= 65.0 and channel in resume_missing:
                    continue
                for frame in aligner.push(s(channel, t, 1e6 if channel == "hookload" else 1.0),
                                          t):
                    step.on_frame(frame, self._emit(sink))
        for frame in aligner.flush():
            step.on_frame(frame, self._emit(sink))
        return [m for m in sink["alarm"] if m["kind"] == "sensor_stale"]

    @staticmethod
    def _emit(sink: CollectSink) -> Emit:
        def emit(name: str, message: dict[str, Any]) -> None:
            sink.write(f"/tdmon/{name}", 0, message)
        return emit

    def test_one_alarm_for_the_gap_when_the_channels_went_stale(self) -> None:
        [alarm] = self._run()
        # the last samples before the gap are at 19 s: stale from 24 s, data again at 65 s
        assert alarm["t"] == 24.0
        assert alarm["message"] == (
            "9 channels went stale together, for 41 s until data resumed: hookload, "
            "bit_depth, block_position, flow_in, hole_depth, rpm, spp, torque, wob")
        assert alarm["value"] == 41.0

    def test_a_channel_still_missing_after_the_gap_is_not_named_twice(self) -> None:
        [alarm] = self._run(resume_missing=("torque",))
        assert "torque" in alarm["message"]

    def test_live_the_alarm_comes_while_the_data_are_missing(self) -> None:
        # the daemon's housekeeping ticks on wall time: after 5 s without a hook load the
        # silence is raised once, stamped when the channels went stale; the resume adds none
        from tdmon.daemon.steps.alarms import AlarmStep

        clock = [0.0]
        sink = CollectSink()
        decoder = Decoder("rig", [ChannelSpec(c, c, "N" if c == "hookload" else "m")
                                  for c in ("hookload", "bit_depth")])
        pipeline = Pipeline(decoder, Aligner(stale_timeout=5.0), [AlarmStep()], [sink],
                            monotonic=lambda: clock[0])

        def send(t: float) -> None:
            clock[0] = t
            for channel in ("hookload", "bit_depth"):
                body = json.dumps({"t": 1.7e9 + t, "value": 1e6}).encode()
                pipeline.process(RawMessage("mqtt", f"rig/{channel}", body, 1.7e9 + t))
            pipeline.tick()

        for k in range(10):
            send(float(k))
        for now in (9.5, 12.0, 14.0):  # silent, not yet stale
            clock[0] = now
            pipeline.tick()
        assert not [m for m in sink["alarm"] if m["kind"] == "sensor_stale"]
        for now in (14.5, 20.0, 40.0):
            clock[0] = now
            pipeline.tick()
        [alarm] = [m for m in sink["alarm"] if m["kind"] == "sensor_stale"]
        assert alarm["t"] == pytest.approx(1.7e9 + 14.0)  # last samples at 9 s, + 5 s
        assert alarm["message"] == ("2 channels went stale together, no data since: hookload, "
                                    "bit_depth")
        for k in range(50, 55):
            send(float(k))
        pipeline.flush()
        assert len([m for m in sink["alarm"] if m["kind"] == "sensor_stale"]) == 1


class TimedSink(CollectSink):
    """Keeps the log time of each message too."""

    def __init__(self) -> None:
        super().__init__()
        self.log_times: list[tuple[str, int]] = []

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        super().write(topic, log_time_ns, message)
        self.log_times.append((topic, log_time_ns))


def test_a_pipeline_following_input_time_stamps_status_and_closing_results_with_it() -> None:
    """Replays: what belongs to no input is stamped with the latest input's time (2024 here),
    not the wall clock; a live pipeline keeps the wall clock for it."""
    decoder = Decoder("rig", [ChannelSpec("hookload", "hookload", "N"),
                              ChannelSpec("bit_depth", "bit_depth", "m")])
    rig_t = 1_709_272_800.0  # 2024-03-01
    for follow in (True, False):
        sink = TimedSink()
        pipeline = Pipeline(decoder, Aligner(wait_for=("bit_depth",)),
                            [RigStateStep(), MonitorStep(linear_model())], [sink])
        if follow:
            pipeline.follow_input_time()
        for i in range(5):
            for channel, value in (("bit_depth", 1000.0 + i), ("hookload", 1e6)):
                body = json.dumps({"t": rig_t + i, "value": value}).encode()
                pipeline.process(RawMessage("mqtt", f"rig/{channel}", body, rig_t + i + 0.5))
        pipeline.emit("status", pipeline.status_message({"mqtt": "finished"}))
        last_input = int((rig_t + 4.5) * 1e9)
        status_ns = sink.log_times[-1][1]
        status = sink.messages["/tdmon/status"][-1]
        if follow:
            assert status_ns == last_input and status["t"] == pytest.approx(rig_t + 4.5)
            assert status["lag_s"] == pytest.approx(0.5)
            assert max(ns for _, ns in sink.log_times) == last_input
        else:
            assert status_ns > last_input + 10**9 * 86400 * 365  # today's wall clock


def test_tdmon_run_follows_input_time_only_when_it_replays_a_recording() -> None:
    from pathlib import Path

    from tdmon.config.daemon import load_daemon_config
    from tdmon.daemon.runner import replays_only

    folder = Path(__file__).resolve().parents[2] / "config" / "daemon"
    replaying = load_daemon_config(folder / "replay-sim-trip-out.toml")
    assert replays_only(replaying)
    assert not replays_only(load_daemon_config(folder / "mqtt-local.toml"))
    both = replaying.model_copy(update={"sources": replaying.sources.model_copy(
        update={"mqtt": load_daemon_config(folder / "mqtt-local.toml").sources.mqtt})})
    assert not replays_only(both)
