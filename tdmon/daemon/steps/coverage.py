"""Model coverage: the well file's string against the bit depth, and the well file per run.

The model is only as good as the string it is given. Two things make it stop fitting the rig
without any sensor noticing:

* the bit goes deeper than the well file's string is long (a short tally, a stand added and not
  booked). The model then takes the top component to surface (the daemon's well is always
  extended to the bottom of the hole, :func:`tdmon.config.well_file.read_well_path`), so loads and
  estimates keep coming, and a critical ``model_coverage`` alarm says so at once, in metres;
* the string changes between runs (a trip for a new BHA). ``[[runs]]`` of the daemon file name a
  well file per run from a rig time on, and SIGHUP (``tdmon run``) re-reads the well file in
  use. Each change puts the new well in the monitor, the calibration and the ``well`` message
  (recorded on ``/tdmon/well``) on the frame it takes effect, and raises an info
  ``model_coverage`` alarm naming what changed.

A change of the hole itself (survey, sections, element length) cannot be taken live: the
calibration's friction profile lives on the hole's grid. Such a file is refused with a critical
alarm and the previous well stays in use (restart the daemon with the new file).
See docs/daemon.md, "Model coverage".
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tdmon.daemon.pipeline import Emit, Frame, Step
from tdmon.errors import TdmonError
from tdmon.messages import alarm_message
from tdmon.vocabulary import AlarmKind, Severity

if TYPE_CHECKING:
    from tdmon.config.daemon import DaemonConfig
    from tdmon.config.well_file import WellFile

__all__ = ["SHORT_TOLERANCE", "CoverageStep", "coverage_step"]

log = logging.getLogger(__name__)

#: the bit may lie this far below the tally before the alarm [m]: depth noise and a bit on
#: bottom with a tally that ends exactly there must not raise it
SHORT_TOLERANCE = 0.5

#: takes the new well file and why it came (e.g. "run 2 from 2024-03-05T12:10:00Z"); called
#: on the daemon's thread between two steps
WellTarget = Callable[["WellFile", str], None]


def _clock(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


class CoverageStep:
    """Step: the string-coverage alarm and the switch to a new well file (run or reload).

    Parameters
    ----------
    well_file : the well file in use at start-up
    runs : (rig time [Unix s], well file path) of each later run, in time order
    reader : reads a well file (:func:`tdmon.config.well_file.read_well_path`)
    targets : called with each new well file (monitor, calibration, well message)
    """

    name = "coverage"

    def __init__(self, well_file: WellFile, *, runs: Sequence[tuple[float, Path]] = (),
                 reader: Callable[[Path], WellFile], targets: Sequence[WellTarget] = ()
                 ) -> None:
        self.well_file = well_file
        self.runs = list(runs)
        self.reader = reader
        self.targets = list(targets)
        self.run = 0  # index of the run in use: 0 is the top-level well
        self._grid_md = _grid_md(well_file.well)
        self._short_alarmed = False
        self._reload = False

    def request_reload(self) -> None:
        """Re-read the well file in use on the next frame (SIGHUP)."""
        self._reload = True

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        started = self.run
        while self.run < len(self.runs) and frame.t >= self.runs[self.run][0]:
            self.run += 1  # a replay that starts late takes the last run that has begun
        if self.run != started:
            start, path = self.runs[self.run - 1]
            self._switch(path, f"run {self.run + 1} from {_clock(start)}", frame.t, emit)
        if self._reload:
            self._reload = False
            self._switch(self.well_file.path, "reload (SIGHUP)", frame.t, emit)
        bit = frame.values.get("bit_depth")
        tally = self.well_file.tally_length
        if bit is not None and not self._short_alarmed and bit > tally + SHORT_TOLERANCE:
            self._short_alarmed = True
            top = self.well_file.well.string.components[-1].name or "top component"
            emit("alarm", alarm_message(
                frame.t, AlarmKind.MODEL_COVERAGE, Severity.CRITICAL,
                f"string tally {bit - tally:.1f} m shorter than bit depth {bit:.1f} m: the top "
                f"component ({top}) is taken to surface; check the well file "
                f"{self.well_file.path.name}", value=bit, limit=tally))

    def close(self, emit: Emit) -> None:
        """Nothing buffered."""

    def _switch(self, path: Path, why: str, t: float, emit: Emit) -> None:
        old = self.well_file
        try:
            new = self.reader(path)
        except (TdmonError, OSError) as exc:
            emit("alarm", alarm_message(
                t, AlarmKind.MODEL_COVERAGE, Severity.CRITICAL,
                f"{why}: cannot read the well file {path.name} ({exc}); the model keeps "
                f"{old.path.name}"))
            return
        if new.digest and new.digest == old.digest and new.path == old.path:
            log.info("%s: %s unchanged", why, path)
            return
        if not np.array_equal(_grid_md(new.well), self._grid_md):
            emit("alarm", alarm_message(
                t, AlarmKind.MODEL_COVERAGE, Severity.CRITICAL,
                f"{why}: the well file {path.name} changes the hole (survey, sections or "
                f"element length), which the running calibration cannot take; the model "
                f"keeps {old.path.name}: restart tdmon with the new file"))
            return
        self.well_file = new
        self._short_alarmed = False  # a new tally: check it afresh
        for target in self.targets:
            target(new, why)
        emit("alarm", alarm_message(
            t, AlarmKind.MODEL_COVERAGE, Severity.INFO,
            f"{why}: well file {path.name} in use (was {old.path.name}): string tally "
            f"{old.tally_length:.1f} m -> {new.tally_length:.1f} m, fluid "
            f"{old.well.fluid.density:.0f} -> {new.well.fluid.density:.0f} kg/m3, block "
            f"{old.well.block_weight / 1e3:.0f} -> {new.well.block_weight / 1e3:.0f} kN",
            value=new.tally_length, limit=old.tally_length))
        log.info("%s: well file %s in use", why, path)


def _grid_md(well: Any) -> np.ndarray[Any, np.dtype[np.float64]]:
    from tdmon.model.well import hole_grid

    return np.asarray(hole_grid(well).md, dtype=np.float64)


def coverage_step(config: DaemonConfig, well_file: WellFile, steps: Sequence[Step], *,
                  own_model: bool = True) -> CoverageStep:
    """The coverage step for the daemon's steps: a new well goes to the monitor (when its
    model is the well file's, ``own_model``), the calibration and the well/profile step."""
    from tdmon.config.well_file import read_well_path
    from tdmon.daemon.steps.calibrate import CalibrationStep
    from tdmon.daemon.steps.monitor import MonitorStep
    from tdmon.daemon.steps.profile import ProfileStep

    targets: list[WellTarget] = []
    for step in steps:
        if isinstance(step, MonitorStep) and own_model:
            targets.append(_monitor_target(config, step))
        elif isinstance(step, CalibrationStep):
            targets.append(_calibration_target(step))
        elif isinstance(step, ProfileStep):
            targets.append(step.new_well)
    runs = [(run.start, config.resolve(run.well)) for run in config.runs]
    return CoverageStep(well_file, runs=runs, reader=read_well_path, targets=targets)


def _monitor_target(config: DaemonConfig, monitor: Any) -> WellTarget:
    def use(well_file: WellFile, _: str) -> None:
        from tdmon.daemon.wellmodel import grid_model_for_well

        monitor.model = grid_model_for_well(config, well_file.well)
    return use


def _calibration_target(calibration: Any) -> WellTarget:
    def use(well_file: WellFile, _: str) -> None:
        from tdmon.model.torque_drag import WellModel

        calibration.use_model(WellModel(well_file.well))
    return use
