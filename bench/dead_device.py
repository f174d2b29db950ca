"""How much a dead unit on a shared bus delays the live ones.

Four live soft starters and, in the second run, one dead unit share one bus (the
simulator on loopback TCP, 20 ms added per transaction like a slow serial device).
Every unit polls its fast class every 0.5 s. The figures are the poll period each live
unit achieved and the bus time the dead unit cost: offline after 3 timeouts, then one
probe per backoff interval (5 s doubling to 300 s), never a retry while offline.

    .venv/bin/python bench/dead_device.py [seconds]
"""

from __future__ import annotations

import asyncio
import itertools
import statistics
import sys
import time
from pathlib import Path

from bridge.config import load_config_data
from bridge.core.entity import PollClass
from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DevicePoller
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator

LIVE = (1, 2, 3, 4)
DEAD = 9
TIMEOUT = 0.5
FAST = 0.5


def stamp_fast_polls(devices: dict[str, DevicePoller], stamps: dict[str, list[float]]) -> None:
    """Record in ``stamps`` when each device finished a poll of its fast class (the poll
    loop passes the intervals due in seconds: the fast one is ``FAST``)."""
    for device_id, poller in devices.items():
        original = poller.poll
        stamps[device_id] = []

        async def timed(
            classes: object, device_id: str = device_id, original: object = original
        ) -> None:
            await original(classes)  # type: ignore[operator]
            if FAST in classes or PollClass.FAST in classes:  # type: ignore[operator]
                stamps[device_id].append(time.monotonic())

        poller.poll = timed  # type: ignore[method-assign,assignment]


async def run(seconds: float, with_dead: bool) -> dict[str, float]:
    mapping = load_mapping(builtin_mapping_path("soft_starter"))
    units = [SimulatedUnit(u, mapping, quirks=Quirks(latency=0.02)) for u in LIVE]
    units.append(SimulatedUnit(DEAD, mapping, quirks=Quirks(dead=True)))
    sim = Simulator(units, tick=0)
    server = asyncio.create_task(sim.serve_tcp("127.0.0.1", 0))
    await sim.ready.wait()
    devices = [
        {
            "id": f"u{u}",
            "bus": "b",
            "unit": u,
            "mapping": "soft_starter",
            "poll": {"fast": FAST, "slow": 3600},
        }
        for u in (*LIVE, *([DEAD] if with_dead else []))
    ]
    bus = {
        "id": "b",
        "transport": "tcp",
        "host": "127.0.0.1",
        "tcp_port": sim.port,
        "timeout": TIMEOUT,
        "retries": 1,
    }
    engine = Engine(load_config_data({"buses": [bus], "devices": devices}, Path("bench.yaml")))
    stamps: dict[str, list[float]] = {}
    stamp_fast_polls(engine.devices, stamps)
    task = asyncio.create_task(engine.run())
    await asyncio.sleep(seconds)
    task.cancel()
    server.cancel()
    await asyncio.gather(task, server, return_exceptions=True)
    periods = [b - a for u in LIVE for a, b in itertools.pairwise(stamps[f"u{u}"][2:])]
    scheduler = engine.schedulers["b"]
    dead = engine.devices.get(f"u{DEAD}")
    return {
        "live period mean ms": 1000 * statistics.fmean(periods),
        "live period p95 ms": 1000 * statistics.quantiles(periods, n=20)[-1],
        "live period max ms": 1000 * max(periods),
        "bus transactions": scheduler.counters.transactions,
        "bus timeouts": scheduler.counters.timeouts,
        "bus busy %": 100 * scheduler.counters.busy_seconds / seconds,
        "dead unit timeouts": dead.health.timeouts if dead else 0,
    }


async def main(seconds: float) -> None:
    alone = await run(seconds, with_dead=False)
    shared = await run(seconds, with_dead=True)
    print(
        f"{len(LIVE)} live units + dead unit, fast poll {FAST} s, timeout {TIMEOUT} s, "
        f"{seconds:.0f} s each run\n"
    )
    print("| figure | live units only | with a dead unit | ratio |")
    print("| --- | ---: | ---: | ---: |")
    for name in alone:
        a, b = alone[name], shared[name]
        ratio = f"{b / a:.2f}" if a else "-"
        print(f"| {name} | {a:.1f} | {b:.1f} | {ratio} |")


if __name__ == "__main__":
    asyncio.run(main(float(sys.argv[1]) if len(sys.argv) > 1 else 60.0))
