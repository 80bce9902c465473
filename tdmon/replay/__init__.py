"""Rig sessions for replay: the simulator, real-data import and the replay driver."""
