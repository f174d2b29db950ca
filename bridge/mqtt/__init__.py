"""The MQTT edge: one broker session (``MqttClient``) and the reconnect loop around it.

Layers, each importing only those below it (pyproject.toml, import-linter):
``reconnect`` (run_with_reconnect: the loop across sessions) -> ``session`` (MqttClient:
one session, Message) -> ``connection`` (one aiomqtt connection: the only module that
reaches into aiomqtt and paho) -> ``errors``. ``broker`` (the demo's embedded broker)
stands apart.
"""

from bridge.mqtt.errors import (
    BaseTopicTakenError,
    MqttConnectError,
    MqttDisconnectedError,
    MqttError,
    MqttPublishError,
    MqttRefusedError,
    MqttUnackedError,
    MqttUnansweredError,
)
from bridge.mqtt.reconnect import run_with_reconnect
from bridge.mqtt.session import Message, MqttClient

__all__ = [
    "BaseTopicTakenError",
    "Message",
    "MqttClient",
    "MqttConnectError",
    "MqttDisconnectedError",
    "MqttError",
    "MqttPublishError",
    "MqttRefusedError",
    "MqttUnackedError",
    "MqttUnansweredError",
    "run_with_reconnect",
]
