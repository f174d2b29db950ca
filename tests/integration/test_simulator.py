"""The simulator against a real pymodbus client: TCP on loopback and RTU over a pty pair."""

from __future__ import annotations

import asyncio
import contextlib
import functools
import time
from collections.abc import AsyncIterator
from random import Random

import pytest
from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.exceptions import ModbusIOException
from pymodbus.framer import FramerRTU, FramerType
from pymodbus.pdu import ExceptionResponse, ModbusPDU

from bridge.core.codec import decode, encode
from bridge.core.entity import Table
from bridge.core.mapping import (
    Mapping,
    Point,
    builtin_mapping_names,
    builtin_mapping_path,
    load_mapping,
)
from bridge.core.request import Read, Write
from bridge.core.simulation import advance, build_movers, initial_image
from bridge.modbus.frame import CoilWordRequest, request_pdu, response_values
from bridge.modbus.null_modem import null_modem
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator, two_byte_count_frame
from tests.library.layout import has_no_status

Client = AsyncModbusTcpClient | AsyncModbusSerialClient
NAMES = builtin_mapping_names()
STATUS = {  # the simulated device is running and healthy
    "nastec_vasco": "running",
    "nibe_s": "heating",
    "stiebel_isg": "program",
    "idm_navigator": "off",  # its status word is its bits, which the simulator leaves off
    "p2_vfd": "running_forward",
    "smartgen_hgm6100": "normal_running",
    "soft_starter": "no_fault",
    "vacon_nx": True,
    "abb_terra_ac": "c2_charging",
    "alfen_eve": "c2_charging",
    "phoenix_contact_ev": "c_charging",
    "huawei_sun2000": "running_on_grid",
    "growatt_min_mod": "normal",
    "growatt_sph": "normal",
    "sungrow_sh_rt": "running",
    "sungrow_sg_rt": "running",
    "victron_gx_system": "idle",
    "marstek_venus_e": "discharge",
    "deye_hybrid": "running",
    "solax_x3_hybrid": "running",
    "goodwe_et": "running_on_grid",
}
WRITE = {  # a readable setting per mapping and a value inside its limits
    "eastron_sdm630": ("demand_period", 15),
    "nastec_vasco": ("operating_frequency", 40),
    "nibe_s": ("room_set_point", 21.5),
    "stiebel_isg": ("comfort_temperature_hc1", 21.5),
    "idm_navigator": ("pv_surplus", 2.5),
    "p2_vfd": ("max_output_frequency", 60.5),
    "soft_starter": ("soft_start_time", 20),
    "vacon_nx": ("speed_reference", -25.5),
    "alfen_eve": ("current_limit_setpoint", 13.2),
    "abb_terra_ac": ("current_limit_setpoint", 10),  # written at 4100h, read at 4022h
    "phoenix_contact_ev": ("current_limit_setpoint", 10),
}


@functools.cache
def mapping(name: str) -> Mapping:
    return load_mapping(builtin_mapping_path(name))


def simulator(*units: tuple[int, str], tick: float = 0.0, **quirks: object) -> Simulator:
    specs = [SimulatedUnit(unit, mapping(name), quirks=Quirks(**quirks)) for unit, name in units]
    return Simulator(specs, tick=tick)


@contextlib.asynccontextmanager
async def tcp(sim: Simulator, framer: str = "socket", **client: object) -> AsyncIterator[Client]:
    """Serve ``sim`` on a free loopback port and connect a client to it."""
    server = asyncio.create_task(sim.serve_tcp("127.0.0.1", 0, framer))
    try:
        await asyncio.wait_for(sim.ready.wait(), 5)
        options = {"timeout": 1.0, "retries": 0} | client
        async with AsyncModbusTcpClient(
            "127.0.0.1", port=sim.port, framer=FramerType(framer), **options
        ) as conn:
            conn.register(CoilWordRequest)
            yield conn
    finally:
        server.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await server


@contextlib.asynccontextmanager
async def serial(sim: Simulator, framer: str = "rtu", **client: object) -> AsyncIterator[Client]:
    """Serve ``sim`` on one end of a pty pair and connect a client to the other."""
    with null_modem() as (device_end, client_end):
        server = asyncio.create_task(sim.serve_serial(device_end, framer=framer))
        try:
            await asyncio.wait_for(sim.ready.wait(), 5)
            options = {"timeout": 1.0, "retries": 0, "baudrate": 9600} | client
            async with AsyncModbusSerialClient(
                client_end, framer=FramerType(framer), **options
            ) as conn:
                conn.register(CoilWordRequest)
                yield conn
        finally:
            server.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await server


