"""The calibration's daemon steps, under their former module name.

The steps live one per module in `tdmon.daemon.steps` and the policy in
`tdmon.calib.estimator`; this module keeps ``from tdmon.daemon.calibrate import ...`` working.
"""

from tdmon.calib.estimator import CalibrationSettings
from tdmon.daemon.steps.alarms import AlarmStep
from tdmon.daemon.steps.calibrate import CalibrationStep
from tdmon.daemon.steps.profile import ProfileStep
from tdmon.daemon.steps.rig_state import RigStateStep

__all__ = ["AlarmStep", "CalibrationSettings", "CalibrationStep", "ProfileStep", "RigStateStep"]
