"""The MQTT edge: one broker session (``MqttClient``) and the reconnect loop around it."""

from bridge.mqtt.client import Message, MqttClient, run_with_reconnect
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
