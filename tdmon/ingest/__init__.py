"""Sources (MQTT, Zenoh, MCAP replay, WITS0, OPC UA) and the pure decoders kept apart from them.

``decode`` (bytes -> Sample | Rejected, no I/O), ``types`` (RawMessage, Sample, Rejected and
their daemon message shapes), ``mqtt`` / ``zenoh_io`` / ``mcap_source`` (async context
managers yielding RawMessages, plus the result publishers), ``wits0`` (the pure WITS Level 0
codec), ``wits0_source`` (its daemon source) and ``wits0_server`` (the simulator's server),
``opcua`` (pure: engineering units, data values as payloads), ``opcua_source`` and
``opcua_server`` (the OPC UA source and the simulator's server), ``witsml`` and
``witsml_well`` (WITSML 1.4.1.1 and 1.3.1.1 logs, 1.4.1.1 well objects), ``lab`` (tribometer
CSV files), ``publish`` (the rig side used by ``tdmon publish``). Reconnecting is the daemon
supervisor's job, not the sources'.
"""
