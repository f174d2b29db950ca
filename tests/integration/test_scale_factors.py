"""``scale_by`` end to end: the real engine polls the simulator (loopback TCP and RTU on a
pty pair) while the simulator changes values and their exponents together, every few
milliseconds, so that changes land between the reads of one poll. Every value published
is raw x 10**exponent of one moment's pair, never a value of one moment with the exponent
of another; a write is encoded with the exponent the device holds, and refused, with
nothing on the wire, when that exponent is "not implemented"."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import time
from collections.abc import AsyncIterator
from decimal import Decimal
from pathlib import Path
from typing import Any

import pytest

from bridge.core.entity import Table
from bridge.core.mapping import load_mapping
from bridge.errors import BridgeError
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DeviceUpdate
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator
from tests.integration.harness import (
    FAST_POLICY,
    config,
    eventually,
    running,
    serving_serial,
    serving_tcp,
    tcp_bus,
)

# Reads of at most 8 registers: a pass takes three reads; a, b and c are read with sf,
# never apart (a planner that cut 0..7 | 8..14 would scale a and b by the next moment's).
MAPPING = """\
manufacturer: Test
model: Scaled
description: values scaled by exponent registers, as a SunSpec model lays them out
source: {title: test}
protocol: {max_read_registers: 8}
entities:
  n0: {name: Noise 0, address: 0}
  n1: {name: Noise 1, address: 1}
  n2: {name: Noise 2, address: 2}
  n3: {name: Noise 3, address: 3}
  n4: {name: Noise 4, address: 4}
  n5: {name: Noise 5, address: 5}
  a: {name: A, address: 6, type: s16, scale_by: sf}
  b: {name: B, address: 7, scale_by: sf}
  sf: {name: Scale, address: 8, type: s16}
  c: {name: C, address: 9, type: u32, scale_by: sf}
  n6: {name: Noise 6, address: 11}
  n7: {name: Noise 7, address: 12}
  limit: {name: Limit, address: 15, access: rw, scale_by: limit_sf, poll: fast}
  limit_sf: {name: Limit scale, address: 16, type: s16}
