"""Command latency through the whole bridge: MQTT command -> write on the wire -> value back.

Five soft starters share one bus (the simulator on loopback TCP, 20 ms per transaction
like a slow serial device) and poll continuously (fast class every 0.5 s, settings every
30 s, readings wandering every second: the bus is about 70 % busy). The real ``Bridge``
runs against a private mosquitto on a free loopback port (``tests/integration/
mosquitto.py``, never the system broker). A second MQTT client sends ``motor_run``
commands (plain ``<base>/<device>/motor_run/set``, QoS 1), one at a time, to one unit
after another, always the opposite of the unit's current value, after a random pause so
commands land at every phase of the poll cycle. For each command:

* command -> wire: from just before the publish to the simulator receiving the write
  (``Simulator.write_times``, stamped on arrival, before the unit's latency);
* command -> MQTT: to the device's JSON state carrying the new value (the topic Home
  Assistant reads) arriving at the subscriber; the bridge publishes the value the unit
  acknowledged, before the read-back that confirms it;
* wire -> MQTT: the part after the write reached the device (its answer, the publish).

The broker runs with ``set_tcp_nodelay true`` as deploy/mosquitto ships it (the bridge's
MQTT client, used here for the commands too, sets TCP_NODELAY itself); a third run keeps
mosquitto's default (Nagle's algorithm on its client sockets), which can hold a command
in the broker until the bridge acknowledges earlier data (up to 40 ms). The
second run adds a dead unit on the same bus (timeout 0.5 s): its timeouts and backoff
probes hold the bus, so a live unit's command may wait for one of them.
Everything runs in this one process (one event loop), so the figures include the
simulator's own work.

    .venv/bin/python bench/latency.py [commands]
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import random
import statistics
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the private broker of the tests

from dead_device import stamp_fast_polls

from bridge.app import Bridge
from bridge.config import LoadedConfig, MqttConfig, load_config_data
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator
from bridge.mqtt import MqttClient
from tests.integration.mosquitto import Broker

LIVE = (1, 2, 3, 4, 5)
DEAD = 9
LATENCY = 0.02
TIMEOUT = 0.5
FAST, SLOW = 0.5, 30.0
KEY = "motor_run"
BASE = "modbus"


class NodelayBroker(Broker):
    """The private broker with ``set_tcp_nodelay true``, as deploy/mosquitto ships it."""

    def _config(self) -> str:
        return super()._config() + "set_tcp_nodelay true\n"


@dataclass
class Run:
    """What one run measured."""

    to_wire: list[float] = field(default_factory=list)
    to_mqtt: list[float] = field(default_factory=list)
    wire_to_mqtt: list[float] = field(default_factory=list)
    periods: list[float] = field(default_factory=list)
    transaction: float = 0.0  # mean seconds per bus transaction
    busy: float = 0.0  # fraction of the run the bus carried a frame


class Watcher:
    """Subscribes to every device's JSON state; resolves a waiter when a value arrives."""

    def __init__(self, client: MqttClient) -> None:
        self.client = client
        self.current: dict[str, object] = {}
        self.waiting: dict[str, tuple[object, asyncio.Future[float]]] = {}

    async def run(self) -> None:
        async for message in self.client.messages():
            arrived = time.monotonic()
            device = message.topic.removeprefix(f"{BASE}/")
            value = json.loads(message.payload).get(KEY)
            self.current[device] = value
            wanted = self.waiting.get(device)
            if wanted is not None and wanted[0] == value and not wanted[1].done():
                wanted[1].set_result(arrived)


def config(port: int, broker: Broker, units: tuple[int, ...]) -> Any:
    devices = [
        {
            "id": f"u{unit}",
            "bus": "b",
            "unit": unit,
            "mapping": "soft_starter",
            "poll": {"fast": FAST, "slow": SLOW},
        }
        for unit in units
    ]
    bus = {
        "id": "b",
        "transport": "tcp",
        "host": "127.0.0.1",
        "tcp_port": port,
        "timeout": TIMEOUT,
        "retries": 1,
    }
    data = {"mqtt": {"url": broker.url, "base_topic": BASE}, "buses": [bus], "devices": devices}
    return load_config_data(data, Path("bench.yaml"))


