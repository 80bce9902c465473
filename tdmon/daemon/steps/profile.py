"""The well and profile step: the trajectory and its profiles along MD for the 3D and profile
views (``well`` and ``profile`` messages), and its construction from the configuration."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from tdmon.daemon.pipeline import Emit, Frame, Step
from tdmon.daemon.steps.mu_t import MuTSetup, mu_t_setup

if TYPE_CHECKING:
    from tdmon.config.daemon import DaemonConfig
    from tdmon.config.well_file import WellFile
    from tdmon.daemon.steps.calibrate import CalibrationStep

__all__ = ["MAX_PROFILE_POINTS", "ProfileStep", "profile_step", "run_context"]


class ProfileStep:
    """Step: the well's trajectory and its profiles along MD for the 3D and profile views.

    On the first frame it emits ``well`` (the hole grid's nodes: ``md_m``, ``tvd_m``,
    ``north_m``, ``east_m``; the well file's ``name``, ``file`` and ``string_length_m``, its
    tally; ``change`` = ``"start"``) and a ``profile`` (``temperature_C`` of the annulus when
    the well file has a temperature model, and the friction: the calibration's local profile
    when one runs, else the well file's friction); the ``well`` message's ``notes`` say why
    the mu(T) calibration is off when it is. A new run's well file or a reload sends ``well``
    again, ``change`` saying which (:meth:`new_well`). Afterwards a ``profile`` follows
    whenever the calibration's friction profile has changed, at most every ``interval``
    seconds of rig time, and once more at the end.
    Both are stamped with the frame's time, not the wall clock, so that a replay keeps one time
    axis and gives the same messages at any speed.

    Parameters
    ----------
    well_message : the ``well`` message without ``t``
    md : MD of the profile points [m]
    element_index : hole-grid element of each profile point
    temperature : annulus temperature per hole-grid element [degC], or None
    friction : the well file's friction per element [-], or None
    calibration : the calibration step whose profile is reported, or None
    interval : shortest time between two ``profile`` messages [s]
    mu_t_note : why the mu(T) calibration is off (None: it runs, or there is nothing to say)
    """

    name = "profile"

    def __init__(self, well_message: dict[str, Any], md: NDArray[np.float64],
                 element_index: NDArray[np.int64], *,
                 temperature: NDArray[np.float64] | None = None,
                 friction: NDArray[np.float64] | None = None,
                 calibration: CalibrationStep | None = None, interval: float = 30.0,
                 mu_t_note: str | None = None) -> None:
        self.well_message = well_message
        self.md = np.asarray(md, dtype=np.float64)
        self.element_index = np.asarray(element_index, dtype=np.int64)
        self.temperature = temperature
        self.friction = friction
        self.calibration = calibration
        self.interval = interval
        self.mu_t_note = mu_t_note
        self._started = False
        self._new_well = False
        self._sent_updates = 0
        self._sent_t = -math.inf
        self._last_t: float | None = None

    def new_well(self, well_file: WellFile, change: str) -> None:
        """Send the ``well`` message of ``well_file`` on the next frame: a new run's well file
        or a reload (:mod:`tdmon.daemon.steps.coverage`), said in ``change``. The hole, and so
        the trajectory, is the same."""
        self.well_message = {**self.well_message, **_well_fields(well_file), "change": change}
        self._new_well = True

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        self._last_t = frame.t
        if self._new_well and self._started:
            self._new_well = False
            emit("well", {"t": frame.t, **self.well_message, "notes": []})
        if not self._started:
            self._started = True
            # the note rides on the start-up message rather than an alarm: nothing is wrong
            # on the rig, and dashboards read the well message once anyway
            notes = [] if self.mu_t_note is None else [self.mu_t_note]
            emit("well", {"t": frame.t, **self.well_message, "notes": notes})
            self._send(frame.t, emit)
            return
        calibration = self.calibration
        if (calibration is not None and calibration.profile_updates != self._sent_updates
                and frame.t - self._sent_t >= self.interval):
            self._send(frame.t, emit)

    def close(self, emit: Emit) -> None:
        calibration = self.calibration
        if (self._last_t is not None and calibration is not None
                and calibration.profile_updates != self._sent_updates):
            self._send(self._last_t, emit)

    def message(self, t: float) -> dict[str, Any] | None:
        """The ``profile`` message now (None when there is nothing to show)."""
        message: dict[str, Any] = {"t": t, "md_m": self.md.tolist()}
        if self.temperature is not None:
            message["temperature_C"] = self.temperature[self.element_index].tolist()
        if self.calibration is not None:
            profile = self.calibration.profile
            bins = profile.grid.element_bin[self.element_index]
            message["mu"] = profile.state.mu[bins].tolist()
            message["mu_std"] = profile.state.std[bins].tolist()
            # what the windows taught each point's bin (docs/recording.md): views grey out or
            # leave out the uninformed ones and say why
            info = profile.information()
            message["variance_ratio"] = info.variance_ratio[bins].tolist()
            message["informed"] = info.informed[bins].tolist()
            message["uninformed_reason"] = [info.reason[k] for k in bins.tolist()]
        elif self.friction is not None:
            message["mu"] = self.friction[self.element_index].tolist()
        if "mu" not in message and "temperature_C" not in message:
            return None
        # a non-finite value would be written as null and break the arrays' number schema
        if not all(np.isfinite(message[key]).all()
                   for key in ("temperature_C", "mu", "mu_std", "variance_ratio")
                   if key in message):
            return None
        return message

    def _send(self, t: float, emit: Emit) -> None:
        if self.calibration is not None:
            self._sent_updates = self.calibration.profile_updates
        self._sent_t = t
        message = self.message(t)
        if message is not None:
            emit("profile", message)


#: at most this many points in a ``well`` or ``profile`` message (a 6 km well at 1 m elements
#: would otherwise send 6000-point arrays every profile interval)
MAX_PROFILE_POINTS = 500


def profile_step(config: DaemonConfig, well_file: WellFile, grid: Any,
                 setup: MuTSetup | None = None, calibration: CalibrationStep | None = None
                 ) -> Step:
    """The step emitting ``well`` and ``profile`` (see :class:`ProfileStep`)."""
    if setup is None:
        setup = mu_t_setup(config.model_copy(update={
            "calibration": config.calibration.model_copy(update={"mu_t": "off"})}),
            well_file, grid)
        setup = replace(setup, note=None)  # no calibration: nothing to explain
    nodes = _thin(grid.md.size)
    well_message = {
        **_well_fields(well_file), "change": "start",
        "md_m": grid.md[nodes].tolist(), "tvd_m": grid.tvd[nodes].tolist(),
        "north_m": grid.north[nodes].tolist(), "east_m": grid.east[nodes].tolist(),
        **run_context(config, well_file, setup, calibration),
    }
    elements = _thin(grid.n_elements)
    return ProfileStep(well_message, grid.element_mid_md[elements], elements,
                       temperature=setup.temperature, friction=setup.friction,
                       calibration=calibration, interval=config.calibration.profile_interval,
                       mu_t_note=setup.note)


def _well_fields(well_file: WellFile) -> dict[str, Any]:
    """What a ``well`` message says about the file: its name, path and string tally [m]."""
    return {"name": well_file.well.name or well_file.path.stem, "file": well_file.path.name,
            "string_length_m": well_file.tally_length}


def run_context(config: DaemonConfig, well_file: WellFile, setup: MuTSetup,
                calibration: CalibrationStep | None) -> dict[str, Any]:
    """What a report needs to say which run this was: the daemon file, the torque-and-drag methods,
    the hole sections and the friction law being calibrated (fields of the ``well`` message).
    """
    law = setup.law
    return {
        "daemon_file": None if config.source_file is None else config.source_file.name,
        "method": config.monitor.method,
        "backcalc_method": None if calibration is None else calibration.settings.method,
        "mu_t_mode": "off" if law is None else setup.mode,
        "mu_t_law": None if law is None else law.describe(),
        "sections": [
            {"name": section.name, "kind": section.kind, "top_m": section.top,
             "bottom_m": section.bottom,
             "friction": None if section.friction is None
             else section.friction.friction_model().describe()}
            for section in well_file.config.hole
        ],
    }


def _thin(n: int) -> NDArray[np.int64]:
    """Indices of at most MAX_PROFILE_POINTS evenly spread points out of n, ends included."""
    stride = max(1, math.ceil(n / MAX_PROFILE_POINTS))
    index = np.arange(0, n, stride, dtype=np.int64)
    if index[-1] != n - 1:
        index = np.append(index, n - 1)
    return index
