"""Three sites on a 3-node NATS cluster, each node killed in turn: what a subscriber on a
surviving node sees, and which commands reach the devices (tests/integration/test_cluster.py
asserts it, bench/cluster.py prints it).

A site is a bridge (``Bridge.run()`` in this process, so its MQTT state and its
subscriptions can be read as they change) with its own simulated drive on its own Modbus TCP
port and its own base topic. Its broker is either one URL (a load balancer in front of the
nodes) or the three node URLs, starting at its own node, so that every failure hits a
different mix of sites. Per failure (``Cluster.fail(k)``): a subscriber (QoS 0, as Home
Assistant subscribes to state) on a node that stays up; a commander, also on a surviving
node, sends each site a command every ``COMMAND_EVERY`` seconds, each with its own value,
alternately at QoS 0 (Home Assistant's default) and QoS 1, one connection each, from before
the kill until ``AFTER_LIVE`` seconds after the site's command subscription is
live again; node ``k`` is killed (SIGKILL); then node ``k`` starts again and the cluster
settles before the next failure.

Per site hit by the failure, ``Failure`` has: when the bridge saw the loss, when its new
session started (CONNACK), when it said online again, when its command subscription was live, when its first value reached the
subscriber, and per command its send time and the simulator's writes of its value.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bridge.app import Bridge
from bridge.config import MqttConfig, load_config_data
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.modbus.simulator import Simulator
from bridge.mqtt import MqttClient, MqttError
from tests.integration.cluster import NatsCluster, balancing
from tests.integration.harness import cancel, serving_tcp, simulator

SITES = 3
UNIT = 1
MAPPING = "vacon_nx"
KEY = "pd_in_1"  # process data, -32768..32767, no EEPROM pacing: every command its own value
REGISTER = load_mapping(builtin_mapping_path(MAPPING)).points()[KEY].address
COMMAND_EVERY = 0.25  # seconds between two commands to one site
AFTER_LIVE = 3.0  # seconds of commands after a site's command subscription is live again
COMMAND_EXPIRY = 3.0  # mqtt.command_expiry of the bridges: a write later than this is late
SETTLE_WITHIN = 90.0  # seconds for a node to rejoin and every bridge to be live again


@dataclass
class Command:
    site: int
    value: int
    sent: float  # monotonic, before the PUBLISH left
    qos: int = 0
    # QoS 1: when the broker acknowledged it (PUBACK), the broker's now; QoS 0: when the
    # PUBLISH was handed to the socket (nothing more to wait for)
    acked: float | None = None


@dataclass
class SiteFailure:
    """One site's view of one node failure (times: monotonic seconds)."""

    site: int
    lost: float | None = None  # the bridge saw the connection end
    connected: float | None = None  # its session started again (the CONNACK came)
    online: float | None = None  # the bridge said online again
    live: float | None = None  # its command subscription was held again
    first_value: float | None = None  # its state reached the subscriber on a surviving node
    # (the first after the loss: the bridge publishes its state before it says online)
    commands: list[Command] = field(default_factory=list)
    writes: dict[int, list[float]] = field(default_factory=dict)  # value -> write times

    def judged(self) -> list[Command]:
        """The commands sent once the bridge said its command subscription was live, and
        taken by the broker (a QoS 1 one it never acknowledged is the publisher's to send
        again)."""
        assert self.live is not None
        return [c for c in self.commands if c.sent >= self.live and c.acked is not None]

    def lost_commands(self) -> list[int]:
        return [c.value for c in self.judged() if not self.writes.get(c.value)]

    def duplicated(self) -> list[int]:
        return [value for value, times in self.writes.items() if len(times) > 1]

    def late(self) -> list[int]:
        """Commands written more than the command expiry after the broker took them (on
        MQTT 3.1.1 the bridge cannot see how long a broker held a command before that)."""
        taken = {c.value: c.sent if c.acked is None else c.acked for c in self.commands}
        return [
            value
            for value, times in self.writes.items()
            if any(t - taken[value] > COMMAND_EXPIRY for t in times)
        ]

    def held(self) -> float:
        """The longest the broker held a command before acknowledging it (seconds)."""
        return max((c.acked - c.sent for c in self.commands if c.acked is not None), default=0)


@dataclass
class Failure:
    node: int
    killed: float
    sites: list[SiteFailure] = field(default_factory=list)  # those the failure cut off
    commands: list[Command] = field(default_factory=list)  # to every site


