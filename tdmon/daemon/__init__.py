"""The asyncio daemon: sources -> decode -> record -> align -> rig state -> monitor -> sinks."""
