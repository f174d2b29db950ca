"""How long the bridge's event loop is held up under attack, and what that does to a command.

The five seed devices are simulated on loopback TCP (2 ms per transaction), the real
``Bridge`` runs against a private mosquitto (``tests/integration/mosquitto.py``), and a lag
probe sleeps 2 ms at a time, recording how much later than asked it wakes: anything that
holds the loop (a callback, a parse, a build) shows up as lag. Each phase floods the bridge
the way a hostile or careless client would, then publishes one command (``vacon_nx``
``run``, alternately ON and OFF) and times it from the publish to the write reaching the
simulator (``Simulator.write_times``, stamped on arrival):

* ``idle``: polling only;
* ``ha_online``: 200 ``online`` on ``homeassistant/status``;
* ``get``: 500 empty ``/get`` for one device;
* ``bad_set``: 1000 malformed ``/set``;
* ``oversized``: 20 payloads of 200 kB (not UTF-8) on ``/set`` and on a request topic;
* ``requests``: 50 ``device/read`` and 5 ``device/scan`` of units 1-247 on the bus;
* ``reload``: 5 ``mapping/reload`` of every device (info, discovery and state again).

Everything runs in this one process (the simulator too), so the lag includes its work.
``--slow MS`` also turns on asyncio's debug mode and lists the callbacks that held the loop
longer than MS milliseconds (debug mode slows everything down: figures are not comparable).

    .venv/bin/python bench/loop_block.py [--slow MS]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import statistics
import sys
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the private broker of the tests

from latency import bridged

from bridge.app import Bridge
from bridge.config import MqttConfig, load_config_data
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator
from bridge.mqtt import MqttClient
from tests.integration.mosquitto import Broker

SEEDS = ("nastec_vasco", "p2_vfd", "soft_starter", "vacon_nx", "smartgen_hgm6100")
VACON = 4
LATENCY = 0.002
PROBE = 0.002


class LagProbe:
    """Sleeps ``PROBE`` seconds at a time and keeps how late each wake-up was."""

    def __init__(self) -> None:
        self.lags: list[float] = []

    async def run(self) -> None:
        while True:
            asked = time.perf_counter()
            await asyncio.sleep(PROBE)
            self.lags.append(time.perf_counter() - asked - PROBE)

    def take(self) -> list[float]:
        lags, self.lags = self.lags, []
        return lags


class SlowCallbacks(logging.Handler):
    """Collects asyncio's debug-mode reports of callbacks that held the loop too long."""

    def __init__(self) -> None:
        super().__init__()
        self.reports: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if "took" in record.getMessage():
            self.reports.append(record.getMessage())


