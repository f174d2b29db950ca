"""The gateway (bridge/gateway.py): other masters read and write through the bridge's
Modbus TCP server while the bridge polls its own devices on the same serial line (a pty
pair, the simulator at the far end). Answers are compared with the simulator's registers;
refusals with what reached the simulator (nothing). Hostile clients (half frames, wrong
lengths, floods, unsupported functions) are dropped while another client is served.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from pymodbus.client import AsyncModbusTcpClient

from bridge.config import load_config_data
from bridge.core.entity import Table
from bridge.core.gateway import ClientBook, ProxyRequest
from bridge.core.request import Write
from bridge.dispatcher import Dispatcher
from bridge.gateway import Gateway
from bridge.modbus.engine import Engine
from bridge.modbus.gateway_server import GatewayServer, Limits
from bridge.modbus.simulator import Quirks, Simulator
from tests.integration.harness import (
    FAST_POLICY,
    cancel,
    eventually,
    running,
    serving_serial,
    simulator,
)

H = Table.HOLDING
PUMP, STARTER = 1, 3  # units on the line: Nastec (one register per read), soft starter


@contextlib.asynccontextmanager
async def site(
    starter: dict[str, Any] | None = None,
    bridge: dict[str, Any] | None = None,
    pump: dict[str, Any] | None = None,
    **gateway: Any,
) -> AsyncIterator[tuple[Gateway, Simulator, Engine]]:
    """Two devices polled on one RTU line; the gateway on a free loopback port;
    ``starter``, ``pump``: more settings of their device configs; ``bridge``: more of the
    bridge section."""
    sim = simulator((PUMP, "nastec_vasco"), (STARTER, "soft_starter"))
    async with serving_serial(sim, baudrate=38400) as path:
        settings = {"enabled": True, "port": 0, "units": {1: "pump", 3: "starter"}} | gateway
        data = {
            "bridge": {"gateway": settings} | (bridge or {}),
            "buses": [
                {"id": "line", "transport": "rtu", "port": path}
                | {"baudrate": 38400, "timeout": 0.3}
            ],
            "devices": [
                {"id": "pump", "bus": "line", "unit": PUMP, "mapping": "nastec_vasco"}
                | (pump or {}),
                {"id": "starter", "bus": "line", "unit": STARTER, "mapping": "soft_starter"}
                | (starter or {}),
            ],
        }
        async with gateway_for(data, Path()) as (gateway, engine):
            yield gateway, sim, engine


@contextlib.asynccontextmanager
async def gateway_for(data: dict[str, Any], folder: Path) -> AsyncIterator[tuple[Gateway, Engine]]:
    """The engine, dispatcher and gateway of a config, running."""
    loaded = load_config_data(data, folder / "gateway-test.yaml")
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


@contextlib.asynccontextmanager
async def master(gateway: Gateway) -> AsyncIterator[AsyncModbusTcpClient]:
    client = AsyncModbusTcpClient("127.0.0.1", port=gateway.server.port, timeout=3, retries=0)
    await client.connect()
    try:
        yield client
    finally:
        client.close()


def words(sim: Simulator, unit: int, address: int, count: int) -> list[int]:
    image = sim.image(unit)
    return [image.get((H, a), 0) for a in range(address, address + count)]


def frame(tid: int, unit: int, pdu: bytes) -> bytes:
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


async def exchange(port: int, data: bytes, *, answers: int = 1) -> list[bytes]:
    """Send raw bytes; the Modbus TCP replies that come back (at most ``answers``)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(data)
        await writer.drain()
        replies = []
        for _ in range(answers):
            header = await asyncio.wait_for(reader.readexactly(6), 5)
            (length,) = struct.unpack(">H", header[4:6])
            replies.append(header + await asyncio.wait_for(reader.readexactly(length), 5))
        return replies
    finally:
        writer.close()