class Site:
    """One bridge, its simulator and what it went through."""

    def __init__(self, index: int, sim: Simulator, bridge: Bridge) -> None:
        self.index = index
        self.sim = sim
        self.bridge = bridge
        self.base = f"site{index}"
        self.states: list[tuple[float, str]] = []
        report = bridge._mqtt_is
        session = bridge._session

        def follow(state: str) -> None:
            self.states.append((time.monotonic(), state))
            report(state)

        async def connected(client: MqttClient) -> None:
            self.states.append((time.monotonic(), "connected"))  # the CONNACK came
            await session(client)

        bridge._mqtt_is = follow  # type: ignore[method-assign]
        bridge._session = connected  # type: ignore[method-assign]

    @property
    def live(self) -> bool:
        return self.bridge.mqtt_state == "online" and (
            self.bridge.subscriptions.states.get("commands") == "live"
        )

    def writes_since(self, since: float) -> dict[int, list[float]]:
        found: dict[int, list[float]] = {}
        for (unit, write), at in zip(self.sim.writes, self.sim.write_times, strict=True):
            if unit == UNIT and write.address == REGISTER and at >= since:
                found.setdefault(write.values[0], []).append(at)
        return found

    def event_after(self, state: str, since: float) -> float | None:
        return next((t for t, s in self.states if s == state and t >= since), None)


def site_config(index: int, modbus_port: int, urls: list[str]) -> Any:
    data = {
        "mqtt": {
            "url": urls if len(urls) > 1 else urls[0],
            "base_topic": f"site{index}",
            "discovery_prefix": f"ha-site{index}",
            "version": "3.1.1",  # what NATS speaks: no MQTT 5 attempt per connect
            "command_expiry": COMMAND_EXPIRY,
        },
        "buses": [
            {"id": "sim", "transport": "tcp", "host": "127.0.0.1", "tcp_port": modbus_port,
             "timeout": 0.5}
        ],
        "devices": [
            {"id": "drive", "bus": "sim", "unit": UNIT, "mapping": MAPPING,
             "poll": {"fast": 0.5, "slow": 5}}
        ],
    }  # fmt: skip
    return load_config_data(data, Path(f"site{index}.yaml"))


class Cluster:
    """The cluster, its sites and the failures so far."""

    def __init__(self, nats: NatsCluster, sites: list[Site]) -> None:
        self.nats = nats
        self.sites = sites
        self.failures: list[Failure] = []

    async def settled_nodes(self, within: float = SETTLE_WITHIN) -> None:
        """Every node takes MQTT clients (a QoS 1 subscription and a retained publish)."""
        async with asyncio.timeout(within):
            for url in self.nats.urls:
                while not await _usable(url):
                    await asyncio.sleep(0.3)

    async def settled(self, within: float = SETTLE_WITHIN) -> None:
        """The nodes settled, and every site online with its command subscription live."""
        await self.settled_nodes(within)
        async with asyncio.timeout(within):
            while not all(site.live for site in self.sites):
                await asyncio.sleep(0.05)

    async def fail(self, node: int) -> Failure:
        """Kill ``node`` with commands flowing; return what each site it hit went through
        (once they were live again and their commands settled); the node stays down."""
        survivor = self.nats.urls[(node + 2) % len(self.nats.urls)]
        async with (
            _subscriber(survivor, [f"{s.base}/drive" for s in self.sites]) as arrivals,
            _commander(survivor) as send,
        ):
            failure = Failure(node, time.monotonic())
            sending = asyncio.create_task(self._commands(send, failure))
            try:
                await asyncio.sleep(0.5)  # some commands before the kill
                killed = failure.killed = time.monotonic()
                await asyncio.to_thread(self.nats.kill, node)
                await asyncio.sleep(1.0)  # a broken connection is seen at once on loopback
                hit = [s for s in self.sites if s.event_after("offline", killed) is not None]
                failure.sites = [SiteFailure(s.index) for s in hit]
                async with asyncio.timeout(SETTLE_WITHIN):
                    while any(seen.live is None for seen in failure.sites):
                        for site, seen in zip(hit, failure.sites, strict=True):
                            back = site.event_after("online", killed) is not None
                            if seen.live is None and back and site.live:
                                seen.live = time.monotonic()
                        await asyncio.sleep(0.02)
                    await asyncio.sleep(AFTER_LIVE)
            finally:
                await cancel(sending)
            await asyncio.sleep(COMMAND_EXPIRY)  # the last ones written, or given up
        for site, seen in zip(hit, failure.sites, strict=True):
            seen.lost = site.event_after("offline", killed)
            assert seen.lost is not None
            seen.connected = site.event_after("connected", seen.lost)
            seen.online = site.event_after("online", killed)
            seen.writes = site.writes_since(killed - 0.5)
            seen.commands = [c for c in failure.commands if c.site == site.index]
            assert seen.online is not None
            seen.first_value = next(
                (at for topic, at in arrivals if topic == f"{site.base}/drive" and at >= seen.lost),
                None,
            )
        self.failures.append(failure)
        return failure

    async def _commands(self, send: Any, failure: Failure) -> None:
        """A command to every site each COMMAND_EVERY seconds, each with its own value."""
        value = 1000 + 1000 * len(self.failures)
        while True:
            for site in self.sites:
                value += 1
                command = Command(site.index, value, time.monotonic(), qos=value % 2)
                if await send(f"{site.base}/drive/{KEY}/set", command):
                    failure.commands.append(command)
            await asyncio.sleep(COMMAND_EVERY)

    async def restart(self, node: int) -> None:
        await asyncio.to_thread(self.nats.start, node)
        await self.settled()


