"""The gateway (bridge/gateway.py) attacked by another master: what it may read and write.

- A password written through the gateway is not logged (masked, or the refusal's reason
  left out).
- A password (a ``secret`` or write-only entity) is never read through the gateway unless
  ``bridge.allow_raw_writes`` permits raw reads of it: alone, inside a range, from the
  bus or from the bridge's image, by the unit of its device or, on a TCP bus, by a unit
  its device may answer as. The answer is 0x02 and nothing goes to the bus.
- Every refusal the writer can make is answered with one exception code, pinned here per
  refusal (0x01: may not be written; 0x03: the value), and nothing reaches the wire.
- Words that mean no value (a NaN, a sentinel, an enum code without a label, 7 to an
  on/off register, digits beyond the entity's precision) are refused whole (0x03), and so
  are bits of a word no entity has (the writer would keep the device's); FC15 writes its
  count of coils, never its padding bits.
- A raw write (``gateway_raw_writes``) never carries an entity's words past its checks,
  and keeps the guard a device had before a mapping reload (the rule of raw writes,
  bridge/core/reach.py).

Real simulators (an RTU line on a pty, Modbus TCP on loopback), the real engine, writer,
dispatcher and gateway; pymodbus' client as the hostile master.
"""

from __future__ import annotations

import contextlib
import logging
import struct
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from pymodbus.client import AsyncModbusTcpClient

from bridge.core.entity import Table
from bridge.core.mapping import load_mapping
from bridge.gateway import Gateway
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import SimulatedUnit, Simulator
from tests.integration.harness import (
    eventually,
    serving_tcp,
    simulator,
)
from tests.integration.test_gateway_server import (
    PUMP,
    STARTER,
    exchange,
    frame,
    gateway_for,
    master,
    site,
    words,
)

H = Table.HOLDING


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
        await eventually(lambda: all((H, a) in pump.state.image for a in secret), 30)
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
            assert not reply.isError(), (address, count, getattr(reply, "exception_code", None))
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


