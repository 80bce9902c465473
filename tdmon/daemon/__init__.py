"""The asyncio daemon: sources -> decode -> record -> align -> rig state -> monitor -> sinks.

``pipeline`` (Sink, Step, Frame, Pipeline: the plug-in points), ``aligner``, ``rigstate``,
``monitor`` and ``wellmodel`` (the steps), ``supervisor`` (the only reconnect loop), ``daemon``
(queues, tasks, shutdown), ``build`` (config -> daemon), ``runner`` (signals, ``tdmon run``).
See docs/daemon.md.
"""
