"""The farewell at a stop (bridge.mqtt.client) against a broker that acknowledges late or not
at all: a real mosquitto behind a relay that holds back what the broker answers (PUBACKs)
while passing on everything the client sends. Whatever the broker does, the will topic
must not be left ``online``. Where a test shortens ``FAREWELL_TIMEOUT``, it is to keep the
test short, not to replace anything."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

import pytest

from bridge.mqtt import MqttClient
from bridge.mqtt import client as client_module
from tests.integration.harness import eventually
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import Observer, observing
from tests.integration.test_mqtt_client import STATE, cfg


class Relay:
    """Client <-> relay <-> broker. ``delay``: the broker's answers reach the client that
    many seconds late; ``hold``: they never do (a broker that stops acknowledging)."""

    def __init__(self, broker: Broker) -> None:
        self.broker = broker
        self.delay = 0.0
        self.hold = False

    async def serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        up_reader, up_writer = await asyncio.open_connection(self.broker.host, self.broker.port)
        down = asyncio.ensure_future(self._down(up_reader, writer))
        try:
            while chunk := await reader.read(65536):  # the client's packets: at once
                up_writer.write(chunk)
                await up_writer.drain()
        except ConnectionError:
            pass
        finally:
            up_writer.close()  # no DISCONNECT passed: the broker sends the will
            writer.close()
            await asyncio.gather(down, return_exceptions=True)

    async def _down(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        loop = asyncio.get_running_loop()

        def write(chunk: bytes) -> None:
            if not writer.is_closing():
                writer.write(chunk)

        while chunk := await reader.read(65536):
            if self.hold:
                continue
            if self.delay:
                loop.call_later(self.delay, write, chunk)
            else:
                write(chunk)
        writer.close()


@contextlib.asynccontextmanager
async def relayed(broker: Broker) -> AsyncIterator[tuple[Relay, str]]:
    relay = Relay(broker)
    server = await asyncio.start_server(relay.serve, "127.0.0.1", 0)
    try:
        yield relay, f"mqtt://127.0.0.1:{server.sockets[0].getsockname()[1]}"
    finally:
        server.close()


def devices_offline(count: int) -> list[tuple[str, str]]:
    return [(f"t/device{i}/availability", "offline") for i in range(count)]


def state(observer: Observer) -> bytes | None:
    return observer.retained.get(STATE)


@pytest.mark.asyncio
async def test_a_broker_that_stops_acknowledging_is_left_offline(
    mosquitto: Broker, monkeypatch: pytest.MonkeyPatch
) -> None:
    """More farewell messages than paho keeps in flight (20): the goodbye waits behind them
    and never goes out. No clean DISCONNECT then, so the broker publishes the will."""
    monkeypatch.setattr(client_module, "FAREWELL_TIMEOUT", 0.5)
    async with observing(mosquitto, "t/#") as observer, relayed(mosquitto) as (relay, url):
        client = MqttClient(cfg(url), will_topic=STATE)
        await client.__aenter__()
        await eventually(lambda: state(observer) == b"online")
        client.farewell = lambda: devices_offline(30)
        relay.hold = True
        await client.__aexit__(None, None, None)
        await eventually(lambda: state(observer) == b"offline")


@pytest.mark.asyncio
async def test_farewell_messages_are_acknowledged_together(mosquitto: Broker) -> None:
    """Each acknowledgement a second late: one after the other, ten would take twice the
    FAREWELL_TIMEOUT; together they take one second."""
    farewell = devices_offline(10)
    async with observing(mosquitto, "t/#") as observer, relayed(mosquitto) as (relay, url):
        client = MqttClient(cfg(url), will_topic=STATE)
        await client.__aenter__()
        await eventually(lambda: state(observer) == b"online")
        client.farewell = lambda: farewell
        relay.delay = 1.0
        await client.__aexit__(None, None, None)
        await eventually(lambda: state(observer) == b"offline")
        assert all(observer.retained.get(topic) == b"offline" for topic, _ in farewell)
