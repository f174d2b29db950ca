"""Simulated Modbus devices: a pymodbus 3.16 server built from mappings, quirks switchable.

One ``Simulator`` serves any number of units (each a mapping, its options and its
``Quirks``) on one TCP port or one serial line. It answers like the device the mapping
describes: the function codes it supports, its read limit, refused gaps and reserved
addresses, its FC05 ON word, and at will a fixed exception code, latency, silence, or the
P2's 2-byte byte count. Read-only measurements wander and counters count every ``tick``
seconds (``tick <= 0``: values stay still); written registers keep what was written. A unit
follows its commands (start and stop change its status, a fault reset clears its faults)
and ``raise_fault`` trips it (bridge/core/simulation_behaviour.py).

The register image of each unit is ours (``bridge.core.simulation``); pymodbus' SimDevice
blocks are only the buffers its ``action`` hook fills before each answer. They declare every
address valid (registers 0..65535, bits 0..4095), because pymodbus refuses invalid ones
before calling the hook (simruntime.py:62-66), which would skip latency and quirks:

* reads: the hook checks the request against ``Rules`` and copies the image into the
  block (FC01/FC02 pass the exact bit count through a context variable: pymodbus hands
  the hook the number of 16-bit words, simruntime.py:89-93);
* writes: every write request a live unit receives is appended to ``writes`` (refused ones
  too) and the moment it arrived (``time.monotonic()``, before any latency) to
  ``write_times``, then checked and stored; then each of ``reactions`` (a test's device
  logic: a status register that follows a command register) answers the cells the
  accepted write changes besides its own. FC05 arrives through ``_CoilWord``, which passes
  the raw 16-bit word (pymodbus' own FC05 only knows on/off) and echoes it back;
* dead units and unknown unit ids: the incoming ``trace_pdu`` hook drops the request, so
  nothing is executed and nothing is sent (requesthandler.py:73 handles no empty PDU);
* unit 0 is a device that answers every unit id no other unit has, as many Modbus TCP
  devices and gateways do (pymodbus' SimDevice id 0, simcore.py:36); its writes are
  recorded as unit 0;
* ``two_byte_count``: the outgoing ``trace_packet`` hook rewrites RTU FC03 replies;
* counter faults (``counter_fault``, ``schedule``): the next reads of a counter answer
  what ``bridge/core/simulation_counter.py`` says instead of the image.

A ``SunSpecUnit`` (bridge/modbus/sunspec_unit.py) serves a SunSpec device image beside
the mapping units: FC03 within the image, 02 outside it.

One module, about 530 lines, on purpose: it is the one place that reaches into pymodbus'
server (its hooks, its SimDevice, its context variable), and every part of it is one of
those hooks or what they call; the decisions themselves are in bridge/core.
"""

from __future__ import annotations

import asyncio
import random
import time
from collections import deque
from collections.abc import Callable, Sequence
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any, Literal, cast

from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.framer import FramerRTU, FramerType
from pymodbus.pdu import ExceptionResponse, ModbusPDU
from pymodbus.pdu.bit_message import ReadCoilsRequest, ReadDiscreteInputsRequest
from pymodbus.server import ModbusBaseServer, ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from bridge.core.address import to_wire
from bridge.core.codec import Value, decode
from bridge.core.entity import Table
from bridge.core.mapping import Mapping, Point
from bridge.core.request import Read, Write
from bridge.core.simulation import (
    Cell,
    Mover,
    Quirks,
    advance,
    build_movers,
    build_rules,
    count_once,
    initial_image,
    stored_cells,
    words_for,
)
from bridge.core.simulation_behaviour import (
    active_faults,
    build_behaviour,
    clear_faults,
    follow,
    is_running,
    raise_fault,
    start_image,
)
from bridge.core.simulation_counter import (
    CounterFault,
    check_counter,
    counter_fault,
    fault_image,
    fault_reads,
)
from bridge.modbus.frame import CoilWordRequest
from bridge.modbus.sunspec_unit import AfterRead, ImageDevice, SunSpecUnit
from bridge.sunspec.image import DeviceImage

