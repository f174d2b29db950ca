"""The web page's test harness: a running bridge with the page on, a raw HTTP client, an
event-stream reader. Plain sockets, so that every header and byte is the test's choice."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bridge.app import Bridge
from bridge.cli.demo import BrokerChoice, demo_config
from bridge.cli.demo_site import SITES
from bridge.config import load_config_data
from bridge.modbus.simulator import Simulator
from tests.integration.harness import cancel, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.ports import free_port

PUMP, STARTER = 1, 3
TOKEN = "cabinet-token-0123456789"


@dataclass
class Site:
    """A running bridge (pump on unit 1, soft starter on unit 3) and its page's port."""

    bridge: Bridge
    sim: Simulator
    port: int


@contextlib.asynccontextmanager
async def site(
    broker: Broker, folder: Path, *, bridge: dict[str, Any] | None = None, **web: Any
) -> AsyncIterator[Site]:
    """The bridge with ``bridge.web`` on (``web`` settings on top), fast polls."""
    sim = simulator((PUMP, "nastec_vasco"), (STARTER, "soft_starter"), tick=0)
    port = free_port()
    async with serving_tcp(sim) as modbus_port:
        data = {
            "mqtt": {"url": broker.url, "command_expiry": 3},
            "bridge": {
                "scan_timeout": 0.1,
                "web": {"enabled": True, "host": "127.0.0.1", "port": port} | web,
            }
            | (bridge or {}),
            "buses": [
                {"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": modbus_port}
                | {"timeout": 0.3}
            ],
            "devices": [
                {"id": "pump", "bus": "tcp", "unit": PUMP, "mapping": "nastec_vasco"},
                {"id": "starter", "bus": "tcp", "unit": STARTER, "mapping": "soft_starter"},
            ],
        }
        for device in data["devices"]:
            device["poll"] = {"fast": 0.2, "slow": 2}
        running = Bridge(load_config_data(data, folder / "config.yaml"))
        task = asyncio.create_task(running.run())
        try:
            await listening(port)
            yield Site(running, sim, port)
        finally:
            await cancel(task)


@contextlib.asynccontextmanager
async def demo_site(broker: Broker, folder: Path) -> AsyncIterator[Site]:
    """The demo's site (``demo --site seeds``): the five seed devices as units 1..5 on the
    bus ``demo``, with the demo's names and config; their values stand still (tick 0), so
    what the page says of them is the same at every run."""
    seeds = SITES["seeds"]
    sim = simulator(*((d.unit, d.mapping) for d in seeds.devices), tick=0)
    port = free_port()
    async with serving_tcp(sim) as modbus_port:
        args = argparse.Namespace(base_topic="modbus", site=seeds.name, username=None)
        args.password_file = args.password_env = None
        where = {"demo": f"127.0.0.1:{modbus_port}"}
        config = demo_config(BrokerChoice(broker.url, "given"), where, args, web_port=port)
        running = Bridge(config)
        task = asyncio.create_task(running.run())
        try:
            await listening(port)
            yield Site(running, sim, port)
        finally:
            await cancel(task)


async def listening(port: int) -> None:
    """Wait until the web page accepts connections."""
    async with asyncio.timeout(10):
        while True:
            try:
                _, writer = await asyncio.open_connection("127.0.0.1", port)
            except OSError:
                await asyncio.sleep(0.05)
                continue
            writer.close()
            return


@dataclass
class Answer:
    status: int
    headers: dict[str, str]
    body: bytes

    def json(self) -> Any:
        return json.loads(self.body)


def request_bytes(
    method: str, path: str, port: int, body: object = None, headers: dict[str, str] | None = None
) -> bytes:
    sent = {"Host": f"127.0.0.1:{port}"} | (headers or {})
    data = b""
    if body is not None:
        data = body if isinstance(body, bytes) else json.dumps(body).encode()
        sent.setdefault("Content-Type", "application/json")
        sent["Content-Length"] = str(len(data))
    head = f"{method} {path} HTTP/1.1\r\n" + "".join(f"{k}: {v}\r\n" for k, v in sent.items())
    return (head + "\r\n").encode("latin-1") + data


async def http(
    port: int,
    method: str,
    path: str,
    body: object = None,
    headers: dict[str, str] | None = None,
    *,
    source: str | None = None,
) -> Answer:
    """One request; the server closes the connection after its answer."""
    local = (source, 0) if source else None
    reader, writer = await asyncio.open_connection("127.0.0.1", port, local_addr=local)
    try:
        writer.write(request_bytes(method, path, port, body, headers))
        async with asyncio.timeout(30):  # a scan of a few units answers in well under that
            raw = await reader.read(-1)
    finally:
        writer.close()
    return parse_answer(raw)


def parse_answer(raw: bytes) -> Answer:
    head, _, body = raw.partition(b"\r\n\r\n")
    status_line, *lines = head.decode("latin-1").split("\r\n")
    headers = {}
    for line in lines:
        name, _, value = line.partition(":")
        headers[name.strip().lower()] = value.strip()
    return Answer(int(status_line.split(" ")[1]), headers, body)


@dataclass
class Events:
    """An open event stream: ``next(name)`` returns the data of the next such event."""

    reader: asyncio.StreamReader
    writer: asyncio.StreamWriter
    status: int = 0
    seen: list[tuple[str, Any]] = field(default_factory=list)

    async def next(self, name: str, check: Any = None, timeout: float = 10.0) -> Any:
        async with asyncio.timeout(timeout):
            while True:
                event, data = await self._one()
                self.seen.append((event, data))
                if event == name and (check is None or check(data)):
                    return data

    async def _one(self) -> tuple[str, Any]:
        block = await self.reader.readuntil(b"\n\n")
        event, lines = "message", []
        for line in block.decode("utf-8").split("\n"):
            if line.startswith("event: "):
                event = line.removeprefix("event: ")
            elif line.startswith("data: "):
                lines.append(line.removeprefix("data: "))
        return event, json.loads("\n".join(lines)) if lines else None


@contextlib.asynccontextmanager
async def events(
    port: int, path: str = "/api/events", headers: dict[str, str] | None = None
) -> AsyncIterator[Events]:
    reader, writer = await asyncio.open_connection("127.0.0.1", port, limit=2**22)
    try:
        writer.write(request_bytes("GET", path, port, headers=headers))
        head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), 10)
        stream = Events(reader, writer, parse_answer(head).status)
        yield stream
    finally:
        writer.close()