async def command(
    client: MqttClient, watcher: Watcher, sim: Simulator, unit: int, run: Run
) -> None:
    """One command to ``unit``: the opposite of its current value; wait for it to come back."""
    device = f"u{unit}"
    value = not watcher.current[device]
    arrived: asyncio.Future[float] = asyncio.get_running_loop().create_future()
    watcher.waiting[device] = (value, arrived)
    seen = len(sim.writes)
    sent = time.monotonic()
    await client.publish(f"{BASE}/{device}/{KEY}/set", "ON" if value else "OFF", qos=1)
    back = await asyncio.wait_for(arrived, 10)
    wire = next(
        sim.write_times[i] for i in range(seen, len(sim.writes)) if sim.writes[i][0] == unit
    )
    run.to_wire.append(wire - sent)
    run.to_mqtt.append(back - sent)
    run.wire_to_mqtt.append(back - wire)


@contextlib.asynccontextmanager
async def bridged(
    sim: Simulator,
    config_for: Callable[[int, Broker], LoadedConfig],
    broker_class: type[Broker] = Broker,
) -> AsyncIterator[tuple[Bridge, Broker]]:
    """A private broker, ``sim`` on a free loopback port and, in this process, the bridge
    of ``config_for(the simulator's port, the broker)``, for the duration of the block."""
    with tempfile.TemporaryDirectory() as folder:
        broker = broker_class(Path(folder))
        broker.start()
        try:
            async with asyncio.TaskGroup() as group:
                server = group.create_task(sim.serve_tcp("127.0.0.1", 0))
                await sim.ready.wait()
                bridge = Bridge(config_for(sim.port, broker))
                task = group.create_task(bridge.run())
                yield bridge, broker
                task.cancel()
                server.cancel()
        finally:
            broker.stop()


@contextlib.asynccontextmanager
async def running(
    units: tuple[int, ...], nodelay: bool
) -> AsyncIterator[tuple[Simulator, Bridge, str]]:
    """A private broker, the simulator (``DEAD`` never answers) and the bridge polling
    ``units``; yields them and the broker's URL."""
    mapping = load_mapping(builtin_mapping_path("soft_starter"))
    specs = [SimulatedUnit(u, mapping, quirks=Quirks(latency=LATENCY)) for u in LIVE]
    specs.append(SimulatedUnit(DEAD, mapping, quirks=Quirks(dead=True)))
    sim = Simulator(specs, tick=1.0)
    kind = NodelayBroker if nodelay else Broker
    async with bridged(sim, lambda port, broker: config(port, broker, units), kind) as (
        bridge,
        broker,
    ):
        yield sim, bridge, broker.url


async def measure(commands: int, with_dead: bool, nodelay: bool, seed: int) -> Run:
    run, stamps = Run(), dict[str, list[float]]()
    rng = random.Random(seed)  # noqa: S311 - pauses, not secrets
    units = (*LIVE, *([DEAD] if with_dead else []))
    async with running(units, nodelay) as (sim, bridge, url):
        stamp_fast_polls(bridge.engine.devices, stamps)
        mqtt = MqttConfig(url=url)
        async with MqttClient(mqtt, will_topic="bench/state", client_id="bench") as client:
            watcher = Watcher(client)
            watching = asyncio.create_task(watcher.run())
            await client.subscribe(*(f"{BASE}/u{u}" for u in LIVE))
            while len(watcher.current) < len(LIVE) or time.monotonic() - bridge.engine.started < 5:
                await asyncio.sleep(0.1)  # settled: first polls done, the dead unit offline
            counters = bridge.engine.schedulers["b"].counters
            started, busy = time.monotonic(), counters.busy_seconds
            for unit in itertools.islice(itertools.cycle(LIVE), commands):
                await asyncio.sleep(rng.uniform(0.1, 0.9))
                await command(client, watcher, sim, unit, run)
            run.busy = (counters.busy_seconds - busy) / (time.monotonic() - started)
            run.transaction = counters.busy_seconds / counters.transactions
            watching.cancel()
    run.periods = [
        b - a for u in LIVE for a, b in itertools.pairwise(stamps[f"u{u}"]) if a >= started
    ]
    return run


