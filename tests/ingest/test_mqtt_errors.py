"""MQTT errors read by their reason code (no broker)."""

from __future__ import annotations

import aiomqtt
import pytest
from aiomqtt.exceptions import MqttConnectError
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.reasoncodes import ReasonCode

from tdmon.config.daemon import MqttConfig
from tdmon.ingest.mqtt import _translate, is_auth_failure


def _connack(name: str) -> ReasonCode:
    return ReasonCode(PacketTypes.CONNACK, name)


@pytest.mark.parametrize(("exc", "auth"), [
    # what paho 2 reports for a refused CONNACK, in MQTT 3.1.1 too
    (MqttConnectError(_connack("Not authorized")), True),  # 0x87
    (MqttConnectError(_connack("Bad user name or password")), True),  # 0x86
    (MqttConnectError(_connack("Server unavailable")), False),  # 0x88
    (aiomqtt.MqttCodeError(_connack("Not authorized"), "refused"), True),
    # MQTT 3.1.1 return codes in a refused connection
    (MqttConnectError(5), True),
    (MqttConnectError(4), True),
    (MqttConnectError(3), False),
    # elsewhere an integer is paho's error number: 5 is MQTT_ERR_CONN_REFUSED, not the password
    (aiomqtt.MqttCodeError(5, "Could not publish message"), False),
    # the text alone no longer decides
    (aiomqtt.MqttError("Not authorized"), False),
    (OSError("Connection refused"), False),
])
def test_auth_failure_is_read_from_the_reason_code(exc: BaseException, auth: bool) -> None:
    assert is_auth_failure(exc) is auth
    message = str(_translate(MqttConfig(host="broker", port=1884), "cannot connect", exc))
    assert message.startswith("mqtt broker:1884: cannot connect: ")
    assert message.endswith("(check username and password)") is auth


def test_auth_message_keeps_the_brokers_reason() -> None:
    exc = MqttConnectError(_connack("Not authorized"))
    assert str(_translate(MqttConfig(), "cannot connect", exc)) == (
        "mqtt 127.0.0.1:1883: cannot connect: [code:135] Not authorized "
        "(check username and password)")
