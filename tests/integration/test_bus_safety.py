"""A faulty field bus cannot feed the bridge wrong values or end it (issue 11, items 8 and 11).

Misbehaving peers on loopback: a scripted RTU-over-TCP gateway and a scripted Modbus TCP
gateway whose answers (late, wrong function code, wrong byte count, wrong unit, garbage)
are chosen per request, talking to the bridge's real Transport and BusScheduler (pymodbus
underneath); and serial ports the OS will not open or configure, beside a working bus.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest
from pymodbus.framer import FramerRTU

from bridge.config import TcpBus
from bridge.core.entity import Table
from bridge.core.request import Read
from bridge.errors import DeviceTimeoutError, FrameError, ModbusError
from bridge.modbus.engine import Engine, bus_scheduler
from bridge.modbus.null_modem import null_modem
from tests.integration.harness import (
    cancel,
    config,
    eventually,
    running,
    serving_tcp,
    simulator,
    tcp_bus,
)

TIMEOUT = 0.3

# An answer: (seconds to wait, bytes) pairs, or nothing (silence).
Answer = list[tuple[float, bytes]]
Script = Callable[[int, int, int, int], Answer]  # (unit, function, address, count) -> answer


def crc(frame: bytes) -> bytes:
    return FramerRTU.compute_CRC(frame).to_bytes(2, "big")


def registers(unit: int, function: int, address: int, count: int) -> bytes:
    """A read reply carrying ``address + i`` in register i: the values name the request."""
    body = bytes([unit, function, 2 * count])
    body += b"".join((address + i).to_bytes(2, "big") for i in range(count))
    return body


def rtu(pdu: bytes) -> bytes:
    return pdu + crc(pdu)


def mbap(tid: int, pdu: bytes) -> bytes:
    return tid.to_bytes(2, "big") + b"\x00\x00" + len(pdu).to_bytes(2, "big") + pdu


class Gateway:
    """A TCP gateway answering each request as ``script`` says; ``mode`` is ``rtu`` (RTU
    frames over TCP, no transaction id) or ``socket`` (Modbus TCP, MBAP header). Like a
    serial line behind it, it answers one request after the other: a request that comes
    while an answer is still due is answered after that answer."""

    def __init__(self, script: Script, mode: str = "rtu") -> None:
        self.script = script
        self.mode = mode
        self.connections = 0
        self.requests: list[tuple[int, int, int, int]] = []
        self.port = 0
        self._free_at = 0.0  # loop time when the line behind is free again

    async def serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.connections += 1
        try:
            while True:
                if self.mode == "rtu":
                    frame = await reader.readexactly(8)  # FC01-04: fixed length
                    tid, pdu = 0, frame[:6]
                else:
                    header = await reader.readexactly(7)
                    tid = int.from_bytes(header[:2], "big")
                    length = int.from_bytes(header[4:6], "big")
                    pdu = header[6:] + await reader.readexactly(length - 1)
                unit, function = pdu[0], pdu[1]
                address = int.from_bytes(pdu[2:4], "big")
                count = int.from_bytes(pdu[4:6], "big")
                self.requests.append((unit, function, address, count))
                loop = asyncio.get_running_loop()
                start = max(loop.time(), self._free_at)
                for delay, data in self.script(unit, function, address, count):
                    self._free_at = start + delay
                    loop.call_at(self._free_at, self._send, writer, tid, data)
        except (asyncio.IncompleteReadError, ConnectionError):
            pass
        finally:
            writer.close()

    def _send(self, writer: asyncio.StreamWriter, tid: int, data: bytes) -> None:
        if not writer.is_closing():
            writer.write(rtu(data) if self.mode == "rtu" else mbap(tid, data))


@contextlib.asynccontextmanager
async def gateway(script: Script, mode: str = "rtu") -> AsyncIterator[Gateway]:
    peer = Gateway(script, mode)
    server = await asyncio.start_server(peer.serve, "127.0.0.1", 0)
    peer.port = server.sockets[0].getsockname()[1]
    try:
        yield peer
    finally:
        server.close()


@contextlib.asynccontextmanager
async def scheduling(peer: Gateway) -> AsyncIterator[Callable[..., object]]:
    transport = "rtu-over-tcp" if peer.mode == "rtu" else "tcp"
    bus = TcpBus(id="gw", transport=transport, host="127.0.0.1", tcp_port=peer.port)
    scheduler = bus_scheduler(bus)
    task = asyncio.create_task(scheduler.run())

    async def read(unit: int, address: int, count: int = 2, table: Table = Table.HOLDING) -> object:
        return await scheduler.submit(unit, Read(table, address, count), timeout=TIMEOUT)

    try:
        yield read
    finally:
        await cancel(task)


# --- item 11: a late reply is never taken for the next request -----------------------------


@pytest.mark.asyncio
async def test_a_reply_two_timeouts_late_is_not_taken_for_the_next_read() -> None:
    late = {100: 2.05 * TIMEOUT}  # the first read of 100 is answered far too late

    def script(unit: int, function: int, address: int, count: int) -> Answer:
        delay = late.pop(address, 0.0)
        return [(delay, registers(unit, function, address, count))]

    async with gateway(script) as peer, scheduling(peer) as read:
        with pytest.raises(DeviceTimeoutError):
            await read(1, 100)
        assert await read(1, 0) == (0, 1)  # never (100, 101)
        assert await read(1, 100) == (100, 101)
        assert await read(1, 0) == (0, 1)
    assert len(peer.requests) == 4


@pytest.mark.asyncio
async def test_a_reply_with_another_function_code_is_refused() -> None:
    def script(unit: int, function: int, address: int, count: int) -> Answer:
        other = 4 if function == 3 else 3
        return [(0.0, registers(unit, other, address, count))]

    async with gateway(script) as peer, scheduling(peer) as read:
        with pytest.raises(FrameError, match="function"):
            await read(1, 10)


@pytest.mark.asyncio
async def test_a_reply_with_the_wrong_byte_count_is_refused() -> None:
    def script(unit: int, function: int, address: int, count: int) -> Answer:
        if function == 1:  # 3 coils fit one byte; two bytes is not the answer asked for
            return [(0.0, bytes([unit, 1, 2, 0b101, 0xFF]))]
        return [(0.0, registers(unit, function, address, count + 1))]

    async with gateway(script) as peer, scheduling(peer) as read:
        with pytest.raises(FrameError):
            await read(1, 10, 2)
        with pytest.raises(FrameError):
            await read(1, 10, 3, Table.COIL)


@pytest.mark.asyncio
async def test_a_reply_from_another_unit_is_not_taken() -> None:
    def script(unit: int, function: int, address: int, count: int) -> Answer:
        return [(0.0, registers(unit + 1, function, address, count))]

    async with gateway(script) as peer, scheduling(peer) as read:
        with pytest.raises(ModbusError):
            await read(1, 10)


GARBAGE_MARK = b"garbage"
GARBAGE = [
    b"\x00\x00\x00\x07\x02\x03\x04\x00\x01",  # MBAP with a protocol id that is not 0
    bytes(range(256)),  # noise
    b"\x00\x01\x00\x00\x00\x05\x02\x03\x04",  # truncated: promises more than it brings
    b"\x00\x01\x00\x00\x00\x03\x02\x83\x63",  # an exception code nobody knows
    b"\x00\x01\x00\x00\x00\x03\x02\x63\x01",  # a function code nobody knows
]


@pytest.mark.asyncio
@pytest.mark.parametrize("garbage", GARBAGE, ids=range(len(GARBAGE)))
async def test_garbage_for_one_unit_spares_the_link_of_the_others(
    garbage: bytes, caplog: pytest.LogCaptureFixture
) -> None:
    def script(unit: int, function: int, address: int, count: int) -> Answer:
        if unit == 2:
            return [(0.0, GARBAGE_MARK)]
        return [(0.0, registers(unit, function, address, count))]

    class Noisy(Gateway):
        def _send(self, writer: asyncio.StreamWriter, tid: int, data: bytes) -> None:
            if data == GARBAGE_MARK:
                writer.write(garbage)
            else:
                super()._send(writer, tid, data)

    peer = Noisy(script, "socket")
    server = await asyncio.start_server(peer.serve, "127.0.0.1", 0)
    peer.port = server.sockets[0].getsockname()[1]
    try:
        with caplog.at_level(logging.DEBUG):
            async with scheduling(peer) as read:
                for _ in range(5):
                    assert await read(1, 10) == (10, 11)
                    with pytest.raises(ModbusError):
                        await read(2, 10)
                assert await read(1, 20) == (20, 21)
    finally:
        server.close()
    assert peer.connections == 1  # the shared link stayed up
    assert "Exception in callback" not in caplog.text
    assert "Fatal error" not in caplog.text
    assert "Traceback" not in caplog.text


# --- item 8: no serial port ends the process ------------------------------------------------


@pytest.mark.asyncio
async def test_a_port_that_refuses_its_settings_is_retried_while_other_buses_poll(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A pty takes 8N1 but refuses parity (termios: EINVAL): like a USB adapter without
    parity support. The bus is logged once with the reason and retried; the TCP bus goes on."""
    sim = simulator((1, "soft_starter"))
    with null_modem() as (_, bridge_end):
        async with serving_tcp(sim) as port:
            loaded = config(
                [
                    tcp_bus(port),
                    {"id": "rs485", "transport": "rtu", "port": bridge_end, "parity": "E",
                     "timeout": 0.2},
                ],
                [
                    {"id": "starter", "bus": "tcp", "unit": 1, "mapping": "soft_starter",
                     "poll": {"fast": 0.2, "slow": 5}},
                    {"id": "drive", "bus": "rs485", "unit": 1, "mapping": "vacon_nx",
                     "poll": {"fast": 0.2, "slow": 5}},
                ],
            )  # fmt: skip
            engine = Engine(loaded)
            with caplog.at_level(logging.WARNING):
                task = asyncio.create_task(engine.run())
                try:
                    starter = engine.devices["starter"]
                    await eventually(lambda: starter.health.requests >= 10, timeout=10)
                    serial = engine.schedulers["rs485"]
                    await eventually(lambda: serial.counters.reopenings >= 2, timeout=10)
                    assert not task.done()
                finally:
                    await cancel(task)
    opens = [r for r in caplog.records if "cannot open" in r.getMessage()]
    assert len(opens) == 1
    assert "Invalid argument" in opens[0].getMessage()
    assert "parity" in opens[0].getMessage()


@pytest.mark.asyncio
async def test_a_missing_port_says_so(caplog: pytest.LogCaptureFixture, tmp_path: Path) -> None:
    missing = tmp_path / "ttyUSB9"
    loaded = config(
        [{"id": "rs485", "transport": "rtu", "port": str(missing), "timeout": 0.2}],
        [{"id": "drive", "bus": "rs485", "unit": 1, "mapping": "vacon_nx"}],
    )
    engine = Engine(loaded)
    with caplog.at_level(logging.WARNING):
        async with running(engine):
            await eventually(lambda: engine.schedulers["rs485"].counters.reopenings >= 1)
    message = next(r.getMessage() for r in caplog.records if "cannot open" in r.getMessage())
    assert "No such file or directory" in message
    assert "plugged in" in message
