"""``verify_delay``: a write is read back that long after it, and the bus serves the other
devices meanwhile (the wait is not a slot of the scheduler). Counted in the simulator's
own list of the requests it received, in order."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.mapping import load_mapping
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import Request, SimulatedUnit, Simulator
from tests.integration.harness import config, eventually, running, serving_tcp, tcp_bus

pytestmark = pytest.mark.asyncio
SLOW = """
manufacturer: Test
model: Slow relay
description: a relay module that takes its time to switch
source: {title: test}
entities:
  relay: {name: Relay, address: 3, type: bool, access: rw, verify_delay: DELAY}
"""
METER = """
manufacturer: Test
model: Meter
description: a meter polled often on the same bus
source: {title: test}
entities:
  power: {name: Power, address: 10}
"""
READ, WRITE = 3, 6


def between_write_and_read_back(requests: list[Request]) -> list[Request]:
    """The requests after the relay's write (unit 1, FC06) up to its next read (FC03)."""
    start = requests.index((1, WRITE, 3))
    end = requests.index((1, READ, 3), start)
    return requests[start + 1 : end]


async def write_and_list(tmp_path: Path, delay: str) -> list[Request]:
    """Write the relay while the meter (unit 2) polls every 20 ms; the requests the
    simulator received from the write to the relay's read back."""
    relay, meter = tmp_path / "relay.yaml", tmp_path / "meter.yaml"
    relay.write_text(SLOW.replace("DELAY", delay), encoding="utf-8")
    meter.write_text(METER, encoding="utf-8")
    sim = Simulator([SimulatedUnit(1, load_mapping(relay)), SimulatedUnit(2, load_mapping(meter))])
    devices = [
        {"id": "relay", "bus": "tcp", "unit": 1, "mapping": str(relay), "poll": {"slow": 600}},
        {"id": "meter", "bus": "tcp", "unit": 2, "mapping": str(meter), "poll": {"fast": 0.02}},
    ]
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], devices))
        async with running(engine):
            await eventually(lambda: "relay" in engine.devices["relay"].values)
            await eventually(lambda: "power" in engine.devices["meter"].values)
            assert await engine.write("relay", "relay", "ON") is True
    assert sim.value(1, "relay") is True
    return between_write_and_read_back(list(sim.requests))


async def test_the_read_back_waits_and_the_bus_serves_the_others_meanwhile(
    tmp_path: Path,
) -> None:
    waited = await write_and_list(tmp_path, "0.5s")
    assert {unit for unit, _, _ in waited} == {2}  # the relay itself is not asked meanwhile
    assert len(waited) >= 5  # the meter kept being polled, ~25 times at 20 ms


async def test_without_a_delay_the_read_back_follows_the_write(tmp_path: Path) -> None:
    immediate = await write_and_list(tmp_path, "null")
    assert len(immediate) <= 1  # at most the meter's read already in flight