def config(port: int, broker: Broker) -> Any:
    devices = [
        {
            "id": name,
            "bus": "tcp",
            "unit": unit,
            "mapping": name,
            "poll": {"fast": 0.5, "slow": 5},
            "protocol": {"min_request_interval": 0.05} if name == "smartgen_hgm6100" else {},
        }
        for unit, name in enumerate(SEEDS, start=1)
    ]
    data = {
        "mqtt": {"url": broker.url, "command_expiry": 5},
        "bridge": {"health_interval": 5, "scan_timeout": 0.02},
        "buses": [
            {"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port, "timeout": 0.2}
        ],
        "devices": devices,
    }
    return load_config_data(data, Path(__file__).with_name("loop_block.yaml"))


@contextlib.asynccontextmanager
async def running() -> AsyncIterator[tuple[Simulator, Bridge, Broker]]:
    quirks = Quirks(latency=LATENCY)
    specs = [
        SimulatedUnit(unit, load_mapping(builtin_mapping_path(name)), quirks=quirks)
        for unit, name in enumerate(SEEDS, start=1)
    ]
    sim = Simulator(specs, tick=1.0)
    async with bridged(sim, config) as (bridge, broker):
        yield sim, bridge, broker


Flood = Callable[[MqttClient], Awaitable[None]]


async def ha_online(client: MqttClient) -> None:
    for _ in range(200):
        await client.publish("homeassistant/status", "online", qos=0)


async def get(client: MqttClient) -> None:
    for _ in range(500):
        await client.publish("modbus/nastec_vasco/get", "", qos=0)


async def bad_set(client: MqttClient) -> None:
    for _ in range(1000):
        await client.publish("modbus/smartgen_hgm6100/set", "{not json", qos=0)


async def oversized(client: MqttClient) -> None:
    payload = b"\xff" * 200_000
    for _ in range(10):
        await client.publish("modbus/p2_vfd/set", payload, qos=0)
        await client.publish("modbus/bridge/request/device/read", payload, qos=0)


async def requests(client: MqttClient) -> None:
    for address in range(50):
        read = {"device": "p2_vfd", "address": 0x1000 + address, "count": 2}
        await client.publish("modbus/bridge/request/device/read", json.dumps(read), qos=0)
    for _ in range(5):
        await client.publish("modbus/bridge/request/device/scan", '{"units": "1-247"}', qos=0)


async def reload(client: MqttClient) -> None:
    for _ in range(5):
        await client.publish("modbus/bridge/request/mapping/reload", "{}", qos=0)


async def idle(_: MqttClient) -> None:
    await asyncio.sleep(0.5)


PHASES: dict[str, Flood] = {
    "idle": idle,
    "ha_online": ha_online,
    "get": get,
    "bad_set": bad_set,
    "oversized": oversized,
    "requests": requests,
    "reload": reload,
}


async def command(client: MqttClient, sim: Simulator, on: bool) -> float:
    """Publish one command; seconds until the write reached the simulated Vacon."""
    seen = len(sim.writes)
    sent = time.monotonic()
    await client.publish("modbus/vacon_nx/run/set", "ON" if on else "OFF", qos=1)
    deadline = sent + 10
    while time.monotonic() < deadline:
        for index in range(seen, len(sim.writes)):
            if sim.writes[index][0] == VACON:
                return sim.write_times[index] - sent
        await asyncio.sleep(0.001)
    return float("nan")


async def main(slow: float | None) -> None:
    if slow is not None:
        loop = asyncio.get_running_loop()
        loop.set_debug(True)
        loop.slow_callback_duration = slow / 1000
        reports = SlowCallbacks()
        logging.getLogger("asyncio").addHandler(reports)
    probe = LagProbe()
    rows = []
    async with running() as (sim, bridge, broker), asyncio.TaskGroup() as group:
        probing = group.create_task(probe.run())
        mqtt = MqttConfig(url=broker.url)
        async with MqttClient(mqtt, will_topic="bench/state", client_id="bench") as client:
            while not all(p.health.online for p in bridge.engine.devices.values()):
                await asyncio.sleep(0.1)
            await asyncio.sleep(2.0)  # discovery and the first full state are out
            for index, (name, flood) in enumerate(PHASES.items()):
                probe.take()
                started = time.monotonic()
                await flood(client)
                latency = await command(client, sim, on=index % 2 == 0)
                await asyncio.sleep(2.0)  # what the flood set off (reads, republishes) runs
                lags = sorted(probe.take())
                rows.append((name, lags, latency, time.monotonic() - started))
        probing.cancel()
    print(f"{'phase':<10} {'wakeups':>8} {'lag p99 ms':>11} {'lag max ms':>11} {'command ms':>11}")
    for name, lags, latency, _ in rows:
        p99 = lags[min(len(lags) - 1, int(len(lags) * 0.99))] * 1000
        print(
            f"{name:<10} {len(lags):>8} {p99:>11.1f} {lags[-1] * 1000:>11.1f} "
            f"{latency * 1000:>11.1f}"
        )
    every = [lag for _, lags, _, _ in rows for lag in lags]
    print(f"all phases: lag median {statistics.median(every) * 1000:.2f} ms")
    if slow is not None:
        print(f"\ncallbacks holding the loop over {slow} ms (asyncio debug mode):")
        for report in reports.reports[:40]:
            print(" ", report[:300])


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--slow", type=float, default=None, metavar="MS")
    asyncio.run(main(parser.parse_args().slow))
