"""What the web page costs the bridge: event-loop lag and polling while browsers watch.

The five seed devices are simulated on loopback TCP (2 ms per transaction, values moving
every second), the real ``Bridge`` runs against a private mosquitto with ``bridge.web``
on, and a lag probe sleeps 2 ms at a time, recording how much later than asked it wakes.
Each phase lasts ``PHASE`` seconds:

* ``idle``: the page on, nobody watching;
* ``watch``: 20 event streams on the genset's page (137 values) and 20 on the overview;
* ``fetch``: 20 clients fetching the genset's page (``api/devices/...``) back to back;
* ``stuck``: 20 event streams whose client never reads (dropped after 10 s);
* ``after``: nobody watching again (the first phase also carries the start's slow polls).

Polling is measured as bus transactions per second (the scheduler's counter): the page
must not slow it. The cost of the page's code is measured in a fresh interpreter:
import time and RSS of ``bridge.web.server`` on top of ``bridge.app``.

    .venv/bin/python bench/web_load.py
"""

from __future__ import annotations

import asyncio
import contextlib
import statistics
import subprocess
import sys
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the private broker of the tests

from latency import bridged

from bridge.app import Bridge
from bridge.config import load_config_data
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator
from tests.integration.mosquitto import Broker
from tests.ports import free_port

SEEDS = ("nastec_vasco", "p2_vfd", "soft_starter", "vacon_nx", "smartgen_hgm6100")
GENSET = "smartgen_hgm6100"
CLIENTS = 20
PHASE = 12.0
PROBE = 0.002


def config(modbus_port: int, web_port: int, broker: Broker) -> Any:
    devices = [
        {"id": name, "bus": "tcp", "unit": unit, "mapping": name, "poll": {"fast": 0.5}}
        for unit, name in enumerate(SEEDS, start=1)
    ]
    data = {
        "mqtt": {"url": broker.url},
        "bridge": {"web": {"enabled": True, "port": web_port}},
        "buses": [{"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": modbus_port}],
        "devices": devices,
    }
    return load_config_data(data, Path(__file__).with_name("web_load.yaml"))


@contextlib.asynccontextmanager
async def running() -> AsyncIterator[tuple[Bridge, int]]:
    specs = [
        SimulatedUnit(unit, load_mapping(builtin_mapping_path(name)), quirks=Quirks(latency=0.002))
        for unit, name in enumerate(SEEDS, start=1)
    ]
    sim = Simulator(specs, tick=1.0)
    web_port = free_port()
    async with bridged(sim, lambda port, broker: config(port, web_port, broker)) as (bridge, _):
        yield bridge, web_port


async def watch(port: int, path: str, counted: list[int], *, read: bool = True) -> None:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode())
    try:
        while read:
            block = await reader.readuntil(b"\n\n")
            counted[0] += block.startswith(b"event:")
        await asyncio.sleep(3600)
    except (ConnectionError, asyncio.IncompleteReadError):
        pass
    finally:
        writer.close()


async def fetch(port: int, path: str, counted: list[int]) -> None:
    while True:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode())
        await reader.read(-1)
        writer.close()
        counted[0] += 1


async def phase(bridge: Bridge, port: int, name: str, lags: list[float]) -> tuple[Any, ...]:
    counted = [0]
    scheduler = bridge.engine.schedulers["tcp"]
    async with asyncio.TaskGroup() as group:
        tasks = []
        for _ in range(CLIENTS if name in ("watch", "fetch", "stuck") else 0):
            if name == "watch":
                tasks.append(
                    group.create_task(watch(port, f"/api/events?device={GENSET}", counted))
                )
                tasks.append(group.create_task(watch(port, "/api/events", counted)))
            elif name == "fetch":
                tasks.append(group.create_task(fetch(port, f"/api/devices/{GENSET}", counted)))
            elif name == "stuck":
                path = f"/api/events?device={GENSET}"
                tasks.append(group.create_task(watch(port, path, counted, read=False)))
        before, started = scheduler.counters.transactions, time.monotonic()
        lags.clear()
        await asyncio.sleep(PHASE)
        rate = (scheduler.counters.transactions - before) / (time.monotonic() - started)
        observed = sorted(lags)
        for task in tasks:
            task.cancel()
    return name, observed, rate, counted[0] / PHASE


async def main() -> None:
    lags: list[float] = []

    async def probe() -> None:
        while True:
            asked = time.perf_counter()
            await asyncio.sleep(PROBE)
            lags.append(time.perf_counter() - asked - PROBE)

    rows = []
    async with running() as (bridge, port), asyncio.TaskGroup() as group:
        probing = group.create_task(probe())
        while not all(p.health.online for p in bridge.engine.devices.values()):
            await asyncio.sleep(0.1)
        await asyncio.sleep(2.0)
        for name in ("idle", "watch", "fetch", "stuck", "after"):
            rows.append(await phase(bridge, port, name, lags))
        probing.cancel()
    print("phase  lag p50 ms  p99 ms  max ms  bus tx/s  events or pages/s")
    for name, observed, rate, per_second in rows:
        p50 = statistics.median(observed) * 1000
        p99 = observed[min(len(observed) - 1, int(len(observed) * 0.99))] * 1000
        worst = observed[-1] * 1000
        print(f"{name:<6} {p50:>10.2f} {p99:>7.1f} {worst:>7.1f} {rate:>9.1f} {per_second:>18.1f}")
    print(import_cost())


def import_cost() -> str:
    code = (
        "import time; import bridge.app, bridge.cli; "
        "rss = lambda: int(open('/proc/self/statm').read().split()[1]) * 4096 / 2**20; "
        "a = rss(); t = time.perf_counter(); "
        "import bridge.web.server, bridge.web.http, bridge.web.access; "
        "ms = (time.perf_counter() - t) * 1000; "
        "print(f'page code: import {ms:.1f} ms, RSS +{rss() - a:.2f} MiB "
        "(bridge.app + bridge.cli: {a:.1f} MiB)')"
    )
    runs = [
        subprocess.run(  # noqa: S603 - this interpreter, this code
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        ).stdout.strip()
        for _ in range(3)
    ]
    return "\n".join(runs)


if __name__ == "__main__":
    asyncio.run(main())
