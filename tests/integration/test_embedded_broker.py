"""The demo's embedded broker (amqtt, in a child Python) as ``mosquitto_pub``/``_sub`` use it.

Raw MQTT 3.1.1 packets, so that a test decides exactly what arrives together: a QoS 0
PUBLISH, DISCONNECT and the end of the stream in one segment (what ``mosquitto_pub``
sends when the broker is slow to read) must still reach the subscribers, and a client
gets the retained messages of its own subscriptions only.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from bridge.config import MqttConfig
from bridge.mqtt import MqttClient
from bridge.mqtt.broker import PROTOCOL
from tests.integration.brokers import AmqttBroker

pytestmark = pytest.mark.skipif(not AmqttBroker.available(), reason="no amqtt (demo extra)")


def _string(text: str) -> bytes:
    data = text.encode()
    return struct.pack("!H", len(data)) + data


def _packet(kind: int, body: bytes) -> bytes:
    length, encoded = len(body), bytearray()
    while True:
        length, digit = divmod(length, 128)
        encoded.append(digit | (0x80 if length else 0))
        if not length:
            return bytes([kind]) + bytes(encoded) + body


def connect(client_id: str) -> bytes:
    return _packet(
        0x10, _string("MQTT") + bytes([4, 0x02]) + struct.pack("!H", 60) + _string(client_id)
    )


def publish(topic: str, payload: bytes, retain: bool = False) -> bytes:
    return _packet(0x30 | int(retain), _string(topic) + payload)


def subscribe(topic_filter: str) -> bytes:
    return _packet(0x82, struct.pack("!H", 1) + _string(topic_filter) + b"\x00")


DISCONNECT = b"\xe0\x00"


@contextlib.asynccontextmanager
async def broker(workdir: Path) -> AsyncIterator[tuple[int, MqttClient]]:
    """The embedded broker and a client of it (the bridge's own MQTT client)."""
    server = AmqttBroker(workdir)
    await asyncio.to_thread(server.start)
    try:
        config = MqttConfig(url=server.url, version=PROTOCOL)  # type: ignore[arg-type]
        async with MqttClient(config, will_topic="observer/state", client_id="observer") as client:
            yield server.port, client
    finally:
        await asyncio.to_thread(server.stop)


async def send_and_leave(port: int, data: bytes) -> None:
    """One segment and the end of the stream, without waiting for any answer."""
    _, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(data)
    writer.write_eof()
    await writer.drain()
    writer.close()
    with contextlib.suppress(OSError):
        await writer.wait_closed()


@pytest.mark.asyncio
async def test_a_qos0_publish_followed_at_once_by_disconnect_reaches_a_qos1_subscriber(
    tmp_path: Path,
) -> None:
    async with broker(tmp_path) as (port, client):
        await client.publish("homeassistant/device/pump/config", "x" * 60000, retain=True)
        await client.subscribe("homeassistant/#", "modbus/+/+/set", qos=1)
        for value in (b"OFF", b"ON"):
            await send_and_leave(
                port,
                connect(f"pub-{value.decode()}")
                + publish("modbus/pump/start_stop/set", value)
                + DISCONNECT,
            )
        got = []
        async with asyncio.timeout(5):
            async for message in client.messages():
                if message.topic.endswith("/set"):
                    got.append(message.payload)
                if len(got) == 2:
                    break
        assert got == [b"OFF", b"ON"]


@pytest.mark.asyncio
async def test_a_client_gets_the_retained_messages_of_its_own_subscriptions_only(
    tmp_path: Path,
) -> None:
    async with broker(tmp_path) as (port, client):
        await client.publish("homeassistant/device/pump/config", "x" * 60000, retain=True)
        await client.subscribe("homeassistant/#")  # someone else's subscription
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(connect("watcher") + subscribe("modbus/pump"))
        await writer.drain()
        received = b""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(1.5):
                while chunk := await reader.read(65536):
                    received += chunk
        writer.write(DISCONNECT)
        async with asyncio.timeout(5):  # the broker closes its end: nothing left open
            assert await reader.read() == b""
        writer.close()
        with contextlib.suppress(OSError):
            await writer.wait_closed()
        assert received == b"\x20\x02\x00\x00" + b"\x90\x03\x00\x01\x00"  # CONNACK, SUBACK