async def call(conn: Client, request: Read | Write, unit: int = 1) -> ModbusPDU:
    pdu = request_pdu(request, unit)
    return await conn.execute(False, pdu)


async def read(
    conn: Client, table: Table, address: int, count: int = 1, unit: int = 1
) -> tuple[int, ...]:
    request = Read(table, address, count)
    return response_values(await call(conn, request, unit), request)


async def exception_of(conn: Client, request: Read | Write, unit: int = 1) -> int:
    response = await call(conn, request, unit)
    assert isinstance(response, ExceptionResponse), response
    return response.exception_code


async def read_point(
    conn: Client, point: Point, limit: int, unit: int = 1
) -> dict[tuple[Table, int], int]:
    """The point's cells, read in chunks the device accepts."""
    cells: dict[tuple[Table, int], int] = {}
    for start in range(point.address, point.address + point.count, limit):
        count = min(limit, point.address + point.count - start)
        words = await read(conn, point.table, start, count, unit)
        cells |= {(point.table, start + i): word for i, word in enumerate(words)}
    return cells


# --- initial values and writes ---------------------------------------------------------------


@pytest.mark.asyncio
@pytest.mark.parametrize("name", NAMES)
async def test_initial_values_read_back_decoded(name: str) -> None:
    """Every readable entity, read with the device's own read limit, decodes to the
    simulator's value; the device runs, no alarm is active, nothing was written."""
    sim = simulator((1, name))
    points = {k: p for k, p in mapping(name).points().items() if p.entity.readable}
    limit = mapping(name).protocol.max_read_registers
    image: dict[tuple[Table, int], int] = {}
    async with tcp(sim) as conn:
        for point in points.values():
            image |= await read_point(conn, point, limit)
    for key, point in points.items():
        value = decode(point, image)
        assert value == sim.value(1, key), key
        if point.entity.alarm:
            labels = point.entity.enum or {}
            assert value in {False, *(labels.get(raw) for raw in point.entity.normal)}, key
        elif point.entity.kind == "number" and value is None:
            pytest.fail(f"{key} reads as a sentinel")
    status = mapping(name).status
    assert status is None or sim.value(1, status) == STATUS[name]
    assert (status is None) is has_no_status(mapping(name))  # a meter has no status word
    assert sim.writes == []


@pytest.mark.asyncio
@pytest.mark.parametrize("name", sorted(WRITE))
async def test_a_write_sticks_and_reads_back(name: str) -> None:
    key, value = WRITE[name]
    sim = simulator((1, name))
    point = mapping(name).points()[key]
    (write,) = encode(point, value, sim.image(1))
    async with tcp(sim) as conn:
        response = await call(conn, write)
        assert not isinstance(response, ExceptionResponse), response
        cells = await read_point(conn, point, 1)
    assert decode(point, cells) == value
    assert sim.value(1, key) == value
    assert sim.writes == [(1, write)]


@pytest.mark.asyncio
async def test_a_reaction_changes_other_cells_after_an_accepted_write_only() -> None:
    """A status register that follows a command register: the reaction's cells are what
    the next read answers; a refused write (to a read-only register) reaches no reaction."""
    sim = simulator((1, "soft_starter"))
    point = mapping("soft_starter").points()["soft_start_time"]
    status = (Table.HOLDING, point.address + 1)
    seen: list[Write] = []

    def follow(unit: int, write: Write) -> dict[tuple[Table, int], int]:
        seen.append(write)
        return {status: write.values[0] + 1000}

    sim.reactions.append(follow)
    (write,) = encode(point, 20, sim.image(1))
    refused = Write(6, Table.HOLDING, 0x7FFF, (5,))
    async with tcp(sim) as conn:
        assert await exception_of(conn, refused) == 2
        assert not isinstance(await call(conn, write), ExceptionResponse)
        after = await read(conn, *status)
    assert seen == [write]
    assert after == (write.values[0] + 1000,)
    assert sim.writes == [(1, refused), (1, write)]


