"""tdmon: real-time torque-and-drag monitoring and friction back-calculation."""

__version__ = "0.1.0"
