"""The daemon's steps, one per module, each a thin adapter of `tdmon.calib`'s pure estimators.

In pipeline order: `rig_state.RigStateStep`, `monitor.MonitorStep`,
`calibrate.CalibrationStep` (around `tdmon.calib.estimator`), `alarms.AlarmStep`,
`profile.ProfileStep`; `compose` builds them from the configuration. Nothing is imported here,
so that a daemon without the calibration does not load the calibration's modules.
"""
