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

Every reply is checked against its request: pymodbus skips frames of another unit (the
request then times out); a reply with another function code, or another byte count than
the count asked for, is a FrameError, never values. Bytes that arrive while no request is
outstanding are stamped (``unsolicited``, ``unsolicited_at``) so the scheduler can keep
the line quiet (pymodbus drops them).

A port that cannot be opened or configured (missing, no permission, held by another
program, line settings the adapter refuses: ``termios.error`` EINVAL for a parity it
does not support) is a BusError naming the operating system's reason and what to do, so
the scheduler retries it like any bus that is down; it never ends the bridge.
"""

from __future__ import annotations

import asyncio
import errno
import grp
import logging
import os
import re
import stat
import time
from collections.abc import Callable

from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.framer import FramerRTU, FramerType
from pymodbus.pdu import DecodePDU, ExceptionResponse
from serial import Serial, SerialException

from bridge.config import SerialBus, TcpBus
from bridge.core.health import exception_meaning
from bridge.core.protocol import Protocol
from bridge.core.request import Read, Write
from bridge.errors import BusError, DeviceExceptionError, DeviceTimeoutError, FrameError
from bridge.modbus.frame import CLIENT_RESPONSES, request_pdu, response_values

try:  # a port that refuses its line settings raises termios.error, not OSError
    import termios

    _TERMIOS: tuple[type[Exception], ...] = (termios.error,)
except ImportError:  # pragma: no cover - not a POSIX system
    _TERMIOS = ()

_NEVER_DISCONNECT = 1 << 30
_OPEN_ERRORS: tuple[type[Exception], ...] = (OSError, ModbusException, ValueError, *_TERMIOS)
_HINTS = {
    errno.ENOENT: "is the adapter plugged in? see ls -l /dev/serial/by-id/",
    errno.ENODEV: "is the adapter plugged in? see ls -l /dev/serial/by-id/",
    errno.ENXIO: "is the adapter plugged in? see ls -l /dev/serial/by-id/",
    errno.EACCES: "add the user to the dialout group (in a container: --group-add dialout)",
    errno.EPERM: "add the user to the dialout group (in a container: --group-add dialout)",
    errno.EBUSY: "another program holds the port; stop it (ModemManager, a second bridge)",
    # pyserial's exclusive lock (flock), which pymodbus asks for: one process per adapter
    errno.EAGAIN: "another program holds the port; stop it (a second bridge, mbpoll, a "
    "vendor tool): one master per RS485 line",
    errno.EINVAL: "the port refuses these line settings: check the adapter supports the "
    "bus's baudrate, parity, stop bits and byte size",
}
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
        self._in_flight = False
        self.unsolicited = 0  # chunks of bytes received while no request was outstanding
        self.unsolicited_at = float("-inf")  # when the last of them arrived (monotonic)

    @property
    def connected(self) -> bool:
        return self._client is not None and self._client.connected

    async def open(self) -> None:
        """Connect (or reconnect); BusError when the port or gateway cannot be reached."""
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # the bridge logs outcomes
        if self._client is None:
            self._client = _client_for(self.bus, self._traced)
            if isinstance(self._client.ctx.framer, FramerRTU):
                self._client.ctx.framer = _CheckedRTU(DecodePDU(False))
            for custom in CLIENT_RESPONSES:
                self._client.register(custom)
            self._client.set_max_no_responses(_NEVER_DISCONNECT)
        try:
            connected = await self._client.connect()
        except _OPEN_ERRORS as exc:
            self.close()
            reason = await asyncio.to_thread(_why, self.bus, exc)
            raise BusError(f"{self.bus.id}: cannot open {_where(self.bus)}: {reason}") from None
        _restore_lost_cancel()
        if not connected:
            self.close()
            reason = await asyncio.to_thread(_why, self.bus, None)
            raise BusError(f"{self.bus.id}: cannot open {_where(self.bus)}: {reason}")

    def _traced(self, sending: bool, data: bytes) -> bytes:
        """pymodbus' packet hook: stamps bytes that arrive while no request is out."""
        if not sending and not self._in_flight:
            self.unsolicited += 1
            self.unsolicited_at = time.monotonic()
        return data

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
        self._in_flight = True
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
        finally:
            self._in_flight = False
        if response.function_code & 0x7F != pdu.function_code:
            raise FrameError(
                f"unit {unit} answered function {response.function_code & 0x7F} "
                f"to a function {pdu.function_code} request"
            )
        if isinstance(response, ExceptionResponse):
            code = int(response.exception_code)
            meaning = exception_meaning(code, STANDARD)  # the scheduler applies the device's
            raise DeviceExceptionError(code, meaning.name, meaning.action)
        if isinstance(request, Write):  # the echo of a single-register write: some devices
            return tuple(response.registers) if request.function == 6 else ()  # answer a code
        return response_values(response, request)