@pytest.mark.asyncio
async def test_reads_answer_the_devices_registers_split_into_their_read_limits() -> None:
    async with site() as (gateway, sim, engine), master(gateway) as client:
        pump = await client.read_holding_registers(50, count=12, device_id=PUMP)
        starter = await client.read_holding_registers(4097, count=20, device_id=STARTER)
        assert not pump.isError() and not starter.isError()
        assert pump.registers == words(sim, PUMP, 50, 12)  # the Nastec takes 1 per read
        assert starter.registers == words(sim, STARTER, 4097, 20)  # the starter 6 per read
        assert gateway.transactions["line"] == 12 + 4
        counters = gateway.book.totals()
        assert (counters.served, counters.refused, counters.failed) == (2, 0, 0)
        assert engine.schedulers["line"].counters.frame_errors == 0


@pytest.mark.asyncio
async def test_a_device_exception_is_passed_on_as_the_device_sent_it() -> None:
    async with site() as (gateway, sim, _), master(gateway) as client:
        sim.set_quirks(STARTER, Quirks(refused=frozenset({4097})))
        reply = await client.read_holding_registers(4097, count=1, device_id=STARTER)
        assert reply.isError() and reply.exception_code == 2


@pytest.mark.asyncio
async def test_an_unknown_unit_answers_0x0a_and_a_silent_one_0x0b() -> None:
    async with (
        site(units={1: "pump", 3: "starter", 9: {"bus": "line", "unit": 9}}) as (
            gateway,
            _,
            _,
        ),
        master(gateway) as client,
    ):
        unknown = await client.read_holding_registers(0, count=1, device_id=42)
        assert unknown.isError() and unknown.exception_code == 0x0A
        silent = await client.read_holding_registers(0, count=1, device_id=9)  # nobody there
        assert silent.isError() and silent.exception_code == 0x0B


@pytest.mark.asyncio
async def test_a_dead_configured_device_answers_0x0b_and_polling_goes_on() -> None:
    async with site() as (gateway, sim, _), master(gateway) as client:
        sim.set_quirks(PUMP, Quirks(dead=True))
        reply = await client.read_holding_registers(50, count=1, device_id=PUMP)
        assert reply.isError() and reply.exception_code == 0x0B
        starter = await client.read_holding_registers(4097, count=3, device_id=STARTER)
        assert starter.registers == words(sim, STARTER, 4097, 3)


@pytest.mark.asyncio
async def test_functions_beyond_reads_and_writes_answer_0x01_and_bad_counts_0x03() -> None:
    async with site() as (gateway, _, _):
        port = gateway.server.port
        diagnostics = frame(1, PUMP, bytes([0x08, 0x00, 0x04, 0x00, 0x00]))  # listen only
        (reply,) = await exchange(port, diagnostics)
        assert reply[7:] == bytes([0x88, 0x01])
        too_many = frame(2, PUMP, struct.pack(">BHH", 3, 0, 126))
        (reply,) = await exchange(port, too_many)
        assert reply[7:] == bytes([0x83, 0x03])
        past_end = frame(3, PUMP, struct.pack(">BHH", 3, 0xFFFF, 2))
        (reply,) = await exchange(port, past_end)
        assert reply[7:] == bytes([0x83, 0x02])


@pytest.mark.asyncio
async def test_a_client_with_too_many_requests_waiting_gets_0x06() -> None:
    async with site(max_queued_per_client=1) as (gateway, sim, _):
        sim.set_quirks(PUMP, Quirks(latency=0.1))
        reads = b"".join(frame(t, PUMP, struct.pack(">BHH", 3, 50, 3)) for t in (1, 2, 3))
        replies = await exchange(gateway.server.port, reads, answers=3)
        by_tid = {struct.unpack(">H", r[:2])[0]: r[7:] for r in replies}
        assert by_tid[2] == by_tid[3] == bytes([0x83, 0x06])  # busy, at once
        assert by_tid[1][:2] == bytes([0x03, 6])  # the first: its 3 registers
        assert list(struct.unpack(">3H", by_tid[1][2:])) == words(sim, PUMP, 50, 3)