async def _usable(url: str) -> bool:
    config = MqttConfig(url=url, version="3.1.1", keepalive=10)
    try:
        async with asyncio.timeout(8), MqttClient(config, will_topic="probe/state") as client:
            await client.subscribe("probe/x")
            await client.publish("probe/x", b"ok", retain=True)
    except (MqttError, TimeoutError):
        return False
    return True


@contextlib.asynccontextmanager
async def _subscriber(url: str, topics: list[str]) -> AsyncIterator[list[tuple[str, float]]]:
    """(topic, arrival) of every live message on ``topics`` at a client on ``url`` (QoS 0)."""
    arrivals: list[tuple[str, float]] = []
    config = MqttConfig(url=url, version="3.1.1", keepalive=10)
    async with MqttClient(config, will_topic="subscriber/state") as client:

        async def run() -> None:
            with contextlib.suppress(MqttError):
                async for message in client.messages():
                    arrivals.append((message.topic, message.received or time.monotonic()))

        task = asyncio.create_task(run())
        await client.subscribe(*topics, qos=0)
        try:
            yield arrivals
        finally:
            await cancel(task)


@contextlib.asynccontextmanager
async def _commander(url: str) -> AsyncIterator[Any]:
    """``send(topic, command)``: a publish of the command's value at its QoS (0, as Home
    Assistant sends commands by default, or 1) from a client on ``url``, one connection per
    QoS: on NATS 2.9 a QoS 1 PUBLISH holds the packets behind it on its connection until
    JetStream stored it, seconds while a stream elects its leader. Does not wait for the
    PUBACK; a lost connection is opened again. False: not sent (no connection)."""
    config = MqttConfig(url=url, version="3.1.1", keepalive=10)
    clients: dict[int, MqttClient] = {}
    pending: set[asyncio.Task[None]] = set()

    async def publish(client: MqttClient, topic: str, command: Command) -> None:
        with contextlib.suppress(MqttError, TimeoutError):
            async with asyncio.timeout(10):
                await client.publish(topic, str(command.value), qos=command.qos)
                command.acked = time.monotonic()

    async def send(topic: str, command: Command) -> bool:
        client = clients.get(command.qos)
        if client is None or client._connection is None or client._connection.lost:
            client = MqttClient(config, will_topic=f"commander{command.qos}/state", announce=False)
            try:
                async with asyncio.timeout(5):
                    await client.__aenter__()
            except (MqttError, TimeoutError):
                clients.pop(command.qos, None)
                return False
            clients[command.qos] = client
        task = asyncio.create_task(publish(client, topic, command))
        pending.add(task)
        task.add_done_callback(pending.discard)
        return True

    try:
        yield send
    finally:
        for task in list(pending):
            await cancel(task)
        for client in clients.values():
            with contextlib.suppress(MqttError):
                await client.__aexit__(None, None, None)


@contextlib.asynccontextmanager
async def running_sites(workdir: Path, *, balancer: bool) -> AsyncIterator[Cluster]:
    """The cluster up, three sites on it (through a balancer, or each with the node URLs
    starting at its own node), all online and live."""
    nats = NatsCluster(workdir)
    await asyncio.to_thread(nats.start)
    try:
        async with contextlib.AsyncExitStack() as stack:
            front = await stack.enter_async_context(balancing(nats)) if balancer else None
            sites: list[Site] = []
            for index in range(SITES):
                sim = simulator((UNIT, MAPPING))
                port = await stack.enter_async_context(serving_tcp(sim))
                urls = nats.urls[index:] + nats.urls[:index]
                config = site_config(index, port, [front.url] if front else urls)
                sites.append(Site(index, sim, Bridge(config)))
            cluster = Cluster(nats, sites)
            await cluster.settled_nodes()
            tasks = [asyncio.create_task(site.bridge.run()) for site in sites]
            try:
                await cluster.settled()
                yield cluster
            finally:
                for task in tasks:
                    await cancel(task)
    finally:
        await asyncio.to_thread(nats.stop)


def describe(failure: Failure) -> str:
    return json.dumps(
        {
            "node": failure.node,
            "sites": [
                {
                    "site": s.site,
                    "lost": _ms(s.lost, failure.killed),
                    "connected": _ms(s.connected, failure.killed),
                    "online": _ms(s.online, failure.killed),
                    "live": _ms(s.live, failure.killed),
                    "first_value": _ms(s.first_value, failure.killed),
                    "judged": len(s.judged()),
                    "lost_commands": s.lost_commands(),
                    "duplicated": s.duplicated(),
                    "late": s.late(),
                    "held_ms": round(1000 * s.held()),
                }
                for s in failure.sites
            ],
        }
    )


def _ms(at: float | None, since: float) -> int | None:
    return None if at is None else round(1000 * (at - since))
