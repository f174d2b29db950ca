"""The gateway (issue 29): what a proxied read costs a master, and what the cache saves.

One RTU line at 19200 baud (a pty pair, the simulator at the far end) carries a Nastec
pump (unit 1, one register per read) and a soft starter (unit 3), both polled by the
bridge (fast class every second, slow every 10 s). The engine, the dispatcher and the
gateway run as in ``run`` (no MQTT: it plays no part in a proxied read).

1. Latency: a pymodbus client reads one register of the starter through the gateway, one
   read at a time, after a random pause (0-300 ms) so reads land at every phase of the
   poll cycle. Its latency is measured at the client, and shown in ms and in bus
   transactions (the line's mean transaction time, from its own counters): the added
   latency is what the read waits for the transaction in flight and the commands ahead of
   it, then its own transaction.
2. Cache: a master polls every second what the bridge polls anyway (the starter's
   fast-class block), for ``seconds``, once with ``max_age: 0`` and once with
   ``max_age: 2`` (twice the poll period): the bus transactions the gateway sent for it,
   and the line's total.

    .venv/bin/python bench/gateway.py [reads] [seconds]
"""

from __future__ import annotations

import asyncio
import random
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pymodbus.client import AsyncModbusTcpClient

from bridge.config import load_config_data
from bridge.core.entity import PollClass
from bridge.dispatcher import Dispatcher
from bridge.gateway import Gateway
from bridge.modbus.engine import Engine
from tests.integration.harness import cancel, running, serving_serial, simulator

BAUD = 19200
PUMP, STARTER = 1, 3


def config(path: str, max_age: float) -> Any:
    return load_config_data(
        {
            "bridge": {
                "gateway": {
                    "enabled": True,
                    "port": 0,
                    "units": {1: "pump", 3: "starter"},
                    "max_age": max_age,
                }
            },
            "buses": [
                {"id": "line", "transport": "rtu", "port": path, "baudrate": BAUD}
                | {"timeout": 0.5}
            ],
            "devices": [
                {"id": d, "bus": "line", "unit": u, "mapping": m, "poll": {"fast": 1, "slow": 10}}
                for d, u, m in (
                    ("pump", PUMP, "nastec_vasco"),
                    ("starter", STARTER, "soft_starter"),
                )
            ],
        },
        Path("bench-gateway.yaml"),
    )


async def with_gateway(max_age: float, work: Any) -> Any:
    sim = simulator((PUMP, "nastec_vasco"), (STARTER, "soft_starter"))
    async with serving_serial(sim, baudrate=BAUD) as path:
        loaded = config(path, max_age)
        engine = Engine(loaded)
        dispatcher = Dispatcher(engine, 5.0, spawn=_unused, error=_unused, read=_unused)
        gateway = Gateway(loaded, engine, dispatcher)
        async with running(engine):
            task = asyncio.create_task(gateway.run())
            try:
                await asyncio.wait_for(gateway.server.ready.wait(), 5)
                while not all(p.first_poll_done for p in engine.devices.values()):
                    await asyncio.sleep(0.05)
                client = AsyncModbusTcpClient("127.0.0.1", port=gateway.server.port, timeout=5)
                await client.connect()
                try:
                    return await work(client, engine, gateway)
                finally:
                    client.close()
            finally:
                await cancel(task)


def _unused(*_: object) -> None:
    """The dispatcher's MQTT-side callbacks: no MQTT here."""


async def latency(reads: int) -> dict[str, float]:
    async def work(client: AsyncModbusTcpClient, engine: Engine, _: Gateway) -> Any:
        rng = random.Random(29)  # noqa: S311 - a benchmark's pauses
        times = []
        counters = engine.schedulers["line"].counters
        start_tx, start_busy = counters.transactions, counters.busy_seconds
        for _ in range(reads):
            await asyncio.sleep(rng.uniform(0, 0.3))
            began = time.perf_counter()
            reply = await client.read_holding_registers(4101, count=1, device_id=STARTER)
            times.append(time.perf_counter() - began)
            assert not reply.isError(), reply
        mean_tx = (counters.busy_seconds - start_busy) / (counters.transactions - start_tx)
        return times, mean_tx

    times, mean_tx = await with_gateway(0.0, work)
    cuts = statistics.quantiles(times, n=100)
    return {
        "reads": reads,
        "mean_transaction_ms": mean_tx * 1000,
        "p50_ms": statistics.median(times) * 1000,
        "p95_ms": cuts[94] * 1000,
        "p50_transactions": statistics.median(times) / mean_tx,
        "p95_transactions": cuts[94] / mean_tx,
    }


async def cache(max_age: float, seconds: float) -> dict[str, float]:
    async def work(client: AsyncModbusTcpClient, engine: Engine, gateway: Gateway) -> Any:
        (block, *_) = engine.devices["starter"].state.plan([PollClass.FAST])
        counters = engine.schedulers["line"].counters
        start_tx = counters.transactions
        began = time.monotonic()
        polls = 0
        while time.monotonic() - began < seconds:
            reply = await client.read_holding_registers(
                block.address, count=block.count, device_id=STARTER
            )
            assert not reply.isError(), reply
            polls += 1
            await asyncio.sleep(max(0.0, began + polls - time.monotonic()))
        elapsed = time.monotonic() - began
        totals = gateway.book.totals()
        return {
            "max_age": max_age,
            "block": f"{block.table.value} {block.address}+{block.count}",
            "master_reads": polls,
            "from_cache": totals.cached,
            "gateway_transactions": gateway.transactions["line"],
            "line_transactions_per_min": (counters.transactions - start_tx) * 60 / elapsed,
        }

    return await with_gateway(max_age, work)


async def main(reads: int, seconds: float) -> None:
    print("latency:", {k: round(v, 2) for k, v in (await latency(reads)).items()})
    for max_age in (0.0, 2.0):
        print("cache:", await cache(max_age, seconds))


if __name__ == "__main__":
    arguments = [float(a) for a in sys.argv[1:]]
    asyncio.run(
        main(int(arguments[0]) if arguments else 200, arguments[1] if len(arguments) > 1 else 60)
    )