__all__ = ["Quirks", "SimulatedUnit", "Simulator", "SunSpecUnit", "two_byte_count_frame"]

_TABLES = {1: Table.COIL, 5: Table.COIL, 15: Table.COIL, 2: Table.DISCRETE, 4: Table.INPUT}
_BIT_SPACE = 4096  # coils/discrete inputs 0..4095 exist; above, pymodbus answers 02 itself
REQUESTS_KEPT = 10_000  # the latest requests a simulator lists (``Simulator.requests``)
Request = tuple[int, int, int]  # unit, function code, address
_BIT_COUNT: ContextVar[int] = ContextVar("bit_count", default=1)


@dataclass(frozen=True, slots=True)
class SimulatedUnit:
    """One device on the simulated bus."""

    unit: int
    mapping: Mapping
    options: dict[str, str] = field(default_factory=dict)
    quirks: Quirks = field(default_factory=Quirks)


class _CoilWord(CoilWordRequest):
    """FC05 on the server side: the raw word goes to the hook, the reply echoes it."""

    async def datastore_update(self, context: ModbusServerContext, device_id: int) -> ModbusPDU:
        word = self.registers[0]
        code = await context.async_setValues(device_id, 5, self.address, [word])
        if code:
            return ExceptionResponse(5, code)
        return _CoilWord(
            dev_id=device_id,
            transaction_id=self.transaction_id,
            address=self.address,
            registers=[word],
        )


class _ReadCoils(ReadCoilsRequest):
    async def datastore_update(self, context: ModbusServerContext, device_id: int) -> ModbusPDU:
        _BIT_COUNT.set(self.count)
        return await super().datastore_update(context, device_id)


class _ReadDiscrete(ReadDiscreteInputsRequest):
    async def datastore_update(self, context: ModbusServerContext, device_id: int) -> ModbusPDU:
        _BIT_COUNT.set(self.count)
        return await super().datastore_update(context, device_id)


def two_byte_count_frame(frame: bytes) -> bytes:
    """An RTU FC03 reply as the P2 sends it with F9.05 = 0: ``00`` before the byte count."""
    body = frame[:2] + b"\x00" + frame[2:-2]
    return body + FramerRTU.compute_CRC(body).to_bytes(2, "big")


