"""The gateway's Modbus TCP server: pymodbus' server, each request handed to ``answer``.

``GatewayServer(host, port, answer, limits, book).run()`` listens until cancelled. Every
request a client sends is decoded by pymodbus (MBAP framing, PDUs), turned into a pure
``ProxyRequest`` (bridge/core/gateway.py) and answered by ``answer(peer, request)``: the
values read (or written), or an exception code. Only FC01-06, FC15 and FC16 are decoded;
any other function answers 0x01 before the bridge sees it.

Per connection, at most ``max_queued`` requests wait for their answer; more answer 0x06
at once. At most ``max_clients`` connections are open; one more is closed as soon as it is
accepted. A connection is closed when its bytes cannot start a Modbus TCP frame (a wrong
protocol id or length), and when it sends no complete request for ``idle_timeout``
seconds (a half frame held open). Each request is answered with its own transaction id,
also when a client sends the next before the previous is answered.

pymodbus' own request handler reads the connection's *last* request again after the
datastore answered, so a request sent while another waits would get the other's
transaction id; ``_Connection.handle_request`` keeps each request's own.
"""

from __future__ import annotations

import asyncio
import logging
import struct
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from pymodbus.datastore import ModbusServerContext
from pymodbus.exceptions import ModbusIOException
from pymodbus.pdu import ExceptionResponse, ModbusPDU
from pymodbus.pdu.bit_message import (
    ReadCoilsRequest,
    ReadCoilsResponse,
    ReadDiscreteInputsRequest,
    ReadDiscreteInputsResponse,
    WriteMultipleCoilsRequest,
    WriteMultipleCoilsResponse,
    WriteSingleCoilRequest,
    WriteSingleCoilResponse,
)
from pymodbus.pdu.register_message import (
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    ReadInputRegistersRequest,
    ReadInputRegistersResponse,
    WriteMultipleRegistersRequest,
    WriteMultipleRegistersResponse,
    WriteSingleRegisterRequest,
    WriteSingleRegisterResponse,
)
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.transaction import TransactionManager

from bridge.core.gateway import (
    MBAP_HEADER,
    ClientBook,
    ClientCounters,
    Code,
    ProxyRequest,
    header_problem,
)
from bridge.errors import BusError

log = logging.getLogger(__name__)

Answer = Callable[[ClientCounters, ProxyRequest], Awaitable[tuple[int, ...] | int]]
"""(the client's counters, its request) -> the values (a write: those written), or an
exception code; never raises for a request."""


@dataclass(frozen=True, slots=True)
class Limits:
    max_clients: int = 8
    max_queued: int = 4
    idle_timeout: float = 120.0


class _CoilWord(WriteSingleCoilRequest):
    """FC05 keeping the word sent: only 0xFF00 (on) and 0x0000 (off) are coil values."""

    word = 0

    def decode(self, data: bytes) -> None:
        self.address, self.word = struct.unpack(">HH", data[:4])
        self.bits = [self.word == 0xFF00]


_DECODED: dict[int, type[ModbusPDU]] = {
    1: ReadCoilsRequest,
    2: ReadDiscreteInputsRequest,
    3: ReadHoldingRegistersRequest,
    4: ReadInputRegistersRequest,
    5: _CoilWord,
    6: WriteSingleRegisterRequest,
    15: WriteMultipleCoilsRequest,
    16: WriteMultipleRegistersRequest,
}


class _Context(ModbusServerContext):
    """pymodbus' server wants a context; every request is answered by ``answer``."""

    def __init__(self) -> None:  # no datastore: nothing is served from here
        self.old_simulator = True
        self.simdevices = []
        self._devices = {}


def request_of(pdu: ModbusPDU) -> ProxyRequest | int:
    """The request a decoded PDU asks, or 0x03 when its byte counts do not add up."""
    function, unit, address = pdu.function_code, pdu.dev_id, pdu.address
    if function in (1, 2, 3, 4):
        return ProxyRequest(unit, function, address, pdu.count)
    if function == 5:
        word = getattr(pdu, "word", 0)
        if word not in (0x0000, 0xFF00):
            return Code.ILLEGAL_VALUE
        return ProxyRequest(unit, 5, address, 1, (1 if word else 0,))
    if function == 6:
        return ProxyRequest(unit, 6, address, 1, (pdu.registers[0],))
    if isinstance(pdu, WriteMultipleCoilsRequest):
        count = pdu.count
        if pdu.byte_count != (count + 7) // 8 or pdu.data_byte_count != pdu.byte_count:
            return Code.ILLEGAL_VALUE
        return ProxyRequest(unit, 15, address, count, tuple(int(b) for b in pdu.bits[:count]))
    if not isinstance(pdu, WriteMultipleRegistersRequest):  # pragma: no cover - _DECODED
        return Code.ILLEGAL_FUNCTION
    count = pdu.count
    payload = getattr(pdu, "_payload_byte_count", None)
    if pdu.byte_count != 2 * count or payload != pdu.byte_count:
        return Code.ILLEGAL_VALUE
    return ProxyRequest(unit, 16, address, count, tuple(pdu.registers))


