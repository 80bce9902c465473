"""The asyncio daemon: sources -> decode -> record -> align -> rig state -> monitor -> sinks.

``pipeline`` (Step, Frame, Pipeline: the plug-in points), ``aligner``, ``clock`` (rig clock
faults), ``loss`` (seq and sampling gaps), ``monitor`` and ``wellmodel``, ``steps/`` (one step per
module, each adapting a pure object of tdmon.calib), ``supervisor`` (the only reconnect loop),
``daemon`` (queues, tasks, acknowledgements, shutdown), ``build`` with the ``sources`` and
``sinks`` tables and ``wiring`` (config -> daemon), ``runner`` (signals, ``tdmon run``).
See docs/daemon.md.
"""
