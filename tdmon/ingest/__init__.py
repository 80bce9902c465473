"""Sources (MQTT, Zenoh, MCAP replay) and the pure payload decoders kept apart from them."""