class _Device:
    """One simulated unit: its image, its rules, and the pymodbus hook that applies them."""

    def __init__(
        self,
        spec: SimulatedUnit,
        record: Callable[[int, Write, float], None],
        react: Callable[[int, Write], dict[Cell, int]],
        read_log: int,
    ) -> None:
        self.unit = spec.unit
        self.mapping = spec.mapping
        self.points = spec.mapping.points(spec.options)
        self.image = initial_image(spec.mapping, self.points)
        self.movers = build_movers(self.points, self.image)
        self.behaviour = build_behaviour(spec.mapping, self.points, self.image)
        self.image |= start_image(self.behaviour, self.image)
        self.quirks = spec.quirks
        self.rules = build_rules(spec.mapping, self.points, spec.quirks)
        self.record = record
        self.react = react
        self.reads: deque[tuple[Read, float]] = deque(maxlen=read_log)  # answered, with when
        self.unlocked = False  # Quirks.password: the right password was written
        self.misreads: list[dict[Cell, int]] = []  # answers the next reads get (counter faults)
        self.requests: deque[Request] = deque(maxlen=REQUESTS_KEPT)  # the simulator's, shared

    def set_quirks(self, quirks: Quirks) -> None:
        _check_quirks(quirks)
        self.rules = build_rules(self.mapping, self.points, quirks)
        self.quirks = quirks
        self.unlocked = False  # a password quirk locks the unit (again)

    def point(self, key: str) -> Point:
        try:
            return self.points[key]
        except KeyError:
            raise KeyError(f"unit {self.unit} has no entity {key!r}") from None

    def sim_device(self) -> SimDevice:
        def words() -> list[SimData]:
            return [SimData(0, count=0x10000, values=0, datatype=DataType.REGISTERS)]

        def bits() -> list[SimData]:
            return [SimData(0, values=[False] * _BIT_SPACE, datatype=DataType.BITS)]

        return SimDevice(self.unit, simdata=(bits(), bits(), words(), words()), action=self.action)

    async def action(  # noqa: PLR0917 - the signature of pymodbus' SimAction
        self,
        function_code: int,
        start: int,
        address: int,
        count: int,
        registers: list[int],
        values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """pymodbus' hook, called before every answer (simdevice.py:91-115)."""
        received = time.monotonic()
        table = _TABLES.get(function_code, Table.HOLDING)
        if values is None and function_code in (5, 6, 15, 16):
            self._fill(table, start, address, count, registers)  # the echo after FC06
            return None
        self.requests.append((self.unit, function_code, address))
        delay = self.quirks.latency + (self.quirks.write_latency if values is not None else 0)
        if delay > 0:
            await asyncio.sleep(delay)
        locked = self._locked(function_code, address, values)
        if values is None:
            size = _BIT_COUNT.get() if table.is_bits else count
            code = (
                locked
                or self._refusal(function_code)
                or self.rules.check_read(table, address, size)
            )
            if code is None:
                self._fill(table, start, address, count, registers)
                self._count_on_read(table, address, count)
                self.reads.append((Read(table, address, size), received))
        else:
            write = Write(function_code, table, address, tuple(int(v) for v in values))
            self.record(self.unit, write, received)
            code = locked or self._refusal(function_code) or self.rules.check_write(write)
            if code is None:
                if not (table is Table.COIL and address in self.rules.commands):
                    self.image |= stored_cells(write)
                    self._take_password(write)
                self.image |= self.rules.toggled(write, self.image)
                self.image |= self.rules.echoed(write)
                self.image |= follow(self.behaviour, write, self.image)  # start, stop, reset
                self.image |= self.react(self.unit, write)
        return None if code is None else ExcCodes(code)

    def moving(self) -> tuple[Mover, ...]:
        """The values that move now: a stopped machine's output stays at 0."""
        if is_running(self.behaviour, self.image):
            return self.movers
        still = {point.key for point in self.behaviour.motion}
        return tuple(mover for mover in self.movers if mover.point.key not in still)

    def _count_on_read(self, table: Table, address: int, count: int) -> None:
        """``Quirks.count_on_read``: the counters count once this read is answered."""
        watched = self.quirks.count_on_read
        if (
            watched is None
            or table is not Table.HOLDING
            or not address <= watched < address + count
        ):
            return
        self.image |= count_once(self.movers, self.image)

    def _locked(self, function_code: int, address: int, values: object) -> int | None:
        """``Quirks.password``: the exception a locked unit answers (its protocol's
        ``locked`` code to everything; ``wrong_password`` to a wrong password write), or
        None when the request is served."""
        unlock = self.mapping.protocol.unlock
        if self.quirks.password is None or self.unlocked or unlock is None:
            return None
        locked = next(
            (c for c, m in self.mapping.protocol.exceptions.items() if m.action == "locked"), 7
        )
        wire = to_wire(unlock.address, self.mapping.protocol.addressing)
        if function_code != 6 or address != wire or not isinstance(values, list):
            return locked
        return None if values == [self.quirks.password] else unlock.wrong_password

    def _take_password(self, write: Write) -> None:
        """A right password unlocks; the unlock register then holds the success code (the
        write's echo)."""
        unlock = self.mapping.protocol.unlock
        if self.quirks.password is None or self.unlocked or unlock is None:
            return
        self.unlocked = True
        if unlock.success is not None:
            self.image[(Table.HOLDING, write.address)] = unlock.success

    def _misread(self, table: Table, address: int, count: int) -> dict[Cell, int]:
        """What the next counter fault answers for the cells this read covers (a device
        that reads one register per request meets a two-word misread in two reads)."""
        if not self.misreads:
            return {}
        pending = self.misreads[0]
        covered = {
            c: v for c, v in pending.items() if c[0] is table and address <= c[1] < address + count
        }
        for cell in covered:
            del pending[cell]
        if not pending:
            self.misreads.pop(0)
        return covered

    def _refusal(self, function_code: int) -> int | None:
        """The exception any request gets from this unit now: its quirk, or 01."""
        if self.quirks.exception_code is not None:
            return self.quirks.exception_code
        return None if function_code in self.rules.function_codes else 1

    def _fill(self, table: Table, start: int, address: int, count: int, block: list[int]) -> None:
        """Copy the image into pymodbus' block (bit tables: ``count`` 16-bit words)."""
        if not table.is_bits:
            misread = self._misread(table, address, count)
            for a in range(address, address + count):
                block[a - start] = misread.get((table, a), self.image.get((table, a), 0))
            return
        for word in range(address // 16, address // 16 + count):
            bits = (self.image.get((table, word * 16 + b), 0) << b for b in range(16))
            block[word - start] = sum(bits)


def _check_quirks(quirks: Quirks) -> None:
    if quirks.exception_code is not None and quirks.exception_code not in set(ExcCodes):
        codes = ", ".join(str(int(code)) for code in ExcCodes)
        raise ValueError(f"exception_code {quirks.exception_code}: pymodbus can send {codes}")


class Simulator:
    """Simulated units on one bus (TCP port or serial line). ``writes`` lists every write
    request a live unit received, in order, as ``(unit, Write)``: refused ones included;
    ``write_times[i]`` is when ``writes[i]`` arrived (``time.monotonic()``, before the
    unit's latency), for measuring how long a command took to reach the wire. ``requests``
    lists the latest requests live units received, reads and writes, as ``(unit, function
    code, address)``: the order a bus served its devices in. Each of ``reactions``, called
    with ``(unit, Write)`` once a unit stored an accepted write, answers the other cells
    that write changes (``{(Table.HOLDING, 8465): 1}``). With ``read_log``, each unit keeps
    its last that many answered reads with when they arrived (``reads``): what polls are
    counted and timed by. ``SunSpecUnit``s serve device images beside the mapping units."""

    def __init__(
        self,
        units: Sequence[SimulatedUnit | SunSpecUnit],
        *,
        seed: int = 0,
        tick: float = 1.0,
        read_log: int = 0,
    ) -> None:
        self.writes: list[tuple[int, Write]] = []
        self.write_times: list[float] = []
        self.reactions: list[Callable[[int, Write], dict[Cell, int]]] = []
        self.ready = asyncio.Event()
        self._devices = {
            spec.unit: _Device(spec, self._record_write, self._react, read_log)
            for spec in units
            if isinstance(spec, SimulatedUnit)
        }
        self.requests: deque[Request] = deque(maxlen=REQUESTS_KEPT)
        self._images = {
            spec.unit: ImageDevice(spec, self.requests)
            for spec in units
            if isinstance(spec, SunSpecUnit)
        }
        for device in self._devices.values():
            device.requests = self.requests
        self._rng = random.Random(seed)  # noqa: S311 - simulated readings, not secrets
        self._tick = tick
        self._port: int | None = None
        self._moving = False
        self._scheduled: list[tuple[float, list[tuple[int, str, str]]]] = []
        if len(self._devices.keys() | self._images.keys()) != len(units):
            raise ValueError("unit ids must be unique")
        for spec in units:
            if not 0 <= spec.unit <= 255:
                raise ValueError(f"unit {spec.unit} is outside 0..255 (0: any unit id)")
            if isinstance(spec, SimulatedUnit):
                _check_quirks(spec.quirks)

    @property
    def port(self) -> int:
        """The TCP port bound by ``serve_tcp`` (useful with port 0); wait for ``ready``."""
        if self._port is None:
            raise RuntimeError("the simulator is not serving TCP yet")
        return self._port

    # --- test and CLI access ------------------------------------------------------------

    def set_quirks(self, unit: int, quirks: Quirks) -> None:
        """The unit's quirks from now on (a SunSpec unit takes ``dead`` only)."""
        if unit in self._images:
            self._images[unit].quirks = Quirks(dead=quirks.dead)
            return
        self._device(unit).set_quirks(quirks)

    def swap_image(self, unit: int, image: DeviceImage) -> None:
        """A SunSpec unit serves another image from now on (a firmware update)."""
        self._image_device(unit).swap(image)

    def image(self, unit: int) -> dict[Cell, int]:
        return dict(self._device(unit).image)

    def reads(self, unit: int) -> list[tuple[Read, float]]:
        """The reads the unit answered (the last ``read_log``), each with when it arrived
        (``time.monotonic()``): what a test or bench counts polls by."""
        return list(self._device(unit).reads)

    def value(self, unit: int, key: str) -> Value:
        device = self._device(unit)
        return decode(device.point(key), device.image)

    def set_value(self, unit: int, key: str, value: object) -> None:
        """Store ``value`` as the device would report it (ValueRejectedError if it cannot)."""
        device = self._device(unit)
        device.image |= words_for(device.point(key), value, device.image)

    def raise_fault(self, unit: int, key: str, label: str | None = None) -> None:
        """Trip the unit: the alarm ``key`` on (a fault code's ``label``), and unless it is a
        warning the device stops (bridge/core/simulation_behaviour.py); ValueRejectedError
        for a key that is no alarm of the unit."""
        device = self._device(unit)
        device.image |= raise_fault(device.behaviour, key, label, device.image)

    def clear_faults(self, unit: int) -> None:
        """Every alarm of the unit back to normal, as a fault reset does."""
        device = self._device(unit)
        device.image |= clear_faults(device.behaviour, device.image)

    def counter_fault(self, unit: int, key: str, fault: str) -> None:
        """Make counter ``key`` misread (bridge/core/simulation_counter.py): ``zero``,
        ``reboot``, ``tear`` and ``jitter`` change what the next reads answer, ``wrap``
        and ``reset`` the count itself; ValueRejectedError for a key that is no counter."""
        device = self._device(unit)
        point = device.point(key)
        kind = self.check_counter_fault(unit, key, fault)
        device.misreads.extend(fault_reads(point, kind, device.image))
        device.image |= fault_image(point, kind, device.image)

    def check_counter_fault(self, unit: int, key: str, fault: str) -> CounterFault:
        """The fault ``counter_fault`` would make (ValueRejectedError when it cannot)."""
        point = self._device(unit).point(key)
        check_counter(point)
        kind = counter_fault(fault)
        fault_reads(point, kind, self._device(unit).image)  # refuses a tear of one register
        return kind

    def schedule(self, seconds: float, faults: list[tuple[int, str, str]]) -> None:
        """``counter_fault(unit, key, fault)`` for each of ``faults``, ``seconds`` after
        the simulator starts serving."""
        self._scheduled.append((seconds, faults))

    def faults(self, unit: int) -> list[str]:
        """The unit's active alarms (keys)."""
        device = self._device(unit)
        return active_faults(device.behaviour, device.image)

    def _record_write(self, unit: int, write: Write, received: float) -> None:
        self.writes.append((unit, write))
        self.write_times.append(received)

    def _react(self, unit: int, write: Write) -> dict[Cell, int]:
        changed: dict[Cell, int] = {}
        for reaction in self.reactions:
            changed |= reaction(unit, write)
        return changed

    def set_registers(self, unit: int, values: dict[int, int]) -> None:
        """Store holding registers ``{address: word}`` of the SunSpec unit ``unit``."""
        self._image_device(unit).set_registers(values)

    def after_read(self, unit: int, hook: AfterRead) -> None:
        """Once the SunSpec unit ``unit`` answered a read, ``hook(address, count)`` gives the
        registers ``{address: word}`` that change before its next request (a device whose
        values move between two requests of one poll)."""
        self._image_device(unit).after_read.append(hook)

    def _image_device(self, unit: int) -> ImageDevice:
        try:
            return self._images[unit]
        except KeyError:
            raise KeyError(f"unit {unit} is not a SunSpec unit") from None

    def _device(self, unit: int) -> _Device:
        try:
            return self._devices[unit]
        except KeyError:
            raise KeyError(f"no simulated unit {unit}") from None

    # --- serving ----------------------------------------------------------------------------

    async def serve_tcp(
        self, host: str, port: int, framer: Literal["socket", "rtu"] = "socket"
    ) -> None:
        """Serve Modbus TCP (``socket``) or RTU over TCP until cancelled."""
        server = ModbusTcpServer(
            self._sim_devices(),
            framer=FramerType(framer),
            address=(host, port),
            **self._hooks(framer),
        )
        await self._serve(server, f"{host}:{port}")

    async def serve_serial(
        self,
        port: str,
        *,
        baudrate: int = 9600,
        parity: str = "N",
        stopbits: int = 1,
        bytesize: int = 8,
        framer: Literal["rtu", "ascii"] = "rtu",
    ) -> None:
        """Serve a serial line (RTU or ASCII) until cancelled."""
        server = ModbusSerialServer(
            self._sim_devices(),
            framer=FramerType(framer),
            port=port,
            baudrate=baudrate,
            parity=parity,
            stopbits=stopbits,
            bytesize=bytesize,
            **self._hooks(framer),
        )
        await self._serve(server, port)

    def _answering(self, unit: int) -> _Device | ImageDevice | None:
        """The simulated device that takes a request to ``unit``: its own, else unit 0."""
        return next(
            (d for d in (self._devices.get(unit), self._images.get(unit)) if d is not None),
            self._devices.get(0) or self._images.get(0),
        )

    def _sim_devices(self) -> list[SimDevice]:
        images = [device.sim_device() for device in self._images.values()]
        return [device.sim_device() for device in self._devices.values()] + images

    def _hooks(self, framer: str) -> dict[str, Any]:
        def trace_pdu(sending: bool, pdu: ModbusPDU) -> ModbusPDU | None:
            device = self._answering(pdu.dev_id)
            if sending or (device is not None and not device.quirks.dead):
                return pdu
            return None  # dropped: transaction.py:273 keeps None, nothing is answered

        def trace_packet(sending: bool, packet: bytes) -> bytes:
            if not sending or framer != "rtu" or len(packet) < 5 or packet[1] != 3:
                return packet
            device = self._answering(packet[0])
            if device is None or not device.quirks.two_byte_count:
                return packet
            return two_byte_count_frame(packet)

        return {
            "custom_pdu": [_CoilWord, _ReadCoils, _ReadDiscrete],
            "trace_pdu": cast(Callable[[bool, ModbusPDU], ModbusPDU], trace_pdu),
            "trace_packet": trace_packet,
        }

    async def _serve(self, server: ModbusBaseServer, where: str) -> None:
        try:
            await server.serve_forever(background=True)
        except RuntimeError:
            await server.shutdown()  # type: ignore[no-untyped-call]
            raise OSError(f"the simulator cannot listen on {where}") from None
        sockets = getattr(server.transport, "sockets", None) or ()
        for sock in sockets:
            self._port = int(sock.getsockname()[1])
        self.ready.set()
        try:
            async with asyncio.TaskGroup() as group:
                if self._tick > 0 and not self._moving:
                    group.create_task(self._move())
                for seconds, faults in self._scheduled:
                    group.create_task(self._fault_later(seconds, faults))
                self._scheduled = []
                await server.serving
        finally:
            self.ready.clear()
            await server.shutdown()  # type: ignore[no-untyped-call]

    async def _fault_later(self, seconds: float, faults: list[tuple[int, str, str]]) -> None:
        await asyncio.sleep(seconds)
        for unit, key, fault in faults:
            self.counter_fault(unit, key, fault)

    async def _move(self) -> None:
        self._moving = True
        try:
            while True:
                await asyncio.sleep(self._tick)
                for device in list(self._devices.values()):
                    moving = device.moving()
                    device.image |= advance(moving, device.image, self._rng, self._tick)
                    await asyncio.sleep(0)  # a request waits for one device's tick, not all
        finally:
            self._moving = False
