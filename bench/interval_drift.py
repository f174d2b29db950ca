"""Each entity's measured poll interval on a real bus (issue 35).

The engine (one ``DevicePoller`` per device, one ``BusScheduler`` per bus) polls the
simulator over loopback TCP (20 ms added per transaction, like a slow serial device) for
``SECONDS`` (default 120; issue 35 asks for 1800). The mapping has entities at 5 s, 60 s
and 600 s on neighbouring registers (and one 60 s entity given 600 s by the device
config). Every poll pass is stamped when it starts, with the intervals due in it; an
entity's measured interval is the time between two passes its interval was due in. The
reads the simulator answered give the transactions per hour.

    .venv/bin/python bench/interval_drift.py [SECONDS]
"""

from __future__ import annotations

import asyncio
import statistics
import sys
import tempfile
import time
from itertools import pairwise
from pathlib import Path

from bridge.config import load_config_data
from bridge.core.mapping import load_mapping
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DevicePoller
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator

MAPPING = """\
manufacturer: Bench
model: Three intervals
description: entities at 5 s, 60 s and 600 s on neighbouring registers
source: {title: made up for bench/interval_drift.py}
entities:
  power: {name: Power, address: 1, poll: 5s}
  voltage: {name: Voltage, address: 2, poll: 5s}
  temperature: {name: Temperature, address: 3, poll: 60s}
  energy_today: {name: Energy today, address: 4, type: u32, poll: 1m}
  energy_total: {name: Energy total, address: 6, type: u32, poll: 10m}
  fault: {name: Fault, address: 20, poll: 5}
  serial_number: {name: Serial number, address: 21, poll: 60}
  limit: {name: Limit, address: 40, access: rw, poll: 600}
"""


def stamp_passes(poller: DevicePoller, stamps: list[tuple[float, frozenset[float]]]) -> None:
    """Record when each poll pass starts and the intervals due in it."""
    original = poller.poll

    async def stamped(due: object) -> None:
        chosen = frozenset(map(poller.state.rule.seconds, due))  # type: ignore[call-overload]
        stamps.append((time.monotonic(), chosen))
        await original(due)  # type: ignore[arg-type]

    poller.poll = stamped  # type: ignore[method-assign]


async def run(seconds: float, folder: Path) -> None:
    path = folder / "three_intervals.yaml"
    path.write_text(MAPPING)
    unit = SimulatedUnit(1, load_mapping(path), quirks=Quirks(latency=0.02))
    sim = Simulator([unit], tick=0, read_log=100_000)
    server = asyncio.create_task(sim.serve_tcp("127.0.0.1", 0))
    await sim.ready.wait()
    device = {
        "id": "meter",
        "bus": "b",
        "unit": 1,
        "mapping": str(path),
        "poll": {"fast": 5, "slow": 600, "entities": {"serial_number": "10m"}},
    }
    bus = {"id": "b", "transport": "tcp", "host": "127.0.0.1", "tcp_port": sim.port}
    engine = Engine(load_config_data({"buses": [bus], "devices": [device]}, Path("bench.yaml")))
    poller = engine.devices["meter"]
    stamps: list[tuple[float, frozenset[float]]] = []
    stamp_passes(poller, stamps)
    task = asyncio.create_task(engine.run())
    await asyncio.sleep(seconds)
    task.cancel()
    server.cancel()
    await asyncio.gather(task, server, return_exceptions=True)
    report(poller, stamps, len(sim.reads(1)), seconds)


def report(
    poller: DevicePoller, stamps: list[tuple[float, frozenset[float]]], reads: int, seconds: float
) -> None:
    per_entity = sum(3600 / i for i in poller.state.intervals.values())
    print(
        f"{seconds:g} s, {len(stamps)} passes, {reads} reads ({reads * 3600 / seconds:.0f}/h; "
        f"one read per entity: {per_entity:.0f}/h)"
    )
    print("| entity | nominal s | polls | min s | mean s | max s | within 10 % |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | --- |")
    for key, nominal in poller.state.intervals.items():
        times = [at for at, due in stamps if nominal in due]
        gaps = [b - a for a, b in pairwise(times)]
        if not gaps:
            print(f"| {key} | {nominal:g} | {len(times)} | - | - | - | (run longer) |")
            continue
        ok = all(abs(gap - nominal) <= 0.1 * nominal for gap in gaps)
        low, mean, high = min(gaps), statistics.fmean(gaps), max(gaps)
        row = f"| {key} | {nominal:g} | {len(times)} | {low:.3f} | {mean:.3f} | {high:.3f} |"
        print(f"{row} {'yes' if ok else 'NO'} |")


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 120.0
    with tempfile.TemporaryDirectory() as folder:
        asyncio.run(run(seconds, Path(folder)))


if __name__ == "__main__":
    main()