@pytest.mark.asyncio
@pytest.mark.parametrize(
    "garbage",
    [
        b"\x00\x01\x00\x07\x00\x06\x01\x03\x00\x00\x00\x01",  # protocol id 7
        b"\x00\x01\x00\x00\x00\x00\x01\x03",  # length 0
        b"\x00\x01\x00\x00\xff\xff\x01\x03\x00\x00\x00\x01",  # length 65535
        bytes(range(256)) * 40,  # a flood of noise
    ],
    ids=["protocol-id", "length-0", "length-huge", "flood"],
)
async def test_a_broken_client_is_dropped_and_others_are_served(garbage: bytes) -> None:
    async with site() as (gateway, sim, engine), master(gateway) as client:
        reader, writer = await asyncio.open_connection("127.0.0.1", gateway.server.port)
        writer.write(garbage)
        await writer.drain()
        assert await asyncio.wait_for(reader.read(), 5) == b""  # closed by the gateway
        writer.close()
        reply = await client.read_holding_registers(4097, count=2, device_id=STARTER)
        assert reply.registers == words(sim, STARTER, 4097, 2)
        assert gateway.book.totals().dropped == 1
        assert engine.schedulers["line"].counters.frame_errors == 0


@pytest.mark.asyncio
async def test_a_half_frame_held_open_is_closed_after_the_idle_timeout() -> None:
    async with site(idle_timeout=0.3) as (gateway, _, _):
        reader, writer = await asyncio.open_connection("127.0.0.1", gateway.server.port)
        writer.write(frame(1, PUMP, struct.pack(">BHH", 3, 50, 1))[:9])  # 9 of 12 bytes
        await writer.drain()
        assert await asyncio.wait_for(reader.read(), 5) == b""
        writer.close()
        assert gateway.book.totals().dropped == 1


@pytest.mark.asyncio
async def test_connections_beyond_max_clients_are_turned_away() -> None:
    async with site(max_clients=1) as (gateway, sim, _), master(gateway) as first:
        reader, writer = await asyncio.open_connection("127.0.0.1", gateway.server.port)
        assert await asyncio.wait_for(reader.read(), 5) == b""
        writer.close()
        reply = await first.read_holding_registers(4097, count=1, device_id=STARTER)
        assert reply.registers == words(sim, STARTER, 4097, 1)
        assert gateway.book.totals().rejected == 1


# --- writes -------------------------------------------------------------------------------


@pytest.mark.asyncio
async def test_writes_are_refused_unless_allowed_and_never_reach_the_bus() -> None:
    async with site() as (gateway, sim, _), master(gateway) as client:
        reply = await client.write_register(4101, 20, device_id=STARTER)  # soft_start_time
        assert reply.isError() and reply.exception_code == 0x01
        assert sim.writes == []


@pytest.mark.asyncio
async def test_a_write_goes_through_the_command_checks_and_is_read_back() -> None:
    async with site(allow_writes=True) as (gateway, sim, engine), master(gateway) as client:
        await eventually(lambda: engine.devices["starter"].health.online)
        reply = await client.write_register(4101, 20, device_id=STARTER)  # 20 s
        assert not reply.isError(), reply
        assert sim.value(STARTER, "soft_start_time") == 20
        assert engine.devices["starter"].state.values["soft_start_time"] == 20
        assert engine.devices["starter"].writes.done == 1
        written = len(sim.writes)
        out_of_range = await client.write_register(4101, 201, device_id=STARTER)  # max 200
        dangerous = await client.write_register(4103, 400, device_id=STARTER)  # rated_voltage
        unmapped = await client.write_register(4000, 1, device_id=STARTER)
        several = await client.write_registers(4100, [300, 30], device_id=STARTER)
        assert [r.exception_code for r in (out_of_range, dangerous, unmapped, several)] == [
            0x03,
            0x01,
            0x01,
            0x01,  # starting_current_limit beside it is dangerous: all or nothing
        ]
        assert len(sim.writes) == written  # nothing more reached the wire
        assert gateway.book.totals().refused == 4