_Trace = Callable[[bool, bytes], bytes]


def _why(bus: SerialBus | TcpBus, raised: BaseException | None) -> str:
    """The operating system's reason a port cannot be opened, and what to do about it.
    Opens the serial port the way pymodbus does (blocking: run it in a thread)."""
    if isinstance(bus, TcpBus):
        return _said(raised) if raised is not None else "no connection (refused or no answer)"
    error = raised
    if error is None or not _errno(error):
        try:
            handle = Serial(
                bus.port, bus.baudrate, bus.bytesize, bus.parity, bus.stopbits, exclusive=True
            )
            handle.close()
        except (*_OPEN_ERRORS, SerialException) as probe:
            error = probe
    if error is None:
        return "the port opened on a second try; it may come and go"
    code = _errno(error)
    hint = _HINTS.get(code) if code is not None else None
    if code in (errno.EACCES, errno.EPERM):
        hint = _permission_hint(bus.port) or hint
    return _said(error) + (f" ({hint})" if hint else "")


def _permission_hint(port: str) -> str | None:
    """What to do about a port this process may not open: which group owns it and how to
    join that group, on the host or in a container (where the host's group id counts)."""
    try:
        status = os.stat(port)
    except OSError:
        return None
    try:
        name = f" ({grp.getgrgid(status.st_gid).gr_name})"
    except KeyError:  # a host group this system (the container) does not know by name
        name = ""
    return permission_hint(
        status.st_gid, name, status.st_mode, os.getuid(), {os.getgid(), *os.getgroups()}
    )


def permission_hint(gid: int, name: str, mode: int, uid: int, groups: set[int]) -> str:
    """The advice for a port owned by group ``gid`` (`` (dialout)`` as ``name``) with
    permission bits ``mode``, refused to ``uid`` in ``groups``."""
    group_rw = stat.S_IRGRP | stat.S_IWGRP
    if gid in groups and mode & group_rw != group_rw:
        return (
            f"the port's group {gid}{name} may not read and write it (mode "
            f"{stat.filemode(mode)}): a udev rule should make it 0660"
        )
    if gid in groups:
        return f"uid {uid} is in the port's group {gid}{name}: check the mode and owner"
    return (
        f"the port belongs to group {gid}{name} and uid {uid} is not in it: add the user to "
        f"that group; in a container pass the host's group id: --group-add {gid} "
        f"(compose: group_add: ['{gid}'])"
    )


def _errno(error: BaseException) -> int | None:
    """The errno an error carries (OSError, termios.error's first argument, a
    SerialException's 'could not open port ...: [Errno 2] ...')."""
    if isinstance(error, OSError) and error.errno:
        return error.errno
    if error.args and isinstance(error.args[0], int):
        return error.args[0]
    found = re.search(r"\[Errno (\d+)\]", str(error))
    return int(found.group(1)) if found else None


def _said(error: BaseException) -> str:
    code = _errno(error)
    if code is not None:
        return f"{os.strerror(code)} [{errno.errorcode.get(code, code)}]"
    return str(error) or type(error).__name__


def _restore_lost_cancel() -> None:
    """Raise the cancellation that 3.11's ``asyncio.wait_for`` (inside pymodbus) swallowed
    when the answer and the cancel arrived together."""
    task = asyncio.current_task()
    if task is not None and task.cancelling():
        raise asyncio.CancelledError


def _client_for(bus: SerialBus | TcpBus, trace: _Trace) -> Client:
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
            trace_packet=trace,
        )
    return AsyncModbusTcpClient(
        bus.host,
        port=bus.tcp_port,
        framer=FramerType.RTU if bus.transport == "rtu-over-tcp" else FramerType.SOCKET,
        timeout=bus.timeout,
        retries=0,
        reconnect_delay=0,
        trace_packet=trace,
    )


def _where(bus: SerialBus | TcpBus) -> str:
    return bus.port if isinstance(bus, SerialBus) else f"{bus.host}:{bus.tcp_port}"
