"""Estimation, synchronous and pure: lab regression, rig-state detection, back-calculation, the
local friction profile and live mu(T) calibration. Nothing here does I/O."""
