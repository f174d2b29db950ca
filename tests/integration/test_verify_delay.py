"""``verify_delay``: a write is read back that long after it, and the bus serves the other
devices meanwhile (the wait is not a slot of the scheduler). Counted in the simulator's
own list of the requests it received, in order."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import pytest

from bridge.core.mapping import load_mapping
from bridge.core.topics import Action, CommandTopic
from bridge.dispatcher import Dispatcher
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import Request, SimulatedUnit, Simulator
from bridge.mqtt.session import Message
from tests.integration.harness import config, eventually, running, serving_tcp, tcp_bus

pytestmark = pytest.mark.asyncio
SLOW = """
manufacturer: Test
model: Slow relay
description: a relay module that takes its time to switch
source: {title: test}
entities:
  relay: {name: Relay, address: 3, type: bool, access: rw, verify_delay: DELAY}
  level: {name: Level, address: 4, access: rw}
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


def command(key: str, payload: bytes) -> tuple[CommandTopic, Message]:
    topic = f"modbus/relay/{key}/set"
    message = Message(
        topic, payload, qos=1, retain=False, duplicate=False, mid=None, received=time.monotonic()
    )
    return CommandTopic("relay", key, Action.SET), message


async def test_the_device_s_next_command_does_not_wait_for_the_read_back(tmp_path: Path) -> None:
    """Through the dispatcher (the path of an MQTT command): the relay's read back comes
    0.5 s after its write, and the level written meanwhile (a command after it, for the
    same device) is not held up by it; the relay's state is read back in the end."""
    path = tmp_path / "relay.yaml"
    path.write_text(SLOW.replace("DELAY", "0.5s"), encoding="utf-8")
    sim = Simulator([SimulatedUnit(1, load_mapping(path))])
    errors: list[str] = []
    tasks: list[asyncio.Task[None]] = []

    def spawn(work: Coroutine[Any, Any, None], _: Callable[[str], None]) -> None:
        tasks.append(asyncio.create_task(work))

    async with serving_tcp(sim) as port:
        device = {"id": "relay", "bus": "tcp", "unit": 1, "mapping": str(path)}
        engine = Engine(config([tcp_bus(port)], [device]))
        async with running(engine, pollers=False):
            await engine.devices["relay"].read_now()
            dispatcher = Dispatcher(
                engine,
                5.0,
                spawn=spawn,
                error=lambda _d, _k, _v, reason: errors.append(reason),
                read=lambda _d: None,
            )
            dispatcher.handle(*command("relay", b"ON"))
            await asyncio.sleep(0.1)  # the relay is written, its read back waits
            dispatcher.handle(*command("level", b"7"))
            await asyncio.gather(*tasks)
            assert engine.devices["relay"].values["relay"] is True
    assert errors == []
    requests = list(sim.requests)
    relay_written = requests.index((1, WRITE, 3))
    relay_read = requests.index((1, READ, 3), relay_written)
    assert relay_written < requests.index((1, WRITE, 4)) < relay_read
