"""One bus connection on pymodbus' async clients: RTU/ASCII serial, Modbus TCP, RTU over TCP.

``Transport.execute(unit, request, timeout)`` performs one transaction and maps every
pymodbus outcome to the bridge's errors: no answer -> DeviceTimeoutError, an exception
reply -> DeviceExceptionError (standard meaning; the scheduler applies the device's own),
port or socket down -> BusError. pymodbus' own retries are off (the scheduler decides),
and so is its habit of dropping a TCP connection after a few unanswered requests: behind
a gateway one dead unit must not cut off the others. pymodbus drops an RTU reply whose
CRC is wrong without a word and lets the request time out; the transport counts those
drops, so such a transaction ends in FrameError (a frame error on the bus, not a silent
unit). pymodbus waits with Python 3.11's ``asyncio.wait_for``, which loses a cancellation
that arrives together with the answer; the transport raises it again, or a stopping
bridge would keep its bus task (and its TaskGroup) running.
"""

from __future__ import annotations

import asyncio
import logging

from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.framer import FramerRTU, FramerType
from pymodbus.pdu import DecodePDU, ExceptionResponse

from bridge.config import SerialBus, TcpBus
from bridge.core.health import exception_meaning
from bridge.core.protocol import Protocol
from bridge.core.request import Read, Write
from bridge.errors import BusError, DeviceExceptionError, DeviceTimeoutError, FrameError
from bridge.modbus.frame import CLIENT_RESPONSES, request_pdu, response_values

_NEVER_DISCONNECT = 1 << 30
STANDARD = Protocol()  # no device-specific exception meanings
Client = AsyncModbusSerialClient | AsyncModbusTcpClient


class _CheckedRTU(FramerRTU):
    """pymodbus' RTU framer, counting the frames it drops for a wrong CRC."""

    crc_errors = 0

    def decode(self, data: bytes) -> tuple[int, int, int, bytes]:
        used, dev_id, tid, frame = super().decode(data)
        if used and not frame:  # framer/rtu.py consumes data without a frame only then
            self.crc_errors += 1
        return used, dev_id, tid, frame


class Transport:
    """The connection of one bus; one transaction at a time (the scheduler guarantees it)."""

    def __init__(self, bus: SerialBus | TcpBus) -> None:
        self.bus = bus
        self._client: Client | None = None

    @property
    def connected(self) -> bool:
        return self._client is not None and self._client.connected

    async def open(self) -> None:
        """Connect (or reconnect); BusError when the port or gateway cannot be reached."""
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # the bridge logs outcomes
        if self._client is None:
            self._client = _client_for(self.bus)
            if isinstance(self._client.ctx.framer, FramerRTU):
                self._client.ctx.framer = _CheckedRTU(DecodePDU(False))
            for custom in CLIENT_RESPONSES:
                self._client.register(custom)
            self._client.set_max_no_responses(_NEVER_DISCONNECT)
        try:
            connected = await self._client.connect()
        except (OSError, ModbusException) as exc:
            raise BusError(f"{self.bus.id}: cannot open {_where(self.bus)}: {exc}") from None
        _restore_lost_cancel()
        if not connected:
            raise BusError(f"{self.bus.id}: cannot open {_where(self.bus)}")

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    async def execute(self, unit: int, request: Read | Write, timeout: float) -> tuple[int, ...]:
        """One transaction: the values read (empty for a write)."""
        client = self._client
        if client is None or not client.connected:
            raise BusError(f"{self.bus.id}: not connected to {_where(self.bus)}")
        client.ctx.comm_params.timeout_connect = timeout
        pdu = request_pdu(request, unit)
        framer = client.ctx.framer
        crc_errors = framer.crc_errors if isinstance(framer, _CheckedRTU) else 0
        try:
            response = await client.execute(False, pdu)
            _restore_lost_cancel()
        except ConnectionException as exc:
            raise BusError(f"{self.bus.id}: connection lost: {exc}") from None
        except ModbusIOException:
            if isinstance(framer, _CheckedRTU) and framer.crc_errors > crc_errors:
                raise FrameError(f"unit {unit}: the reply had a wrong CRC") from None
            raise DeviceTimeoutError(f"unit {unit} did not answer within {timeout:g} s") from None
        except ModbusException as exc:
            raise FrameError(f"unit {unit}: {exc}") from None
        if isinstance(response, ExceptionResponse):
            code = int(response.exception_code)
            meaning = exception_meaning(code, STANDARD)  # the scheduler applies the device's
            raise DeviceExceptionError(code, meaning.name, meaning.action)
        if isinstance(request, Write):
            return ()
        return response_values(response, request)


def _restore_lost_cancel() -> None:
    """Raise the cancellation that 3.11's ``asyncio.wait_for`` (inside pymodbus) swallowed
    when the answer and the cancel arrived together."""
    task = asyncio.current_task()
    if task is not None and task.cancelling():
        raise asyncio.CancelledError


def _client_for(bus: SerialBus | TcpBus) -> Client:
    if isinstance(bus, SerialBus):
        return AsyncModbusSerialClient(
            bus.port,
            framer=FramerType.ASCII if bus.transport == "ascii" else FramerType.RTU,
            baudrate=bus.baudrate,
            bytesize=bus.bytesize,
            parity=bus.parity,
            stopbits=bus.stopbits,
            timeout=bus.timeout,
            retries=0,
            reconnect_delay=0,
        )
    return AsyncModbusTcpClient(
        bus.host,
        port=bus.tcp_port,
        framer=FramerType.RTU if bus.transport == "rtu-over-tcp" else FramerType.SOCKET,
        timeout=bus.timeout,
        retries=0,
        reconnect_delay=0,
    )


def _where(bus: SerialBus | TcpBus) -> str:
    return bus.port if isinstance(bus, SerialBus) else f"{bus.host}:{bus.tcp_port}"