# --- the cache ----------------------------------------------------------------------------


@pytest.mark.asyncio
@pytest.mark.parametrize(("max_age", "frames"), [(0.0, 1), (30.0, 0)])
async def test_a_read_of_what_the_bridge_polled_is_answered_from_its_image(
    max_age: float, frames: int
) -> None:
    async with site(max_age=max_age) as (gateway, sim, engine), master(gateway) as client:
        await eventually(lambda: engine.devices["starter"].first_poll_done)
        reply = await client.read_holding_registers(4097, count=6, device_id=STARTER)
        assert reply.registers == words(sim, STARTER, 4097, 6)
        assert gateway.transactions["line"] == frames
        assert gateway.book.totals().cached == 1 - frames


@pytest.mark.asyncio
async def test_a_write_is_in_the_image_and_a_cached_read_answers_it() -> None:
    async with (
        site(max_age=30.0, allow_writes=True) as (gateway, sim, engine),
        master(gateway) as client,
    ):
        starter = engine.devices["starter"]
        await eventually(lambda: starter.first_poll_done and starter.health.online)
        assert not (await client.write_register(4101, 25, device_id=STARTER)).isError()
        before = gateway.transactions["line"]
        reply = await client.read_holding_registers(4101, count=1, device_id=STARTER)
        assert reply.registers == [25] == words(sim, STARTER, 4101, 1)
        assert gateway.transactions["line"] == before  # the write left it in the image


@pytest.mark.asyncio
async def test_unmapped_words_go_raw_only_where_the_device_allows_it_and_never_guarded() -> None:
    async with (
        site(starter={"gateway_raw_writes": True}, allow_writes=True) as (
            gateway,
            sim,
            engine,
        ),
        master(gateway) as client,
    ):
        await eventually(lambda: engine.devices["starter"].health.online)
        raw = await client.write_register(4000, 7, device_id=STARTER)
        assert sim.writes[-1] == (STARTER, Write(6, H, 4000, (7,)))  # on the wire
        assert raw.isError() and raw.exception_code == 2  # the simulator has no 4000
        written = len(sim.writes)
        # 4096 is unmapped, 4097 soft_start_mode, 4098 current_range (guarded): raw, the
        # entities' words would skip their checks; the whole write is refused
        mixed = await client.write_registers(4096, [1, 2, 100], device_id=STARTER)
        assert mixed.isError() and mixed.exception_code == 0x01
        out_of_range = await client.write_registers(4096, [1, 2, 3], device_id=STARTER)
        assert out_of_range.isError() and out_of_range.exception_code == 0x03  # 3 A: min 10
        assert len(sim.writes) == written


@pytest.mark.asyncio
async def test_a_fault_inside_the_bridge_answers_0x04_and_the_server_serves_on() -> None:
    """The server's own boundary: whatever fails behind ``answer`` (a bug, not a refusal
    or a device's silence, which come back as codes) is answered 0x04 and logged; the
    connection and the server go on, so no request can end the bridge."""

    async def answer(client: Any, request: ProxyRequest) -> tuple[int, ...] | int:
        if request.address == 13:
            raise RuntimeError("a fault of the bridge's own")
        return tuple(range(request.count))

    server = GatewayServer("127.0.0.1", 0, answer, Limits(), ClientBook())
    task = asyncio.create_task(server.run())
    try:
        await asyncio.wait_for(server.ready.wait(), 5)
        client = AsyncModbusTcpClient("127.0.0.1", port=server.port, timeout=3, retries=0)
        await client.connect()
        try:
            failed = await client.read_holding_registers(13, count=2, device_id=1)
            assert failed.isError() and failed.exception_code == 0x04
            served = await client.read_holding_registers(20, count=3, device_id=1)
            assert served.registers == [0, 1, 2]
        finally:
            client.close()
        assert not task.done()
        assert server.book.totals().failed == 1
    finally:
        await cancel(task)