@pytest.mark.asyncio
async def test_set_value_is_what_the_client_reads() -> None:
    sim = simulator((1, "nastec_vasco"))
    sim.set_value(1, "alarm_dry_running", True)
    sim.set_value(1, "motor_current", 7.5)  # read-only on the device
    points = mapping("nastec_vasco").points()
    async with tcp(sim) as conn:
        word = await read(conn, Table.HOLDING, points["alarm_dry_running"].address)
        current = await read(conn, Table.HOLDING, points["motor_current"].address)
    assert word[0] & 0b1000
    assert current == (75,)
    assert sim.writes == []


# --- quirks -------------------------------------------------------------------------------------


@pytest.mark.asyncio
async def test_read_limit_answers_02_or_the_declared_code() -> None:
    vacon = simulator((1, "vacon_nx"), max_read_registers=2)
    async with tcp(vacon) as conn:
        assert len(await read(conn, Table.HOLDING, 2001, 2)) == 2
        assert await exception_of(conn, Read(Table.HOLDING, 2001, 3)) == 2
    soft = simulator((1, "soft_starter"))  # limit 6; exception 03 is "register count ..."
    async with tcp(soft) as conn:
        assert len(await read(conn, Table.HOLDING, 0x1001, 6)) == 6
        assert await exception_of(conn, Read(Table.HOLDING, 0x1001, 7)) == 3


@pytest.mark.asyncio
async def test_gaps_reserved_and_refused_addresses_answer_02() -> None:
    p2 = simulator((1, "p2_vfd"))
    async with tcp(p2) as conn:
        assert await exception_of(conn, Read(Table.HOLDING, 0x100C, 1)) == 2  # reserved
        assert await exception_of(conn, Read(Table.HOLDING, 0x1008, 8)) == 2  # crosses it
        assert await exception_of(conn, Read(Table.HOLDING, 0x2000, 1)) == 2  # write-only
        assert await exception_of(conn, Read(Table.INPUT, 0x1000, 1)) == 1  # FC04 unsupported
    vacon = simulator((1, "vacon_nx"))  # readable gaps: ID 10 reads 0, reserved ID 100 does not
    async with tcp(vacon) as conn:
        assert await read(conn, Table.HOLDING, 9) == (0,)
        assert await exception_of(conn, Read(Table.HOLDING, 99, 1)) == 2
        vacon.set_quirks(1, Quirks(refuse_gaps=True, refused=frozenset({2002})))
        assert await exception_of(conn, Read(Table.HOLDING, 9, 1)) == 2
        assert await exception_of(conn, Read(Table.HOLDING, 2002, 1)) == 2
        assert await exception_of(conn, Write(6, Table.HOLDING, 2002, (5,))) == 2
        assert await read(conn, Table.HOLDING, 2001) == (vacon.image(1)[(Table.HOLDING, 2001)],)
    assert vacon.value(1, "speed_reference") == 50.0  # the refused write changed nothing


@pytest.mark.asyncio
async def test_smartgen_fc05_echoes_00ff_refuses_ff00_and_keeps_status_bits() -> None:
    sim = simulator((1, "smartgen_hgm6100"))
    seen: list[bytes] = []

    def trace(sending: bool, data: bytes) -> bytes:
        if not sending:
            seen.append(bytes(data))
        return data

    before = sim.image(1)
    async with serial(sim, trace_packet=trace) as conn:
        response = await call(conn, Write(5, Table.COIL, 3, (0x00FF,)))
        assert isinstance(response, CoilWordRequest)
        assert list(response.registers) == [0x00FF]
        assert b"".join(seen).endswith(bytes.fromhex("01 05 00 03 00 FF 7D 8A"))
        assert await exception_of(conn, Write(5, Table.COIL, 3, (0xFF00,))) == 3
        refused = await conn.write_coil(4, True, device_id=1)  # pymodbus' own FC05: FF00
        assert refused.isError()
        assert await read(conn, Table.COIL, 0, 82) == tuple(
            before.get((Table.COIL, a), 0) for a in range(82)
        )
    assert sim.image(1) == before  # commands share addresses with FC01 status bits
    assert [w.values for _, w in sim.writes] == [(0x00FF,), (0xFF00,), (0xFF00,)]
    sim.set_quirks(1, Quirks(coil_on_value=0xFF00))  # an N-series controller
    async with tcp(sim) as conn:
        assert not (await conn.write_coil(3, True, device_id=1)).isError()
        assert await exception_of(conn, Write(5, Table.COIL, 3, (0x00FF,))) == 3


