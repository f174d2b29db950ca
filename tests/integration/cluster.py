"""A 3-node NATS cluster with MQTT on every node, and a TCP load balancer in front of it.

``NatsCluster(workdir)``: three nats-server processes on free loopback ports, each with its
own config (``server_name``, a ``cluster`` block naming the other two as routes, its own
JetStream store and an MQTT listener whose streams and consumers are kept on 3 replicas,
``mqtt { stream_replicas, consumer_replicas }``), so that any one node can die without
losing retained messages or sessions. ``kill(i)`` ends a node as a crash would (SIGKILL),
``start(i)`` brings it back on the same ports with its data. ``ready()`` waits until an
MQTT client on every node can publish and subscribe (the MQTT streams exist once
JetStream has a meta leader, a few seconds after the start).

``Balancer``: one address in front of the nodes (what haproxy in TCP mode does with
``balance first``): each client connection goes to the first node that accepts, and is
closed when that node's side closes, so the client reconnects through the balancer to a
node still alive.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import subprocess
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path

from tests.integration.brokers import NATS_SERVER, NatsBroker
from tests.integration.mosquitto import HOST
from tests.ports import free_port

NODES = 3


@dataclass
class NatsNode:
    """One nats-server of the cluster: its ports, config and process."""

    name: str
    workdir: Path
    mqtt_port: int = field(default_factory=free_port)
    client_port: int = field(default_factory=free_port)
    route_port: int = field(default_factory=free_port)
    http_port: int = field(default_factory=free_port)  # monitoring: /jsz counts consumers
    process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"mqtt://{HOST}:{self.mqtt_port}"

    @property
    def log(self) -> str:
        path = self.workdir / "nats.log"
        return path.read_text(errors="replace")[-4000:] if path.exists() else ""

    def write_config(self, routes: list[int]) -> Path:
        store = self.workdir / "jetstream"
        store.mkdir(parents=True, exist_ok=True)
        others = ", ".join(f"nats-route://{HOST}:{port}" for port in routes)
        path = self.workdir / "nats.conf"
        path.write_text(
            f'server_name: "{self.name}"\n'
            f"listen: {HOST}:{self.client_port}\n"
            f"http: {HOST}:{self.http_port}\n"
            f'jetstream {{ store_dir: "{store}" }}\n'
            f"cluster {{ name: pytest-{os.getpid()}, listen: {HOST}:{self.route_port}, "
            f"routes: [{others}] }}\n"
            f"mqtt {{ listen: {HOST}:{self.mqtt_port}, stream_replicas: {NODES}, "
            f"consumer_replicas: {NODES} }}\n"
        )
        return path

    def start(self) -> None:
        with (self.workdir / "nats.log").open("ab") as log:
            self.process = subprocess.Popen(
                [NATS_SERVER, "-c", str(self.workdir / "nats.conf")],
                stdout=log,
                stderr=subprocess.STDOUT,
                cwd=self.workdir,
                start_new_session=True,
            )

    def kill(self) -> None:
        """SIGKILL: no goodbye to clients or to the other nodes."""
        if self.process is not None and self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait(10)
        self.process = None

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGTERM)
            try:
                self.process.wait(20)
            except subprocess.TimeoutExpired:
                self.kill()
        self.process = None

    def listening(self) -> bool:
        import socket  # noqa: PLC0415

        try:
            with socket.create_connection((HOST, self.mqtt_port), timeout=0.2):
                return True
        except OSError:
            return False


class NatsCluster:
    """Three nodes; ``urls`` in node order."""

    available = staticmethod(NatsBroker.available)

    def __init__(self, workdir: Path) -> None:
        self.nodes = [NatsNode(f"n{i}", workdir / f"n{i}") for i in range(NODES)]
        for node in self.nodes:
            node.write_config([n.route_port for n in self.nodes if n is not node])

    @property
    def urls(self) -> list[str]:
        return [node.url for node in self.nodes]

    @property
    def log(self) -> str:
        return "\n".join(f"--- {node.name}\n{node.log}" for node in self.nodes)

    def start(self, index: int | None = None, within: float = 30.0) -> None:
        """Start every node (or one) and wait until it listens for MQTT clients."""
        nodes = self.nodes if index is None else [self.nodes[index]]
        for node in nodes:
            node.start()
        deadline = time.monotonic() + within
        while not all(node.listening() for node in nodes):
            for node in nodes:
                if node.process is None or node.process.poll() is not None:
                    raise RuntimeError(f"nats-server {node.name} exited:\n{node.log}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"the cluster did not listen in time:\n{self.log}")
            time.sleep(0.05)

    def kill(self, index: int) -> None:
        self.nodes[index].kill()

    def stop(self) -> None:
        for node in self.nodes:
            node.stop()


class Balancer:
    """A TCP load balancer on a free loopback port in front of ``targets`` (host, port):
    a connection goes to the first target that accepts (in order), bytes are relayed both
    ways, and either side closing closes the other."""

    def __init__(self, targets: list[tuple[str, int]]) -> None:
        self.targets = targets
        self.url = ""
        self.chosen: list[int] = []  # the target index of each connection, in order
        self._writers: set[asyncio.StreamWriter] = set()

    async def serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        upstream = await self._connect()
        if upstream is None:
            writer.transport.abort()
            return
        up_reader, up_writer = upstream
        self._writers |= {writer, up_writer}
        try:
            await asyncio.gather(_pipe(reader, up_writer), _pipe(up_reader, writer))
        finally:
            self._writers -= {writer, up_writer}

    async def _connect(self) -> tuple[asyncio.StreamReader, asyncio.StreamWriter] | None:
        for index, (host, port) in enumerate(self.targets):
            try:
                async with asyncio.timeout(1.0):
                    found = await asyncio.open_connection(host, port)
            except (OSError, TimeoutError):
                continue
            self.chosen.append(index)
            return found
        return None

    def close(self) -> None:
        for writer in list(self._writers):
            writer.transport.abort()


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    """Copy until the reading side ends, then close the writing side (abort it when the
    reading side broke: a side that died says no goodbye, so neither does the balancer)."""
    try:
        while chunk := await reader.read(65536):
            writer.write(chunk)
            await writer.drain()
    except ConnectionError:
        writer.transport.abort()
    else:
        writer.close()


@contextlib.asynccontextmanager
async def balancing(cluster: NatsCluster) -> AsyncIterator[Balancer]:
    balancer = Balancer([(HOST, node.mqtt_port) for node in cluster.nodes])
    server = await asyncio.start_server(balancer.serve, HOST, 0)
    balancer.url = f"mqtt://{HOST}:{server.sockets[0].getsockname()[1]}"
    try:
        yield balancer
    finally:
        server.close()
        balancer.close()