def percentiles(values: list[float]) -> list[float]:
    cuts = statistics.quantiles(values, n=100, method="inclusive")
    return [statistics.median(values), cuts[94], cuts[98], max(values)]


def ms(seconds: float) -> str:
    return f"{1000 * seconds:.1f}"


def report(alone: Run, shared: Run, nagle: Run) -> None:
    tx = alone.transaction
    print("| figure | p50 ms | p95 ms | p99 ms | max ms | target ms | met |")
    print("| --- | ---: | ---: | ---: | ---: | --- | --- |")
    rows = [  # label, values, target (seconds), the statistic it bounds
        ("command -> wire", alone.to_wire, tx + 0.010, "p95"),
        ("command -> value on MQTT", alone.to_mqtt, 2 * tx + 0.010, "p95"),
        ("wire -> value on MQTT", alone.wire_to_mqtt, tx + 0.010, "p95"),
        ("dead unit on the bus: command -> wire", shared.to_wire, TIMEOUT + tx, "max"),
        ("dead unit on the bus: command -> value on MQTT", shared.to_mqtt, None, ""),
        ("mosquitto defaults (Nagle): command -> wire", nagle.to_wire, tx + 0.010, "p95"),
        ("mosquitto defaults (Nagle): command -> value", nagle.to_mqtt, 2 * tx + 0.010, "p95"),
    ]
    for label, values, target, bounded in rows:
        p50, p95, p99, top = figures = percentiles(values)
        checked = figures[("p50", "p95", "p99", "max").index(bounded)] if bounded else 0.0
        met = "-" if target is None else ("yes" if checked <= target else "no")
        shown = "-" if target is None else f"{bounded} <= {ms(target)}"
        print(f"| {label} | {ms(p50)} | {ms(p95)} | {ms(p99)} | {ms(top)} | {shown} | {met} |")
    print("\n| live poll period | live units only | with a dead unit | ratio |")
    print("| --- | ---: | ---: | ---: |")
    for label, pick in (
        ("mean ms", statistics.fmean),
        ("p95 ms", lambda v: statistics.quantiles(v, n=20)[-1]),
        ("max ms", max),
    ):
        a, b = pick(alone.periods), pick(shared.periods)
        print(f"| {label} | {ms(a)} | {ms(b)} | {b / a:.2f} |")
    print(
        f"\nOne transaction: {ms(alone.transaction)} ms mean (latency {ms(LATENCY)} ms + "
        f"loopback); bus busy {100 * alone.busy:.0f} % (live units only), "
        f"{100 * shared.busy:.0f} % (with the dead unit). Floors on a busy bus: command -> "
        f"wire = the frame in flight ({ms(tx)} ms), command -> value = the frame in flight "
        f"+ the write ({ms(2 * tx)} ms)."
    )


async def main(commands: int) -> None:
    alone = await measure(commands, with_dead=False, nodelay=True, seed=1)
    shared = await measure(commands, with_dead=True, nodelay=True, seed=2)
    nagle = await measure(commands, with_dead=False, nodelay=False, seed=1)
    print(
        f"{len(LIVE)} soft starters on one bus, {ms(LATENCY)} ms per transaction, fast poll "
        f"{FAST} s, slow {SLOW} s, timeout {TIMEOUT} s; {commands} motor_run commands per run\n"
    )
    report(alone, shared, nagle)


if __name__ == "__main__":
    asyncio.run(main(int(sys.argv[1]) if len(sys.argv) > 1 else 200))