@pytest.mark.asyncio
async def test_exception_code_answers_everything() -> None:
    sim = simulator((1, "p2_vfd"), exception_code=8)  # the P2 busy saving to EEPROM
    async with tcp(sim) as conn:
        assert await exception_of(conn, Read(Table.HOLDING, 0x1000, 1)) == 8
        assert await exception_of(conn, Write(6, Table.HOLDING, 0x1000, (100,))) == 8
        sim.set_quirks(1, Quirks())
        assert len(await read(conn, Table.HOLDING, 0x1000)) == 1
    assert sim.value(1, "set_value") == 50.0
    with pytest.raises(ValueError, match="exception_code 9"):
        sim.set_quirks(1, Quirks(exception_code=9))


@pytest.mark.asyncio
async def test_dead_and_unknown_units_do_not_answer() -> None:
    sim = simulator((1, "soft_starter"))
    async with tcp(sim, timeout=0.3) as conn:
        assert await read(conn, Table.HOLDING, 0x1031) == (12,)
        sim.set_quirks(1, Quirks(dead=True))
        with pytest.raises(ModbusIOException):
            await read(conn, Table.HOLDING, 0x1031)
        with pytest.raises(ModbusIOException):
            await call(conn, Write(6, Table.HOLDING, 0x1002, (100,)))
        with pytest.raises(ModbusIOException):
            await read(conn, Table.HOLDING, 0x1031, unit=7)
        sim.set_quirks(1, Quirks())
        assert await read(conn, Table.HOLDING, 0x1031) == (12,)
    assert sim.writes == []  # a dead device receives nothing


@pytest.mark.asyncio
async def test_latency_delays_every_answer() -> None:
    sim = simulator((1, "vacon_nx"), latency=0.2)
    async with tcp(sim) as conn:
        for request in (Read(Table.HOLDING, 2100, 1), Read(Table.HOLDING, 99, 1)):
            started = time.monotonic()
            await call(conn, request)
            assert time.monotonic() - started >= 0.2


@pytest.mark.asyncio
async def test_write_times_stamp_each_write_on_arrival_before_the_latency() -> None:
    sim = simulator((1, "soft_starter"), latency=0.2)
    writes = [Write(6, Table.HOLDING, 0x1030, (v,)) for v in (1, 0)]
    sent, answered = [], []
    async with tcp(sim) as conn:
        for write in writes:
            sent.append(time.monotonic())
            await call(conn, write)
            answered.append(time.monotonic())
    assert sim.writes == [(1, w) for w in writes]
    assert len(sim.write_times) == 2
    for stamp, before, after in zip(sim.write_times, sent, answered, strict=True):
        assert before <= stamp <= after - 0.2  # on arrival, the latency still to come


@pytest.mark.asyncio
async def test_two_byte_count_on_rtu() -> None:
    sim = simulator((1, "p2_vfd"), two_byte_count=True)
    seen: list[bytes] = []

    def trace(sending: bool, data: bytes) -> bytes:
        if not sending:
            seen.append(bytes(data))
        return data

    words = [sim.image(1)[(Table.HOLDING, 0x1000 + i)] for i in range(2)]
    standard = bytes([1, 3, 4]) + b"".join(w.to_bytes(2, "big") for w in words)
    standard += FramerRTU.compute_CRC(standard).to_bytes(2, "big")
    expected = two_byte_count_frame(standard)
    assert expected[:4] == bytes([1, 3, 0, 4])
    async with serial(sim, trace_packet=trace, timeout=0.5) as conn:
        with pytest.raises(ModbusIOException):  # no standard parser takes it
            await read(conn, Table.HOLDING, 0x1000, 2)
        assert expected in b"".join(seen)
        sim.set_quirks(1, Quirks())
        assert await read(conn, Table.HOLDING, 0x1000, 2) == tuple(words)


# --- several units, moving values --------------------------------------------------------------