@pytest.mark.asyncio
async def test_a_password_written_through_the_gateway_is_never_logged(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The Nastec's password 1 written by a master (allow_dangerous_writes on): a digit out
    of range is refused without its reason in the log (it quotes the value tried), and the
    digits written are logged masked."""
    caplog.set_level(logging.INFO, "bridge")
    async with (
        site(pump={"allow_dangerous_writes": True}, allow_writes=True) as (gateway, sim, engine),
        master(gateway) as client,
    ):
        pump = engine.devices["pump"]
        await eventually(lambda: pump.health.online and pump.first_poll_done, 10)
        first = pump.points["password_1_left"].write_address
        tried = await client.write_registers(first, [8, 6, 4321], device_id=PUMP)
        assert tried.isError() and tried.exception_code == 0x03
        written = await client.write_registers(first, [8, 6, 7], device_id=PUMP)
        assert not written.isError(), written
        assert words(sim, PUMP, first, 3) == [8, 6, 7]
    lines = [r.getMessage() for r in caplog.records if r.name == "bridge.gateway"]
    assert any("'password_1_left': '***'" in line for line in lines), lines
    assert not [line for line in lines if "4321" in line or "'password_1_left': 8" in line]


# --- every refusal of a write, its code ------------------------------------------------------

REFUSALS = """
manufacturer: Test
model: Refusals
description: one entity per refusal a write through the gateway can meet
source: {title: test}
entities:
  level: {name: Level, address: 10, access: rw, min: 0, max: 100, step: 1}
  mode: {name: Mode, address: 11, access: rw, enum: {0: manual, 1: auto}}
  start: {name: Start, address: 12, access: rw, min: 0, max: 1, step: 1, requires: {mode: auto}}
  reset: {name: Reset, address: 13, access: rw, min: 0, max: 1, step: 1, dangerous: true}
  speed:
    {name: Speed, address: 14, type: s16, access: rw, min: -100, max: 100, step: 1,
     dangerous_below: 0}
  param: {name: Param, address: 15, access: rw, min: 0, max: 100, step: 1, eeprom: true}
  setpoint:
    {name: Setpoint, address: 16, access: rw, min: 0, max: 100, step: 1, write_interval: 2s}
  temp:
    {name: Temp, address: 17, access: rw, min: 0, max: 40000, step: 1,
     sentinels: {32767: unknown}}
  ratio: {name: Ratio, address: 18, access: rw, min: 0, max: 65.535, scale: 0.001, precision: 1}
  flow: {name: Flow, address: 20, type: f32, access: rw, min: -1000, max: 1000}
  enabled: {name: Enabled, address: 22, type: bool, access: rw}
  fan: {name: Fan, address: 24, bit: 0, access: rw}
  heater: {name: Heater, address: 24, bit: 1, access: rw}
  relay_a: {name: Relay A, address: 0, table: coil, access: rw}
  relay_b: {name: Relay B, address: 1, table: coil, access: rw}
  relay_c: {name: Relay C, address: 2, table: coil, access: rw}
"""
NAN = (0x7FC0, 0x0000)  # a float32 NaN


@contextlib.asynccontextmanager
async def refusals_site(folder: Path) -> AsyncIterator[tuple[Gateway, Simulator, Engine]]:
    path = folder / "refusals.yaml"
    path.write_text(REFUSALS)
    sim = Simulator([SimulatedUnit(1, load_mapping(path))])
    async with serving_tcp(sim) as port:
        data = {
            "bridge": {
                "gateway": {"enabled": True, "port": 0, "allow_writes": True, "units": {1: "dev"}}
            },
            "buses": [
                {"id": "tcp", "transport": "tcp", "host": "127.0.0.1", "tcp_port": port}
                | {"timeout": 0.5, "retries": 0}
            ],
            "devices": [{"id": "dev", "bus": "tcp", "unit": 1, "mapping": str(path)}],
        }
        async with gateway_for(data, folder) as (gateway, engine):
            device = engine.devices["dev"]
            await eventually(lambda: device.first_poll_done and device.health.online)
            yield gateway, sim, engine


async def write(client: AsyncModbusTcpClient, address: int, values: tuple[int, ...]) -> int:
    """The exception code of a write (0: written)."""
    if len(values) == 1:
        reply = await client.write_register(address, values[0], device_id=1)
    else:
        reply = await client.write_registers(address, list(values), device_id=1)
    return int(reply.exception_code) if reply.isError() else 0


@pytest.mark.asyncio
@pytest.mark.parametrize(
    ("before", "address", "values", "code"),
    [
        ((), 10, (50,), 0),  # written: the site works
        ((), 10, (101,), 0x03),  # the writer: outside min..max
        ((), 12, (1,), 0x01),  # the writer: requires mode auto, which reads manual
        ((), 11, (1, 1), 0x01),  # the writer: a key with conditions in a command of several
        ((), 13, (1,), 0x01),  # the writer: guarded (dangerous)
        ((), 14, (0xFFFF,), 0x01),  # the writer: -1, below dangerous_below
        (((15, (5,)),), 15, (6,), 0x01),  # the writer: EEPROM spacing
        (((16, (7,)),), 16, (8,), 0x01),  # the writer: write_interval
        ((), 11, (5,), 0x03),  # the gateway: an enum code without a label
        ((), 17, (32767,), 0x03),  # the gateway: the sentinel ("unknown")
        ((), 20, NAN, 0x03),  # the gateway: a NaN float
        ((), 18, (12345,), 0x03),  # the gateway: 12.345 shown as 12.3, written as 12300
        ((), 22, (7,), 0x03),  # the gateway: 7 to an on/off register the bridge writes 1
        ((), 10, (50, 3), 0x03),  # the gateway: mode 3 has no label, level 50 goes neither
        ((), 24, (0x0003,), 0),  # fan and heater, bits 0 and 1 of one word: written
        ((), 24, (0xFF01,), 0x03),  # the gateway: bits 8-15 are no entity's, the device's 0
    ],
    ids=[
        "written",
        "range",
        "requires",
        "conditions-alone",
        "guarded",
        "dangerous-below",
        "eeprom-spacing",
        "write-interval",
        "enum-code",
        "sentinel",
        "nan",
        "precision",
        "bool-word",
        "one-bad-word-refuses-all",
        "bit-fields",
        "bits-no-entity-has",
    ],
)
async def test_each_refusal_answers_its_code_and_writes_nothing(
    before: tuple[tuple[int, tuple[int, ...]], ...],
    address: int,
    values: tuple[int, ...],
    code: int,
    tmp_path: Path,
) -> None:
    async with refusals_site(tmp_path) as (gateway, sim, _), master(gateway) as client:
        for earlier, words_ in before:
            assert await write(client, earlier, words_) == 0
        written = list(sim.writes)
        assert await write(client, address, values) == code
        if code:
            assert sim.writes == written  # not a frame of it on the wire
            assert gateway.book.totals().refused == 1
        else:
            assert [w.values for _, w in sim.writes[len(written) :]] == [values]


@pytest.mark.asyncio
async def test_fc15_writes_its_count_of_coils_never_the_padding_bits(tmp_path: Path) -> None:
    """FC15 of 3 coils whose data byte has every padding bit set (0xFD: 1, 0, 1, then five
    1s): relays A and C on, B off, and no coil beyond the third written."""
    async with refusals_site(tmp_path) as (gateway, sim, _):
        written = len(sim.writes)
        pdu = struct.pack(">BHHB", 15, 0, 3, 1) + bytes([0xFD])
        (reply,) = await exchange(gateway.server.port, frame(1, 1, pdu))
        assert reply[7:] == struct.pack(">BHH", 15, 0, 3)
        coils = {w.address: w.values for _, w in sim.writes[written:]}
        assert sorted(coils) == [0, 1, 2]
        assert [bool(coils[a][0]) for a in (0, 1, 2)] == [True, False, True]


# --- raw writes ----------------------------------------------------------------------------


@pytest.mark.asyncio
async def test_a_raw_write_never_carries_an_entitys_words_past_its_checks() -> None:
    """``gateway_raw_writes``: FC16 over energy_saving_slow_voltage (0..1200) and the
    unmapped 4131 would go raw as one frame, past the entity's checks (5000 V and all); it
    is refused whole. The unmapped register alone still goes raw."""
    async with (
        site(starter={"gateway_raw_writes": True}, allow_writes=True) as (gateway, sim, engine),
        master(gateway) as client,
    ):
        await eventually(lambda: engine.devices["starter"].health.online)
        written = len(sim.writes)
        beyond = await client.write_registers(4130, [5000, 1], device_id=STARTER)
        assert beyond.isError() and beyond.exception_code == 0x03  # 5000 V: no value it takes
        mixed = await client.write_registers(4130, [600, 1], device_id=STARTER)
        assert mixed.isError() and mixed.exception_code == 0x01  # 600 V, but raw
        assert len(sim.writes) == written
        alone = await client.write_register(4131, 1, device_id=STARTER)
        assert sim.writes[-1][1].address == 4131, alone  # on the wire (the device may refuse)


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
