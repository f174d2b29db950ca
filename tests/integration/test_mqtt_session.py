"""The session the reconnect loop keeps (bridge/mqtt/reconnect.py, docs/brokers.md): one client
id for every connection of a run, clean start, nothing kept by the broker.

The case it is for: a connection the bridge lost but the broker still believes in (a node
or a network path that went quiet; here a relay that drops the bridge's side and leaves the
broker's open). The bridge reconnects at once; with the same client id the broker ends the
old connection there and then, so its will (``offline``) comes before the new ``online``.
With a new id per connection (before: an empty one, which the broker fills in) the old one lived on until the broker gave up
on it (keepalive x 1.5) and its will then said ``offline`` over a bridge that was online.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

import pytest

from bridge.config import MqttConfig
from bridge.mqtt import MqttClient
from bridge.mqtt.reconnect import run_with_reconnect
from tests.integration.harness import cancel, eventually
from tests.integration.mosquitto import Broker
from tests.integration.test_bridge import observing

WILL = "session/bridge/state"


class Strander:
    """Client <-> strander <-> broker; ``strand()`` drops every client side and keeps the
    broker sides open and silent (the broker keeps believing in those connections)."""

    def __init__(self, broker: Broker) -> None:
        self.broker = broker
        self.url = ""
        self._clients: set[asyncio.StreamWriter] = set()
        self._stranded: list[asyncio.StreamWriter] = []

    def strand(self) -> None:
        for writer in list(self._clients):
            writer.transport.abort()

    async def serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        up_reader, up_writer = await asyncio.open_connection(self.broker.host, self.broker.port)
        self._clients.add(writer)

        async def down() -> None:
            with contextlib.suppress(ConnectionError):
                while chunk := await up_reader.read(65536):
                    if not writer.is_closing():
                        writer.write(chunk)

        task = asyncio.ensure_future(down())
        with contextlib.suppress(ConnectionError):
            while chunk := await reader.read(65536):
                up_writer.write(chunk)
        self._clients.discard(writer)
        writer.transport.abort()
        self._stranded.append(up_writer)  # left open: no DISCONNECT, no FIN
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)

    def close(self) -> None:
        for writer in self._stranded:
            writer.transport.abort()


@contextlib.asynccontextmanager
async def stranding(broker: Broker) -> AsyncIterator[Strander]:
    strander = Strander(broker)
    server = await asyncio.start_server(strander.serve, "127.0.0.1", 0)
    strander.url = f"mqtt://127.0.0.1:{server.sockets[0].getsockname()[1]}"
    try:
        yield strander
    finally:
        server.close()
        strander.close()


async def _keep_session(config: MqttConfig, ids: list[str]) -> None:
    async def session(client: MqttClient) -> None:
        ids.append(client.client_id)
        async for _ in client.messages():  # until the connection is lost
            pass

    await run_with_reconnect(config, WILL, session)


@pytest.mark.asyncio
@pytest.mark.parametrize("version", ["5", "3.1.1"])
async def test_a_reconnect_ends_the_connection_the_broker_still_holds(
    mosquitto: Broker, version: str
) -> None:
    async with stranding(mosquitto) as strander, observing(mosquitto, WILL) as observer:
        config = MqttConfig(url=strander.url, keepalive=1, version=version)  # type: ignore[arg-type]
        ids: list[str] = []
        task = asyncio.create_task(_keep_session(config, ids))
        try:
            await eventually(lambda: observer.retained.get(WILL) == b"online")
            strander.strand()
            await eventually(lambda: len(ids) == 2)
            await eventually(lambda: [m.payload for m in observer.log][-1:] == [b"online"])
            # the old connection would have expired after 1.5 s: nothing comes over online
            await asyncio.sleep(2.5)
        finally:
            await cancel(task)
    said = [m.payload for m in observer.log]
    assert said[-1] == b"offline"  # the clean stop
    assert said[:-1] == [b"online", b"offline", b"online"]  # the old will came first
    assert ids[0] == ids[1] and ids[0].startswith("modbusbridge")


@pytest.mark.asyncio
async def test_each_run_has_its_own_id_unless_one_is_configured(mosquitto: Broker) -> None:
    runs: list[list[str]] = [[], [], []]
    configs = [MqttConfig(url=mosquitto.url)] * 2 + [
        MqttConfig(url=mosquitto.url, client_id="site-a")
    ]
    tasks = [
        asyncio.create_task(_keep_session(c, ids)) for c, ids in zip(configs, runs, strict=True)
    ]
    try:
        await eventually(lambda: all(runs))
    finally:
        for task in tasks:
            await cancel(task)
    first, second, configured = (ids[0] for ids in runs)
    assert first != second
    assert configured == "site-a"