@pytest.mark.asyncio
async def test_two_units_on_one_tcp_port() -> None:
    sim = simulator((1, "nastec_vasco"), (2, "p2_vfd"))
    nastec, p2 = mapping("nastec_vasco").points(), mapping("p2_vfd").points()
    async with tcp(sim, timeout=0.3) as conn:
        status_1 = await read(conn, Table.HOLDING, nastec["status"].address, unit=1)
        status_2 = await read(conn, Table.HOLDING, p2["status"].address, unit=2)
        assert (
            decode(nastec["status"], {(Table.HOLDING, nastec["status"].address): status_1[0]})
            == "running"
        )
        assert (
            decode(p2["status"], {(Table.HOLDING, p2["status"].address): status_2[0]})
            == "running_forward"
        )
        assert await exception_of(conn, Read(Table.HOLDING, p2["status"].address, 1), unit=1) == 2
        with pytest.raises(ModbusIOException):
            await read(conn, Table.HOLDING, 0x3000, unit=3)


@pytest.mark.asyncio
async def test_unit_0_answers_every_unit_id_no_other_unit_has() -> None:
    """A Modbus TCP device that ignores the unit id (pymodbus' SimDevice id 0)."""
    sim = simulator((0, "p2_vfd"), (3, "soft_starter"))
    async with tcp(sim, timeout=0.3) as conn:
        for unit in (1, 2, 247, 255):
            assert await read(conn, Table.HOLDING, 0x3000, unit=unit) == (1,)  # running_forward
        assert await read(conn, Table.HOLDING, 0x1031, unit=3) == (12,)  # its own unit
        assert not (await call(conn, Write(6, Table.HOLDING, 0x2000, (6,)), unit=255)).isError()
    assert sim.writes == [(0, Write(6, Table.HOLDING, 0x2000, (6,)))]
    assert sim.image(0)[(Table.HOLDING, 0x2000)] == 6


@pytest.mark.asyncio
async def test_two_units_on_one_serial_line() -> None:
    sim = simulator((1, "smartgen_hgm6100"), (5, "soft_starter"))
    async with serial(sim) as conn:
        genset = await read(conn, Table.HOLDING, 34, unit=1)
        soft = await read(conn, Table.HOLDING, 0x1036, unit=5)
        coils = await read(conn, Table.COIL, 0, 8, unit=1)
    assert genset == (9,)  # normal_running
    assert soft == (0,)  # no_fault
    assert coils == (0,) * 8


@pytest.mark.asyncio
async def test_rtu_over_tcp_and_ascii_on_a_serial_line() -> None:
    sim = simulator((1, "p2_vfd"))
    async with tcp(sim, framer="rtu") as conn:
        assert await read(conn, Table.HOLDING, 0x3000) == (1,)  # running_forward
        assert await exception_of(conn, Read(Table.HOLDING, 0x1000, 17)) == 2
    async with serial(sim, framer="ascii") as conn:
        assert await read(conn, Table.HOLDING, 0x8000) == (0,)  # no_fault
        assert not (await call(conn, Write(6, Table.HOLDING, 0x2000, (6,)))).isError()
    assert sim.writes == [(1, Write(6, Table.HOLDING, 0x2000, (6,)))]
    assert sim.image(1)[(Table.HOLDING, 0x2000)] == 6  # a write-only register takes writes


@pytest.mark.asyncio
async def test_values_move_after_a_tick() -> None:
    sim = simulator((1, "smartgen_hgm6100"), tick=0.05)
    async with tcp(sim) as conn:
        first = await read(conn, Table.HOLDING, 0, 56)
        deadline = time.monotonic() + 5
        later = first
        while later == first and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
            later = await read(conn, Table.HOLDING, 0, 56)
        assert later != first
        await asyncio.sleep(0.2)
    assert isinstance(sim.value(1, "run_hours"), int)
    assert sim.value(1, "run_hours") >= 1250  # counters never fall (and rise by the hour:
    # tests/mappings/test_simulated_values.py walks them over a simulated hour)
    assert sim.value(1, "genset_status") == "normal_running"  # the status stays put
    for key, (low, high) in {
        "generator_voltage_ua": (184, 276),
        "generator_frequency": (40, 60),
    }.items():
        value = sim.value(1, key)
        assert isinstance(value, int | float)
        assert low <= value <= high, key  # the walk stays in its range


def test_moving_values_are_deterministic_for_a_seed() -> None:
    m = mapping("vacon_nx")
    points = m.points()
    runs = []
    for _ in range(2):
        image = initial_image(m, points)
        movers, rng = build_movers(points, image), Random(42)
        for _ in range(20):
            image |= advance(movers, image, rng)
        runs.append(image)
    assert runs[0] == runs[1] != initial_image(m, points)