def response_of(request: ProxyRequest, values: tuple[int, ...]) -> ModbusPDU:
    """The reply to a served request."""
    function, address = request.function, request.address
    if function == 1:
        return ReadCoilsResponse(bits=[bool(v) for v in values])
    if function == 2:
        return ReadDiscreteInputsResponse(bits=[bool(v) for v in values])
    if function == 3:
        return ReadHoldingRegistersResponse(registers=list(values))
    if function == 4:
        return ReadInputRegistersResponse(registers=list(values))
    if function == 5:
        return WriteSingleCoilResponse(address=address, bits=[bool(request.values[0])])
    if function == 6:
        return WriteSingleRegisterResponse(address=address, registers=list(request.values))
    if function == 15:
        return WriteMultipleCoilsResponse(address=address, count=request.count)
    return WriteMultipleRegistersResponse(address=address, count=request.count)


class _Connection(ServerRequestHandler):
    """One client's connection: its requests answered in their own tasks, bounded."""

    def __init__(self, owner: _Server) -> None:
        super().__init__(  # type: ignore[no-untyped-call]
            owner, owner.trace_packet, owner.trace_pdu, owner.trace_connect
        )
        self.owner = owner
        self.pending = 0
        self.counters = ClientCounters()
        self._idle: asyncio.TimerHandle | None = None

    def callback_connected(self) -> None:
        super().callback_connected()
        peer = self.transport.get_extra_info("peername") if self.transport else None
        self.counters = self.owner.book.of(str(peer[0]) if peer else "?")
        if len(self.owner.active_connections) > self.owner.limits.max_clients:
            self.counters.rejected += 1
            log.warning(
                "gateway: %s turned away: %d clients connected", peer, self.owner.limits.max_clients
            )
            self._drop()
            return
        self.counters.connections += 1
        self._watch()

    def callback_disconnected(self, exc: Exception | None) -> None:
        if self._idle is not None:
            self._idle.cancel()
        super().callback_disconnected(exc)

    def data_received(self, data: bytes) -> None:
        """Bytes that cannot start a frame close the connection before pymodbus buffers
        them (it would drop a long run of noise silently and keep the connection)."""
        problem = header_problem(self.recv_buffer[:MBAP_HEADER] + data[:MBAP_HEADER])
        if problem is not None:
            self._broken(problem)
            return
        super().data_received(data)

    def _broken(self, problem: str) -> None:
        self.counters.dropped += 1
        log.info("gateway: a connection closed: %s", problem)
        self.recv_buffer = b""
        self._drop()

    def callback_data(self, data: bytes, addr: tuple[Any, ...] | None = None) -> int:
        """Every whole frame in ``data`` taken (pymodbus takes one per call); the
        connection closed when the bytes cannot start a Modbus TCP frame."""
        used = 0
        while used < len(data):
            problem = header_problem(data[used:])
            if problem is not None:
                self._broken(problem)
                return len(data)
            rest = data[used:]
            if len(rest) <= MBAP_HEADER:
                break
            length = int.from_bytes(rest[4:6], "big") + 6
            if len(rest) < length:
                break  # the rest of the frame is still to come
            if rest[MBAP_HEADER] not in _DECODED:
                self._refuse(rest, Code.ILLEGAL_FUNCTION)
                used += length
                continue
            try:  # pymodbus' own handler would answer a PDU it cannot decode "0x80 01"
                cut = int(TransactionManager.callback_data(self, rest, addr))
            except ModbusIOException:
                self._refuse(rest, Code.ILLEGAL_VALUE)  # a count beyond its function's
                used += length
                continue
            pdu, self.last_pdu = self.last_pdu, None
            if pdu is not None:
                self._take(pdu)
            if cut <= 0:
                break
            used += cut
        return used

    def _refuse(self, data: bytes, code: Code) -> None:
        """Answer the whole frame at the start of ``data`` with exception ``code``."""
        self._watch()
        self.counters.requests += 1
        self.counters.refused += 1
        reply = ExceptionResponse(data[MBAP_HEADER] & 0x7F, code)
        reply.transaction_id = int.from_bytes(data[0:2], "big")
        reply.dev_id = data[6]
        if self.transport is not None and not self.transport.is_closing():
            self.server_send(reply, None)  # type: ignore[no-untyped-call]

    def handle_later(self) -> None:
        """Nothing: ``callback_data`` took the request already."""

    def _take(self, pdu: ModbusPDU) -> None:
        self._watch()
        self.counters.requests += 1
        if self.pending >= self.owner.limits.max_queued:
            self.counters.refused += 1
            self._send(pdu, ExceptionResponse(pdu.function_code, Code.BUSY))
            return
        self.pending += 1
        self.counters.queued += 1
        self.owner.spawn(self._answer(pdu))

    async def _answer(self, pdu: ModbusPDU) -> None:
        try:
            request = request_of(pdu)
            reply: ModbusPDU
            if isinstance(request, int):
                self.counters.refused += 1
                reply = ExceptionResponse(pdu.function_code, request)
            else:
                reply = await self._reply(pdu, request)
            self._send(pdu, reply)
        finally:
            self.pending -= 1
            self.counters.queued -= 1

    async def _reply(self, pdu: ModbusPDU, request: ProxyRequest) -> ModbusPDU:
        """``answer``'s reply; a fault of the bridge's own (not a refusal, a device's
        exception or silence, which ``answer`` turns into codes) is logged and answered
        0x04: no request may end the server, and with it the bridge."""
        try:
            answer = await self.owner.answer(self.counters, request)
        except Exception:
            self.counters.failed += 1
            log.exception("gateway: a request failed inside the bridge: %s", request)
            return ExceptionResponse(pdu.function_code, Code.DEVICE_FAILURE)
        if isinstance(answer, int):
            return ExceptionResponse(pdu.function_code, answer)
        return response_of(request, answer)

    def _send(self, request: ModbusPDU, reply: ModbusPDU) -> None:
        if self.transport is None or self.transport.is_closing():
            return  # the client left meanwhile
        reply.transaction_id = request.transaction_id
        reply.dev_id = request.dev_id
        self.server_send(reply, None)  # type: ignore[no-untyped-call]

    def _watch(self) -> None:
        """(Re)start the idle timer: no complete request for ``idle_timeout`` closes."""
        if self._idle is not None:
            self._idle.cancel()
        self._idle = asyncio.get_running_loop().call_later(
            self.owner.limits.idle_timeout, self._idle_out
        )

    def _idle_out(self) -> None:
        if self.pending:
            self._watch()
            return
        self.counters.dropped += 1
        self._drop()

    def _drop(self) -> None:
        transport = self.transport
        if isinstance(transport, asyncio.Transport):
            transport.abort()
        elif transport is not None:
            transport.close()


