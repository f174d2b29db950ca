"""The gateway (bridge/gateway.py) attacked by another master: what it may read and write.

- A password (a ``secret`` or write-only entity) is never read through the gateway unless
  ``bridge.allow_raw_writes`` permits raw reads of it: alone, inside a range, from the
  bus or from the bridge's image, by the unit of its device or, on a TCP bus, by a unit
  its device may answer as. The answer is 0x02 and nothing goes to the bus.
- A raw write (``gateway_raw_writes``) keeps the guard a device had before a mapping
  reload (the rule of raw writes, bridge/core/reach.py).

Real simulators (an RTU line on a pty, Modbus TCP on loopback), the real engine, writer,
dispatcher and gateway; pymodbus' client as the hostile master.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from bridge.config import load_config_data
from bridge.core.entity import Table
from bridge.core.mapping import load_mapping
from bridge.dispatcher import Dispatcher
from bridge.gateway import Gateway
from bridge.modbus.engine import Engine
from tests.integration.harness import (
    FAST_POLICY,
    cancel,
    eventually,
    running,
    serving_tcp,
    simulator,
)
from tests.integration.test_gateway_server import PUMP, STARTER, master, site, words

H = Table.HOLDING


@contextlib.asynccontextmanager
async def gateway_for(data: dict[str, Any], folder: Path) -> AsyncIterator[tuple[Gateway, Engine]]:
    """The engine, dispatcher and gateway of a config, running."""
    loaded = load_config_data(data, folder / "config.yaml")
    engine = Engine(loaded, policy=FAST_POLICY)
    dispatcher = Dispatcher(
        engine, 5.0, spawn=lambda work, fail: None, error=lambda *a: None, read=lambda d: None
    )
    gateway = Gateway(loaded, engine, dispatcher)
    async with running(engine):
        task = asyncio.create_task(gateway.run())
        try:
            await asyncio.wait_for(gateway.server.ready.wait(), 5)
            yield gateway, engine
        finally:
            await cancel(task)


# --- secrets --------------------------------------------------------------------------------


@pytest.mark.asyncio
@pytest.mark.parametrize("max_age", [0.0, 30.0], ids=["from-the-bus", "from-the-image"])
@pytest.mark.parametrize("raw_reads", [False, True], ids=["default", "allow_raw_writes"])
async def test_a_master_reads_no_password_unless_raw_reads_are_allowed(
    max_age: float, raw_reads: bool
) -> None:
    """The Nastec's password digits (secret) through the gateway: alone, inside a range,
    every one of them; after the bridge polled them into its image."""
    async with (
        site(bridge={"allow_raw_writes": raw_reads}, max_age=max_age) as (gateway, sim, engine),
        master(gateway) as client,
    ):
        pump = engine.devices["pump"]
        secret = sorted(a for p in pump.points.values() if p.entity.secret for a in p.span)
        assert len(secret) == 6, "the Nastec mapping marks its password digits secret"
        await eventually(lambda: all((H, a) in pump.state.image for a in secret), 10)
        first, last = secret[0], secret[-1]
        asked = [(first, 1), (first, 3), (last - 2, 3)]  # the pump reads one register a time
        if not raw_reads:  # and ranges around and across them (not every address is served)
            asked += [(first - 2, 4), (last - 2, 5), (first, last - first + 1)]
        replies = [
            await client.read_holding_registers(a, count=n, device_id=PUMP) for a, n in asked
        ]
        counters = gateway.book.totals()
        if not raw_reads:
            assert [r.exception_code for r in replies] == [0x02] * 6
            assert (counters.refused, counters.served, counters.cached) == (6, 0, 0)
            assert gateway.transactions["line"] == 0  # not a frame for them
            plain = next(
                p for p in pump.points.values() if p.entity.readable and not p.entity.secret
            )
            beside = await client.read_holding_registers(plain.address, count=1, device_id=PUMP)
            assert beside.registers == words(sim, PUMP, plain.address, 1)
            return
        for (address, count), reply in zip(asked, replies, strict=True):
            assert not reply.isError(), reply
            assert reply.registers == words(sim, PUMP, address, count)
        assert counters.refused == 0
        assert counters.cached == (3 if max_age else 0)


@pytest.mark.asyncio
@pytest.mark.parametrize("unit", [1, 7, 8], ids=["pump", "unit-255", "unconfigured-unit"])
async def test_on_a_tcp_bus_no_unit_reads_the_password_of_a_device_that_may_answer_it(
    unit: int, tmp_path: Path
) -> None:
    """A Nastec behind a TCP gateway that answers every unit id; the bridge's gateway serves
    it as unit 1 (the device), 7 (unit 255 of the bus) and 8 (unit 2, where no device is
    configured). Its password digits answer 0x02 by each, and no frame asks for them; a
    plain register is read; a write where no device is configured is refused."""
    sim = simulator((0, "nastec_vasco"), tick=0)  # unit 0: answers any unit id
    async with serving_tcp(sim) as port:
        data = {
            "bridge": {
                "gateway": {
                    "enabled": True,
                    "port": 0,
                    "allow_writes": True,
                    "units": {
                        1: "pump",
                        7: {"bus": "tcp1", "unit": 255},
                        8: {"bus": "tcp1", "unit": 2},
                    },
                }
            },
            "buses": [
                {"id": "tcp1", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}
                | {"timeout": 0.3}
            ],
            "devices": [{"id": "pump", "bus": "tcp1", "unit": 1, "mapping": "nastec_vasco"}],
        }
        async with gateway_for(data, tmp_path) as (gateway, engine), master(gateway) as client:
            pump = engine.devices["pump"]
            secret = sorted(a for p in pump.points.values() if p.entity.secret for a in p.span)
            for start, count in ((secret[0], 1), (secret[0] - 1, 3), (secret[-1], 2)):
                reply = await client.read_holding_registers(start, count=count, device_id=unit)
                assert reply.isError() and reply.exception_code == 0x02, (start, reply)
            assert gateway.book.totals().refused == 3
            assert gateway.transactions["tcp1"] == 0
            language = pump.points["language"].address
            plain = await client.read_holding_registers(language, count=1, device_id=unit)
            assert plain.registers == [sim.image(0)[(H, language)]]
            written = len(sim.writes)
            if unit != 1:  # no device there: writes go to configured devices only
                reply = await client.write_register(language, 1, device_id=unit)
                assert reply.isError() and reply.exception_code == 0x01
            assert len(sim.writes) == written


# --- raw writes ----------------------------------------------------------------------------


HARMLESS_ONLY = """
manufacturer: Test
model: Starter subset
description: the soft starter's soft start time alone; its guarded registers unmapped
source: {title: test}
entities:
  soft_start_time: {name: Soft start time, address: 4101, access: rw, min: 1, max: 200, step: 1}
"""


@pytest.mark.asyncio
async def test_a_raw_write_keeps_the_guard_of_a_mapping_reloaded_away(tmp_path: Path) -> None:
    """The soft starter switched to a mapping without its guarded current_range (4098):
    the register is unmapped now, so a raw write could reach it; the guard the device had
    still refuses it (0x01), and nothing reaches the wire."""
    path = tmp_path / "subset.yaml"
    path.write_text(HARMLESS_ONLY)
    async with (
        site(starter={"gateway_raw_writes": True}, allow_writes=True) as (gateway, sim, engine),
        master(gateway) as client,
    ):
        await eventually(lambda: engine.devices["starter"].health.online)
        await engine.replace_mapping("starter", load_mapping(path))
        assert (Table.HOLDING, 4098) in engine.devices["starter"].guard.dangerous
        written = len(sim.writes)
        guarded = await client.write_register(4098, 100, device_id=STARTER)
        assert guarded.isError() and guarded.exception_code == 0x01
        assert len(sim.writes) == written
        await client.write_register(4131, 1, device_id=STARTER)  # the device may refuse it
        assert sim.writes[-1][1].address == 4131  # it went out raw
