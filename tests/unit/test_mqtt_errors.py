"""Which refused connects are a refused login (the long reconnect backoff) and which a
passing condition of the broker (the normal one): CONNACK reason codes as paho reports
them, by name, for MQTT 5 and translated from MQTT 3.1.1 return codes."""

from __future__ import annotations

import pytest
from paho.mqtt.client import convert_connack_rc_to_reason_code
from paho.mqtt.enums import ConnackCode
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.reasoncodes import ReasonCode

from bridge.mqtt import MqttConnectError

LOGIN = [
    "Client identifier not valid",
    "Bad user name or password",
    "Not authorized",
    "Banned",
    "Bad authentication method",
]
PASSING = [
    "Unspecified error",
    "Unsupported protocol version",
    "Server unavailable",
    "Server busy",
    "Quota exceeded",
    "Connection rate exceeded",
    "Use another server",
    "Server moved",
]


def connack(name: str) -> int:
    return int(ReasonCode(PacketTypes.CONNACK, name).value)  # type: ignore[no-untyped-call]


@pytest.mark.parametrize(
    ("name", "refused"), [(n, True) for n in LOGIN] + [(n, False) for n in PASSING]
)
def test_mqtt5_reason_codes(name: str, refused: bool) -> None:
    assert MqttConnectError("x", connack(name)).refused is refused


@pytest.mark.parametrize(
    ("code", "refused"),
    [
        (ConnackCode.CONNACK_REFUSED_PROTOCOL_VERSION, False),
        (ConnackCode.CONNACK_REFUSED_IDENTIFIER_REJECTED, True),
        (ConnackCode.CONNACK_REFUSED_SERVER_UNAVAILABLE, False),
        (ConnackCode.CONNACK_REFUSED_BAD_USERNAME_PASSWORD, True),
        (ConnackCode.CONNACK_REFUSED_NOT_AUTHORIZED, True),
    ],
)
def test_mqtt311_return_codes_as_paho_translates_them(code: ConnackCode, refused: bool) -> None:
    translated = convert_connack_rc_to_reason_code(code).value
    assert MqttConnectError("x", translated).refused is refused


def test_no_answer_is_no_refusal() -> None:
    assert MqttConnectError("cannot connect", None).refused is False
