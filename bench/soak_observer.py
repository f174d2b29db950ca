"""The soak's MQTT side: an observer on ``#`` and a publisher of commands, both paho
clients in their own threads that reconnect by themselves across broker restarts (the
soak must not lose its own view when it kills the broker). The observer stamps every
message with ``time.monotonic()`` as it arrives and hands it to ``Records.receive``; the
publisher sends with MQTT 5 so a command can carry a message expiry.
"""

from __future__ import annotations

import time
from typing import Any, Protocol

import paho.mqtt.client as paho
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties


class Receiver(Protocol):
    def receive(self, at: float, topic: str, payload: bytes, retain: bool) -> None: ...


class _Client:
    def __init__(self, port: int, client_id: str) -> None:
        self.port = port
        self.client = paho.Client(
            paho.CallbackAPIVersion.VERSION2, client_id=client_id, protocol=paho.MQTTv5
        )
        self.client.reconnect_delay_set(0.2, 2)

    def __enter__(self) -> _Client:
        self.client.connect_async("127.0.0.1", self.port)
        self.client.loop_start()
        return self

    def __exit__(self, *_: object) -> None:
        self.client.disconnect()
        self.client.loop_stop()


class Observer(_Client):
    def __init__(self, port: int, receiver: Receiver) -> None:
        super().__init__(port, "soak-observer")
        self.client.on_connect = self._connected
        self.client.on_message = lambda _c, _u, m: receiver.receive(
            time.monotonic(), m.topic, m.payload, m.retain
        )

    def _connected(self, client: paho.Client, *_: Any) -> None:
        client.subscribe([("modbus/#", 1), ("homeassistant/#", 0)])


class Publisher(_Client):
    def __init__(self, port: int) -> None:
        super().__init__(port, "soak-commands")

    def publish(
        self, topic: str, payload: str, *, retain: bool = False, expiry: int | None = None
    ) -> None:
        properties = None
        if expiry is not None:
            properties = Properties(PacketTypes.PUBLISH)
            properties.MessageExpiryInterval = expiry
        self.client.publish(topic, payload, qos=1, retain=retain, properties=properties)

    @property
    def connected(self) -> bool:
        return self.client.is_connected()
