"""Commissioning helpers against the real simulator over TCP and over a pty (RTU).

Probe and scan find units by any answer, raw reads return what the simulated unit holds,
raw writes land and read back, and a bad request raises before a frame is sent.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
from collections.abc import AsyncIterator

import pytest

from bridge.config import SerialBus, TcpBus
from bridge.core.entity import Table
from bridge.core.request import Read, Write
from bridge.errors import (
    BusError,
    DeviceExceptionError,
    DeviceTimeoutError,
    FrameError,
    ValueRejectedError,
)
from bridge.modbus.commission import (
    Answer,
    explain,
    open_bus,
    probe,
    raw_read,
    raw_write,
    read_interpreted,
    scan,
    scheduler_submit,
)
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import Quirks, Simulator
from tests.integration.harness import config, running, serving_serial, serving_tcp, simulator
from tests.integration.harness import tcp_bus as tcp_bus_fields

HOLDING = Table.HOLDING


def tcp_bus(port: int, transport: str = "tcp") -> TcpBus:
    return TcpBus(id="tcp", transport=transport, host="127.0.0.1", tcp_port=port, timeout=0.5)


def held(sim: Simulator, unit: int, table: Table, first: int, count: int) -> list[int]:
    """What the simulated unit holds, from its own image (0 where it holds nothing)."""
    image = sim.image(unit)
    return [image.get((table, address), 0) for address in range(first, first + count)]


# --- scan and probe -------------------------------------------------------------------


@pytest.mark.asyncio
async def test_scan_over_tcp_finds_exactly_the_simulated_units() -> None:
    sim = simulator((1, "nastec_vasco"), (3, "p2_vfd"))
    heard: list[tuple[int, bool]] = []
    async with serving_tcp(sim) as port, open_bus(tcp_bus(port)) as submit:
        found = await scan(submit, range(1, 7), 0.2, lambda u, f: heard.append((u, f is not None)))
    assert [f.unit for f in found] == [1, 3]
    assert heard == [(1, True), (2, False), (3, True), (4, False), (5, False), (6, False)]
    # holding 0 is in neither mapping, and both refuse reads of gaps: present all the same
    assert all(f.answer is Answer.EXCEPTION and f.exception_code == 2 for f in found)
    assert found[0].describe() == "exception 2 (illegal data address)"


@pytest.mark.asyncio
async def test_scan_over_a_pty_rtu_line() -> None:
    sim = simulator((1, "nastec_vasco"), (3, "p2_vfd"))
    async with serving_serial(sim, baudrate=19200) as port:
        bus = SerialBus(id="rs485", transport="rtu", port=port, baudrate=19200, timeout=0.3)
        async with open_bus(bus) as submit:
            found = await scan(submit, [4, 3, 2, 1], 0.3)
            reading = await read_interpreted(submit, 3, raw_read(HOLDING, 0x1000, 4), 1.0)
    assert [f.unit for f in found] == [3, 1]
    assert reading["registers"] == held(sim, 3, HOLDING, 0x1000, 4)


@pytest.mark.asyncio
async def test_scan_over_rtu_over_tcp() -> None:
    sim = simulator((2, "soft_starter"))
    async with serving_tcp(sim, "rtu") as port, open_bus(tcp_bus(port, "rtu-over-tcp")) as submit:
        found = await scan(submit, [1, 2], 0.3)
    assert [f.unit for f in found] == [2]


@pytest.mark.asyncio
async def test_probe_answers_values_exceptions_or_nothing() -> None:
    sim = simulator((1, "nastec_vasco"), (3, "p2_vfd"))
    async with serving_tcp(sim) as port, open_bus(tcp_bus(port)) as submit:
        answered = await probe(submit, 1, 0.5, Read(HOLDING, 54, 1))
        sim.set_quirks(1, Quirks(refused=frozenset({54})))
        refused = await probe(submit, 1, 0.5, Read(HOLDING, 54, 1))
        sim.set_quirks(3, Quirks(exception_code=6))
        busy = await probe(submit, 3, 0.5)
        sim.set_quirks(3, Quirks(dead=True))
        dead = await probe(submit, 3, 0.2)
    assert answered is not None
    assert (answered.answer, answered.values) == (
        Answer.VALUES,
        tuple(held(sim, 1, HOLDING, 54, 1)),
    )
    assert answered.describe() == f"values 0x{answered.values[0]:04X}"
    assert refused is not None
    assert (refused.answer, refused.exception_code, refused.detail) == (
        Answer.EXCEPTION,
        2,
        "illegal data address",
    )
    assert busy is not None
    assert (busy.exception_code, busy.detail) == (6, "server device busy")
    assert dead is None


@contextlib.asynccontextmanager
async def garbling_server() -> AsyncIterator[int]:
    """A real TCP peer that answers every FC03 read of one register with two registers."""
    handlers: list[asyncio.Event] = []

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        done = asyncio.Event()
        handlers.append(done)
        try:
            while True:
                head = await reader.readexactly(7)
                await reader.readexactly(int.from_bytes(head[4:6], "big") - 1)
                pdu = bytes([3, 4, 0x00, 0x01, 0x00, 0x02])
                writer.write(head[:4] + (len(pdu) + 1).to_bytes(2, "big") + head[6:7] + pdu)
                await writer.drain()
        except (asyncio.IncompleteReadError, ConnectionError):
            pass
        finally:
            writer.close()
            done.set()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    try:
        yield int(server.sockets[0].getsockname()[1])
    finally:
        server.close()
        await server.wait_closed()
        for done in handlers:
            await asyncio.wait_for(done.wait(), 5)


@pytest.mark.asyncio
async def test_a_garbled_answer_counts_as_present_with_its_error() -> None:
    async with garbling_server() as port, open_bus(tcp_bus(port)) as submit:
        found = await scan(submit, [7], 0.5)
    assert [(f.unit, f.answer, f.detail) for f in found] == [
        (7, Answer.GARBLED, "asked for 1 values, got 2")
    ]
    assert found[0].describe() == "garbled answer: asked for 1 values, got 2"
    assert found[0].as_dict()["answer"] == "garbled"


@pytest.mark.asyncio
async def test_scan_through_the_running_bridge_scheduler() -> None:
    sim = simulator((1, "nastec_vasco"), (3, "p2_vfd"))
    async with serving_tcp(sim) as port:
        devices = [{"id": "pump", "bus": "tcp", "unit": 1, "mapping": "nastec_vasco"}]
        # generous timeouts: the loop serves the simulator, the poll and the scan, on a
        # machine running other test workers (CI saw a 0.5 s connect time out)
        engine = Engine(config([tcp_bus_fields(port, timeout=2.0)], devices))
        async with running(engine):
            submit = scheduler_submit(engine.schedulers["tcp"])
            found = await scan(submit, [1, 2, 3], 1.0)
            reading = await read_interpreted(submit, 1, raw_read(HOLDING, 54), 1.0)
    assert [f.unit for f in found] == [1, 3]
    assert reading["registers"] == held(sim, 1, HOLDING, 54, 1)


@pytest.mark.asyncio
async def test_a_bus_that_cannot_open_fails_at_once() -> None:
    with pytest.raises(BusError, match="cannot open"):
        async with open_bus(SerialBus(id="rs485", transport="rtu", port="/dev/nonexistent-tty")):
            pytest.fail("opened a port that does not exist")


@pytest.mark.asyncio
async def test_an_error_in_the_block_is_not_wrapped() -> None:
    sim = simulator((1, "nastec_vasco"))
    async with serving_tcp(sim) as port:
        with pytest.raises(DeviceExceptionError) as caught:
            async with open_bus(tcp_bus(port)) as submit:
                await submit(1, Read(HOLDING, 0, 1), 0.5)
    assert explain(1, caught.value) == "unit 1 refused: exception 2 (illegal data address)"


# --- raw reads and writes against the simulator ----------------------------------------


@pytest.mark.asyncio
async def test_read_returns_what_the_unit_holds() -> None:
    sim = simulator((3, "p2_vfd"), (4, "smartgen_hgm6100"))
    async with serving_tcp(sim) as port, open_bus(tcp_bus(port)) as submit:
        registers = await read_interpreted(submit, 3, raw_read("holding", 0x1000, 8), 1.0)
        coils = await read_interpreted(submit, 4, raw_read("coil", 64, 15), 1.0)
    assert registers["unit"] == 3
    assert registers["table"] == "holding"
    assert registers["registers"] == held(sim, 3, HOLDING, 0x1000, 8)
    assert [w["u16"] for w in registers["words"]] == registers["registers"]
    assert len(registers["pairs"]) == 7
    assert coils["table"] == "coil"
    assert coils["bits"] == held(sim, 4, Table.COIL, 64, 15)
    assert coils["on"] == [64 + i for i, bit in enumerate(coils["bits"]) if bit]


@pytest.mark.asyncio
async def test_write_then_read_back() -> None:
    sim = simulator((1, "nastec_vasco"), (2, "soft_starter"))
    async with serving_tcp(sim) as port, open_bus(tcp_bus(port)) as submit:
        single = raw_write("holding", 54, [123])
        assert await submit(1, single, 1.0) == (123,)  # FC06: the unit's echo
        assert await submit(1, raw_read(HOLDING, 54), 1.0) == (123,)
        several = raw_write(HOLDING, 4097, [7, 0x0008])
        await submit(2, several, 1.0)
        assert await submit(2, raw_read(HOLDING, 4097, 2), 1.0) == (7, 8)
    assert sim.writes == [(1, Write(6, HOLDING, 54, (123,))), (2, Write(16, HOLDING, 4097, (7, 8)))]
    assert held(sim, 1, HOLDING, 54, 1) == [123]


@pytest.mark.asyncio
async def test_coil_write_uses_the_on_word_the_device_wants() -> None:
    sim = simulator((4, "smartgen_hgm6100"))  # FC05 ON is 00 FF on this controller
    async with serving_tcp(sim) as port, open_bus(tcp_bus(port)) as submit:
        with pytest.raises(DeviceExceptionError) as caught:
            await submit(4, raw_write("coil", 0, [1]), 1.0)
        await submit(4, raw_write("coil", 0, [1], coil_on_value=0x00FF), 1.0)
    assert explain(4, caught.value) == "unit 4 refused: exception 3 (illegal data value)"
    assert sim.writes == [
        (4, Write(5, Table.COIL, 0, (0xFF00,))),
        (4, Write(5, Table.COIL, 0, (0x00FF,))),
    ]


@pytest.mark.asyncio
async def test_a_bad_write_raises_before_anything_is_sent() -> None:
    sim = simulator((1, "nastec_vasco"))
    async with serving_tcp(sim) as port, open_bus(tcp_bus(port)) as submit:
        before = held(sim, 1, HOLDING, 54, 1)
        for values in ([70000], [-1], [1, 2**16]):
            with pytest.raises(ValueRejectedError, match=re.escape("write 0..65535")):
                await submit(1, raw_write("holding", 54, values), 1.0)
        with pytest.raises(DeviceTimeoutError):  # the bus still works: unit 9 is absent
            await submit(9, raw_read(HOLDING, 54), 0.2)
    assert sim.writes == []
    assert held(sim, 1, HOLDING, 54, 1) == before


def test_explain_names_the_exception_and_its_meaning() -> None:
    busy = DeviceExceptionError(6, "server device busy", "busy")
    failed = DeviceExceptionError(4, "server device failure", "fail")
    assert explain(3, busy) == "unit 3 is busy: exception 6 (server device busy)"
    assert explain(3, failed) == "unit 3 failed: exception 4 (server device failure)"
    assert explain(3, FrameError("unit 3: bad CRC")) == "unit 3: bad CRC"


# --- request checks (pure: nothing is sent) ----------------------------------------------


@pytest.mark.parametrize(
    ("table", "address", "values", "options", "expected"),
    [
        ("holding", 0x97, [100], {}, Write(6, HOLDING, 0x97, (100,))),
        ("holding", 0x97, [100], {"function": 16}, Write(16, HOLDING, 0x97, (100,))),
        ("holding", 0, [1, 0xFFFF], {}, Write(16, HOLDING, 0, (1, 0xFFFF))),
        ("holding", 0, [0] * 123, {}, Write(16, HOLDING, 0, (0,) * 123)),
        ("holding", 0xFFFF, [5], {}, Write(6, HOLDING, 0xFFFF, (5,))),
        ("coil", 3, [1], {}, Write(5, Table.COIL, 3, (0xFF00,))),
        ("coil", 3, [0], {}, Write(5, Table.COIL, 3, (0x0000,))),
        ("coil", 3, [True], {"coil_on_value": 0x00FF}, Write(5, Table.COIL, 3, (0x00FF,))),
        ("coil", 3, [1], {"function": 15}, Write(15, Table.COIL, 3, (1,))),
        ("coil", 0, [1, 0, 1], {}, Write(15, Table.COIL, 0, (1, 0, 1))),
        ("coil", 0, [1] * 1968, {}, Write(15, Table.COIL, 0, (1,) * 1968)),
    ],
)
def test_raw_write_picks_the_function(
    table: str, address: int, values: list[int], options: dict[str, int], expected: Write
) -> None:
    assert raw_write(table, address, values, **options) == expected


@pytest.mark.parametrize(
    ("table", "address", "values", "options", "message"),
    [
        ("input", 0, [1], {}, "the input table is read-only: write holding or coil"),
        ("discrete", 0, [1], {}, "the discrete table is read-only"),
        ("inputs", 0, [1], {}, "table 'inputs': choose holding, input, coil, discrete"),
        ("holding", 0, [65536], {}, "register value 65536: write 0..65535"),
        (
            "holding",
            0,
            [-1],
            {},
            "register value -1: write 0..65535 (0x0000..0xFFFF; -1 is 0xFFFF)",
        ),
        ("holding", 0, [1.5], {}, "register value 1.5: write 0..65535"),
        ("holding", 0, [True], {}, "register value True: write 0..65535"),
        ("coil", 0, [2], {}, "coil value 2: write 0 or 1"),
        ("coil", 0, [1.0], {}, "coil value 1.0: write 0 or 1"),
        ("holding", 0, [], {}, "0 values: FC16 writes 1..123 registers"),
        ("holding", 0, [0] * 124, {}, "124 values: FC16 writes 1..123 registers"),
        ("coil", 0, [0] * 1969, {}, "1969 values: FC15 writes 1..1968 coils"),
        ("holding", 0, [1, 2], {"function": 6}, "2 values: FC06 writes 1..1 registers"),
        ("holding", 0, [1], {"function": 5}, "FC05 does not write registers"),
        ("coil", 0, [1], {"function": 16}, "FC16 does not write coils"),
        ("holding", 0x10000, [1], {}, "address 65536: wire addresses are 0..65535"),
        ("holding", -1, [1], {}, "address -1: wire addresses are 0..65535"),
        ("holding", 0xFFFF, [1, 2], {}, "address 65535 + 2 values runs past 65535"),
        ("coil", 0, [1], {"coil_on_value": 0}, "coil ON word 0: use 0x0001..0xFFFF"),
    ],
)
def test_raw_write_refuses_with_a_clear_message(
    table: str, address: int, values: list[int], options: dict[str, int], message: str
) -> None:
    with pytest.raises(ValueRejectedError, match=re.escape(message)):
        raw_write(table, address, values, **options)


@pytest.mark.parametrize(
    ("table", "address", "count", "message"),
    [
        ("holding", 0, 126, "count 126: read 1..125 registers at a time"),
        ("input", 0, 0, "count 0: read 1..125 registers at a time"),
        ("coil", 0, 2001, "count 2001: read 1..2000 coils at a time"),
        ("discrete", 0, 2001, "count 2001: read 1..2000 discrete inputs at a time"),
        ("holding", 65535, 2, "address 65535 + 2 values runs past 65535"),
        ("register", 0, 1, "table 'register': choose holding"),
    ],
)
def test_raw_read_limits(table: str, address: int, count: int, message: str) -> None:
    with pytest.raises(ValueRejectedError, match=re.escape(message)):
        raw_read(table, address, count)


def test_raw_read_within_limits() -> None:
    assert raw_read("holding", 0, 125) == Read(HOLDING, 0, 125)
    assert raw_read(Table.DISCRETE, 10, 2000) == Read(Table.DISCRETE, 10, 2000)
    assert raw_read("input", 65535) == Read(Table.INPUT, 65535, 1)


@pytest.mark.asyncio
async def test_scan_refuses_unit_0_before_sending() -> None:
    async def never(unit: int, request: Read | Write, timeout: float) -> tuple[int, ...]:
        raise AssertionError("sent")

    with pytest.raises(ValueRejectedError, match=re.escape("unit 0: address units 1..255")):
        await scan(never, [1, 0], 0.1)
    with pytest.raises(ValueRejectedError, match="unit 256"):
        await probe(never, 256, 0.1)