"""

H = Table.HOLDING
NOT_IMPLEMENTED = -32768  # 0x8000
# (raw, exponent) moments: the values of each pair are apart from every mixed pair's
MOMENTS = [(1234, -2), (12340, -3), (123, -1), (1235, -2), (12350, -3), (777, NOT_IMPLEMENTED)]


def expected(raw: int, exponent: int) -> Decimal | None:
    return None if exponent == NOT_IMPLEMENTED else Decimal(raw).scaleb(exponent).normalize()


VALID = {
    "a": {expected(raw, sf) for raw, sf in MOMENTS},
    "b": {expected(raw, sf) for raw, sf in MOMENTS},
    "c": {expected(raw * 100, sf) for raw, sf in MOMENTS},
}


def shown(value: object) -> Decimal | None:
    assert value is None or isinstance(value, int | float), value
    return None if value is None else Decimal(repr(value)).normalize()


def put(sim: Simulator, raw: int, exponent: int) -> None:
    """One moment: the exponent and the raw words of a, b and c, with no await between
    (the raw words are stored at exponent 0, then the moment's exponent)."""
    sim.set_value(1, "sf", 0)
    for key, factor in (("a", 1), ("b", 1), ("c", 100)):
        sim.set_value(1, key, raw * factor)
    sim.set_value(1, "sf", exponent)
    sim.set_value(1, "n0", raw & 0xFFFF)


class Snapshots:
    """Each update's changed values, copied when it is reported."""

    def __init__(self) -> None:
        self.seen: list[tuple[str, object]] = []

    def __call__(self, update: DeviceUpdate) -> None:
        self.seen.extend((key, update.values.get(key)) for key in update.changed)

    def shown(self) -> dict[str, set[Decimal | None]]:
        """The distinct values published of each scaled key."""
        return {key: {shown(v) for k, v in self.seen if k == key} for key in VALID}


async def churn(sim: Simulator, changes: list[float], every: float) -> None:
    """Change the moment every ``every`` seconds, for ever; note when."""
    index = 0
    while True:
        put(sim, *MOMENTS[index % len(MOMENTS)])
        changes.append(time.monotonic())
        index += 1
        await asyncio.sleep(every)


@contextlib.asynccontextmanager
async def scaled_device(
    tmp_path: Path, transport: str, latency: float
) -> AsyncIterator[tuple[Simulator, Engine, Snapshots]]:
    path = tmp_path / "scaled.yaml"
    path.write_text(MAPPING)
    unit = SimulatedUnit(1, load_mapping(path), quirks=Quirks(latency=latency))
    sim = Simulator([unit], tick=0, read_log=100_000)
    put(sim, *MOMENTS[0])
    sim.set_value(1, "limit_sf", -1)
    snapshots = Snapshots()
    device = {
        "id": "inverter",
        "bus": "line",
        "unit": 1,
        "mapping": str(path),
        "poll": {"fast": 0.05, "slow": 1},
    }
    serving: Any = serving_tcp(sim) if transport == "tcp" else serving_serial(sim, baudrate=115200)
    async with serving as where:
        bus: dict[str, Any]
        if transport == "tcp":
            bus = tcp_bus(where) | {"id": "line"}
        else:
            bus = {"id": "line", "transport": "rtu", "port": where, "baudrate": 115200}
        engine = Engine(config([bus | {"timeout": 0.5}], [device]), snapshots, policy=FAST_POLICY)
        async with running(engine):
            yield sim, engine, snapshots


def changes_between_reads(sim: Simulator, changes: list[float], gap: float) -> int:
    """Changes that landed between two reads of one poll (reads less than ``gap`` apart)."""
    times = sorted(at for _, at in sim.reads(1))
    pairs = [(t1, t2) for t1, t2 in itertools.pairwise(times) if t2 - t1 < gap]
    return sum(1 for t in changes if any(t1 < t < t2 for t1, t2 in pairs))


@pytest.mark.asyncio
@pytest.mark.parametrize("transport", ["tcp", "rtu"])
async def test_every_value_is_scaled_by_the_exponent_of_the_same_moment(
    tmp_path: Path, transport: str
) -> None:
    latency = 0.01
    async with scaled_device(tmp_path, transport, latency) as (sim, engine, snapshots):
        poller = engine.devices["inverter"]
        await eventually(lambda: poller.values.get("a") is not None, 10)
        changes: list[float] = []
        task = asyncio.create_task(churn(sim, changes, every=0.007))
        try:
            await eventually(lambda: changes_between_reads(sim, changes, 0.05) >= 20, 30)
            await eventually(lambda: sum(1 for k, _ in snapshots.seen if k == "a") >= 60, 30)
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        reads = [read for read, _ in sim.reads(1)]
    assert {(r.address, r.count) for r in reads if 6 in r.span} <= {
        (r.address, r.count) for r in reads if 8 in r.span and 10 in r.span
    }  # a, sf and c's two words: always in one read
    published = {key: [shown(v) for k, v in snapshots.seen if k == key] for key in VALID}
    for key, values in published.items():
        assert values, key
        mixed = [v for v in values if v not in VALID[key]]
        assert not mixed, f"{key}: {mixed[:5]} are no moment's raw x 10**exponent"
    for key, values in published.items():  # every moment's value, None included
        assert VALID[key] <= set(values), key


@pytest.mark.asyncio
async def test_a_write_is_encoded_with_the_exponent_the_device_holds(tmp_path: Path) -> None:
    async with scaled_device(tmp_path, "tcp", 0.0) as (sim, engine, _):
        poller = engine.devices["inverter"]
        await eventually(lambda: "limit" in poller.values, 10)
        assert await engine.write("inverter", "limit", 12.3) == 12.3
        assert sim.image(1)[(H, 15)] == 123  # 12.3 at 10**-1
        sim.set_value(1, "limit_sf", -2)
        assert await engine.write("inverter", "limit", 12.3) == 12.3
        assert sim.image(1)[(H, 15)] == 1230  # the exponent read before the write
        sim.set_value(1, "limit_sf", NOT_IMPLEMENTED)
        writes = len(sim.writes)
        with pytest.raises(BridgeError, match="its scale factor limit_sf is unknown"):
            await engine.write("inverter", "limit", 5)
        assert len(sim.writes) == writes  # nothing on the wire
        assert sim.image(1)[(H, 15)] == 1230
        await eventually(lambda: poller.values.get("limit") is None, 10)
