"""Commissioning one bus: find the units on it, read and write raw registers.

The helpers take a ``Submit`` (unit, request, timeout -> values) so they work the same
standalone, on a bus of their own (``open_bus``), and inside the running bridge through
that bus's scheduler (``scheduler_submit``), where they queue like any command and keep
the one-frame-in-flight rule and the inter-frame gap:

    async with open_bus(parse_bus_spec("tcp://10.0.0.7")) as submit:
        found = await scan(submit, range(1, 248), timeout=0.2)
        reading = await read_interpreted(submit, 3, raw_read("holding", 0x97, 2), 1.0)
        await submit(3, raw_write("holding", 0x97, [100]), 1.0)

A unit is present when anything answers: values, a Modbus exception (an illegal address
still proves the unit is there), or a garbled frame (reported as such, never hidden). A
timeout means absent. ``raw_read``/``raw_write`` check the request against the protocol
limits (125 registers or 2000 bits per read, 123 registers or 1968 coils per write,
addresses 0..65535, register values 0..65535, coils 0/1) and raise ValueRejectedError
before anything is sent. Addresses are wire addresses (0-based).
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from bridge.config import SerialBus, TcpBus
from bridge.core.entity import Table
from bridge.core.interpret import interpret, interpret_bits
from bridge.core.request import Read, Write, split_read
from bridge.errors import (
    DeviceExceptionError,
    DeviceTimeoutError,
    FrameError,
    ModbusError,
    ValueRejectedError,
)
from bridge.modbus.engine import bus_scheduler
from bridge.modbus.scheduler import BusScheduler, Priority

Submit = Callable[[int, Read | Write, float], Awaitable[tuple[int, ...]]]
"""One transaction: (unit, request, timeout) -> values read (empty for a write); raises
DeviceTimeoutError, DeviceExceptionError, FrameError or BusError."""

MAX_READ_REGISTERS = 125
MAX_READ_BITS = 2000
MAX_WRITE_REGISTERS = 123
MAX_WRITE_COILS = 1968
COIL_ON = 0xFF00
PROBE = Read(Table.HOLDING, 0, 1)
UNITS = range(1, 256)  # 0 is broadcast: nobody answers it


class Answer(StrEnum):
    """What a probed unit answered."""

    VALUES = "values"
    EXCEPTION = "exception"
    GARBLED = "garbled"


@dataclass(frozen=True, slots=True)
class Found:
    """A unit that answered a probe; ``latency`` in seconds (queueing included)."""

    unit: int
    answer: Answer
    latency: float
    values: tuple[int, ...] = ()
    exception_code: int | None = None
    detail: str = ""  # the exception's meaning, or what was wrong with the frame

    def describe(self) -> str:
        """One line for people: ``values 0x0064``, ``exception 2 (illegal data address)``."""
        if self.answer is Answer.VALUES:
            return "values " + " ".join(f"0x{value:04X}" for value in self.values)
        if self.answer is Answer.EXCEPTION:
            return f"exception {self.exception_code} ({self.detail})"
        return f"garbled answer: {self.detail}"

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "unit": self.unit,
            "answer": self.answer.value,
            "latency_ms": round(self.latency * 1000, 1),
            "values": list(self.values),
            "exception": self.exception_code,
            "detail": self.detail,
        }


async def probe(submit: Submit, unit: int, timeout: float, request: Read = PROBE) -> Found | None:
    """Whether ``unit`` answers ``request`` within ``timeout``: what it said, or None.

    BusError (port or gateway gone) propagates: it says nothing about the unit."""
    _check_unit(unit)
    started = time.monotonic()
    try:
        values = await submit(unit, request, timeout)
    except DeviceTimeoutError:
        return None
    except DeviceExceptionError as refused:
        return Found(
            unit,
            Answer.EXCEPTION,
            time.monotonic() - started,
            exception_code=refused.code,
            detail=refused.meaning,
        )
    except FrameError as garbled:
        return Found(unit, Answer.GARBLED, time.monotonic() - started, detail=str(garbled))
    return Found(unit, Answer.VALUES, time.monotonic() - started, values=values)


async def scan(
    submit: Submit,
    units: Iterable[int],
    timeout: float,
    on_progress: Callable[[int, Found | None], None] | None = None,
) -> list[Found]:
    """Probe ``units`` one after the other (one frame in flight on a serial line), so the
    scan takes at most ``len(units) * (timeout + gap)``. ``on_progress`` hears of each unit
    as it is done (a caller that cancels the scan keeps what it heard)."""
    wanted = tuple(units)
    for unit in wanted:
        _check_unit(unit)
    found = []
    for unit in wanted:
        result = await probe(submit, unit, timeout)
        if result is not None:
            found.append(result)
        if on_progress is not None:
            on_progress(unit, result)
    return found


def raw_read(table: Table | str, address: int, count: int = 1) -> Read:
    """A checked read of ``count`` registers or bits from wire ``address``."""
    table = parse_table(table)
    limit = MAX_READ_BITS if table.is_bits else MAX_READ_REGISTERS
    if not 1 <= count <= limit:
        raise ValueRejectedError(f"count {count}: read 1..{limit} {_kind(table)} at a time")
    _check_span(address, count)
    return Read(table, address, count)


def raw_write(
    table: Table | str,
    address: int,
    values: Sequence[int],
    *,
    function: int | None = None,
    coil_on_value: int = COIL_ON,
) -> Write:
    """The write of ``values`` from wire ``address``: FC06/FC05 for one value, FC16/FC15
    for several. ``function`` forces 16 (or 15) for one value, for devices without FC06.
    A coil is written 0/1; FC05 sends ``coil_on_value`` (0xFF00, some devices 0x00FF)."""
    table = parse_table(table)
    if table not in (Table.HOLDING, Table.COIL):
        raise ValueRejectedError(f"the {table.value} table is read-only: write holding or coil")
    single, multiple = (5, 15) if table is Table.COIL else (6, 16)
    chosen = function or (single if len(values) == 1 else multiple)
    if chosen not in (single, multiple):
        raise ValueRejectedError(f"FC{function:02d} does not write {_kind(table)}")
    limit = 1 if chosen == single else MAX_WRITE_COILS if table.is_bits else MAX_WRITE_REGISTERS
    if not 1 <= len(values) <= limit:
        raise ValueRejectedError(
            f"{len(values)} values: FC{chosen:02d} writes 1..{limit} {_kind(table)}"
        )
    _check_span(address, len(values))
    if not 0 < coil_on_value <= 0xFFFF:
        raise ValueRejectedError(f"coil ON word {coil_on_value}: use 0x0001..0xFFFF (0xFF00)")
    checked = tuple(_checked(table, value) for value in values)
    if chosen == 5:
        checked = (coil_on_value if checked[0] else 0x0000,)
    return Write(chosen, table, address, checked)


def parse_table(table: Table | str) -> Table:
    """``holding``, ``input``, ``coil`` or ``discrete`` (ValueRejectedError otherwise)."""
    try:
        return Table(table)
    except ValueError:
        names = ", ".join(t.value for t in Table)
        raise ValueRejectedError(f"table {table!r}: choose {names}") from None


async def read_interpreted(
    submit: Submit, unit: int, request: Read, timeout: float, *, limit: int | None = None
) -> dict[str, Any]:
    """Read and interpret: ``interpret()``'s dict (``interpret_bits()``'s for bit tables)
    with the unit, the table, the number of ``requests`` sent and a ``note`` saying why
    there were several (else None). See ``read_in_parts`` for ``limit``."""
    values, requests, note = await read_in_parts(submit, unit, request, timeout, limit)
    reading = (interpret_bits if request.table.is_bits else interpret)(request.address, values)
    return {"unit": unit, "table": request.table.value, **reading} | {
        "requests": requests,
        "note": note,
    }


async def read_in_parts(
    submit: Submit, unit: int, request: Read, timeout: float, limit: int | None
) -> tuple[tuple[int, ...], int, str | None]:
    """The values of ``request``, the requests it took and why there were several.

    ``limit`` (the device's known read limit, from its mapping and what the bridge
    learnt) splits the read up front. Without one, a read the unit refuses whole
    (exception 2 or 3 on a device that reads one register per request, like the Nastec)
    is read again one register (or bit) at a time: every part answered means the read
    was only too long; a part refused alone is the error, naming its address.
    """
    kind = _kind(request.table)
    if limit is not None and request.count > limit:
        parts = split_read(request, limit)
        each = kind if limit > 1 else kind.removesuffix("s")
        note = f"{len(parts)} requests: the device reads at most {limit} {each} at once"
        return await _read_parts(submit, unit, parts, timeout), len(parts), note
    try:
        return await submit(unit, request, timeout), 1, None
    except DeviceExceptionError as exc:
        if exc.action != "refused" or request.count == 1 or limit is not None:
            raise
    parts = split_read(request, 1)
    note = f"read one at a time: the unit refused {request.count} {kind} at once"
    return await _read_parts(submit, unit, parts, timeout), len(parts), note


async def _read_parts(
    submit: Submit, unit: int, parts: Sequence[Read], timeout: float
) -> tuple[int, ...]:
    values: list[int] = []
    for part in parts:
        try:
            values += await submit(unit, part, timeout)
        except DeviceExceptionError as exc:
            where = f"{part.table.value} {part.address}"
            if part.count > 1:
                where += f"-{part.address + part.count - 1}"
            raise DeviceExceptionError(exc.code, f"{exc.meaning}, at {where}", exc.action) from exc
    return tuple(values)


def explain(unit: int, error: ModbusError) -> str:
    """A failed transaction in a user's words: ``unit 3 refused: exception 2 (illegal
    data address)``, ``unit 3 did not answer within 1 s``."""
    if isinstance(error, DeviceExceptionError):
        verb = {"refused": "refused", "busy": "is busy"}.get(error.action, "failed")
        return f"unit {unit} {verb}: {error}"
    return str(error)  # timeouts and frame errors name the unit; a bus error is the bus's


def scheduler_submit(
    scheduler: BusScheduler, priority: Priority = Priority.READ_NOW, retries: int = 0
) -> Submit:
    """Submit through a running bus scheduler (the bridge's own), ahead of polls."""

    async def submit(unit: int, request: Read | Write, timeout: float) -> tuple[int, ...]:
        return await scheduler.submit(
            unit, request, timeout=timeout, priority=priority, retries=retries
        )

    return submit


@contextlib.asynccontextmanager
async def open_bus(bus: SerialBus | TcpBus) -> AsyncIterator[Submit]:
    """A bus of our own for the block: port or connection opened now (BusError if it
    cannot be), one scheduler serialising the frames, everything closed on exit."""
    async with open_scheduler(bus) as scheduler:
        yield scheduler_submit(scheduler)


@contextlib.asynccontextmanager
async def open_scheduler(bus: SerialBus | TcpBus) -> AsyncIterator[BusScheduler]:
    """``open_bus``'s running scheduler itself (for a poller of its own: a trial poll)."""
    # No silent timeout after a timeout: a scan would pay it for every absent unit.
    scheduler = bus_scheduler(bus, guard_late_replies=False)
    transport = scheduler.transport
    try:
        await transport.open()
        # Not a TaskGroup: it would wrap the block's own errors in an ExceptionGroup. The
        # task lives exactly as long as the block: cancelled and awaited on the way out.
        runner = asyncio.create_task(scheduler.run(), name=f"bus:{bus.id}")
        try:
            yield scheduler
        finally:
            runner.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await runner
    finally:
        transport.close()


def _checked(table: Table, value: int) -> int:
    if table is Table.COIL:
        if value not in (0, 1) or isinstance(value, float):
            raise ValueRejectedError(f"coil value {value!r}: write 0 or 1")
        return int(value)
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= 0xFFFF:
        raise ValueRejectedError(
            f"register value {value!r}: write 0..65535 (0x0000..0xFFFF; -1 is 0xFFFF)"
        )
    return value


def _check_unit(unit: int) -> None:
    if unit not in UNITS:
        raise ValueRejectedError(f"unit {unit}: address units 1..255 (0 is broadcast)")


def _check_span(address: int, count: int) -> None:
    if not 0 <= address <= 0xFFFF:
        raise ValueRejectedError(f"address {address}: wire addresses are 0..65535")
    if address + count - 1 > 0xFFFF:
        raise ValueRejectedError(f"address {address} + {count} values runs past 65535")


def _kind(table: Table) -> str:
    return {Table.COIL: "coils", Table.DISCRETE: "discrete inputs"}.get(table, "registers")