class _Server(ModbusTcpServer):
    def __init__(
        self, address: tuple[str, int], answer: Answer, limits: Limits, book: ClientBook
    ) -> None:
        super().__init__(_Context(), address=address)
        self.decoder.pdu_table = {fc: (kind, kind) for fc, kind in _DECODED.items()}
        self.decoder.pdu_sub_table = {}
        self.answer = answer
        self.limits = limits
        self.book = book
        self.group: asyncio.TaskGroup | None = None

    def callback_new_connection(self) -> _Connection:
        return _Connection(self)

    def spawn(self, work: Awaitable[None]) -> None:
        if self.group is not None:
            self.group.create_task(work)  # type: ignore[arg-type]


class GatewayServer:
    """Modbus TCP on ``host:port`` until cancelled; ``port`` is the one bound (for 0)."""

    def __init__(
        self, host: str, port: int, answer: Answer, limits: Limits, book: ClientBook
    ) -> None:
        self.host = host
        self.port = port
        self.ready = asyncio.Event()
        self._answer = answer
        self._limits = limits
        self.book = book

    async def run(self) -> None:
        server = _Server((self.host, self.port), self._answer, self._limits, self.book)
        async with asyncio.TaskGroup() as group:
            server.group = group
            try:
                await server.serve_forever(background=True)
            except RuntimeError:
                await server.shutdown()  # type: ignore[no-untyped-call]
                raise BusError(
                    f"gateway: cannot listen on {self.host}:{self.port} (in use, or no such "
                    "address): set bridge.gateway.host and port"
                ) from None
            for sock in getattr(server.transport, "sockets", None) or ():
                self.port = int(sock.getsockname()[1])
            log.info("gateway: Modbus TCP server on %s:%d", self.host, self.port)
            self.ready.set()
            try:
                await server.serving
            finally:
                self.ready.clear()
                server.group = None
                await server.shutdown()  # type: ignore[no-untyped-call]
