"""The Modbus TCP server the bridge offers other masters (the gateway): its decisions. Pure.

Another master (a commissioning tool, evcc, Home Assistant's own ``modbus`` integration,
``mbpoll``) sends Modbus TCP requests to the bridge; each becomes a transaction on the
bus that owns the unit it names, between the bridge's own polls. What is decided here:

- which requests are served at all (``check_request``): FC01-06, FC15 and FC16 only
  (diagnostics, FC22/FC23 and the rest answer 0x01), within the protocol's counts (125
  registers or 2000 bits per read, 123 registers or 1968 coils per write) and the 65536
  addresses (else 0x03 or 0x02);
- which exception code answers a failure (``code_for``): the device's own code as it
  sent it; 0x0B (gateway target failed to respond) when it stayed silent or garbled its
  reply; 0x0A (gateway path unavailable) for a unit the gateway does not map or a bus that
  is down; 0x06 (busy) when the client or the bus has too many requests waiting. A write
  the writer refuses answers by the error's type, never its wording: 0x01 when the entity
  may not be written whatever the value (``WriteForbiddenError``: read-only, guarded, a
  lock, conditions unmet, too soon after the last write), 0x03 when the value is refused
  (range, enum, sentinel);
- a read of a secret or write-only register (a password; bridge/gateway.py checks it with
  the rule of raw reads, bridge/core/reach.py) answers 0x02, illegal data address, from
  the bus and from the image alike: the code a device gives for an address it does not
  serve, so a master treats it as a hole (HA's modbus, mbpoll, pymodbus do), not as a
  function it may retry some other way (0x01) or a bad count (0x03);
- whether a read can be answered from the bridge's own image (``cached_words``): every
  register (or bit) of it read or written no longer than ``max_age`` seconds ago;
- whether a client's first bytes are Modbus TCP at all (``header_problem``): protocol id
  0 and a length of 2..254; anything else ends the connection;
- per client (by peer address) what it was served, from the cache, refused and failed
  (``ClientBook``), bounded to ``MAX_CLIENTS_KEPT`` addresses.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from bridge.core.entity import Table
from bridge.core.request import Read, Write
from bridge.errors import (
    BridgeError,
    BusError,
    CommandExpiredError,
    DeviceExceptionError,
    DeviceTimeoutError,
    FrameError,
    PartialWriteError,
    ValueRejectedError,
)

MAX_READ_REGISTERS = 125
MAX_READ_BITS = 2000
MAX_WRITE_REGISTERS = 123
MAX_WRITE_COILS = 1968
MAX_CLIENTS_KEPT = 64  # peer addresses whose counters the health report keeps
MBAP_HEADER = 7  # transaction id, protocol id, length, unit id
MAX_MBAP_LENGTH = 254  # unit id + the longest PDU (253 bytes)

READ_TABLES = {1: Table.COIL, 2: Table.DISCRETE, 3: Table.HOLDING, 4: Table.INPUT}
WRITE_TABLES = {5: Table.COIL, 6: Table.HOLDING, 15: Table.COIL, 16: Table.HOLDING}


class Code(IntEnum):
    """The Modbus exception codes the gateway answers with itself."""

    ILLEGAL_FUNCTION = 0x01
    ILLEGAL_ADDRESS = 0x02
    ILLEGAL_VALUE = 0x03
    DEVICE_FAILURE = 0x04
    BUSY = 0x06
    PATH_UNAVAILABLE = 0x0A
    TARGET_NO_RESPONSE = 0x0B


@dataclass(frozen=True, slots=True)
class ProxyRequest:
    """One request of another master: a read (``count`` cells) or a write (``values``;
    coils as 0/1, registers as words)."""

    unit: int
    function: int
    address: int
    count: int
    values: tuple[int, ...] = ()

    @property
    def is_write(self) -> bool:
        return self.function in WRITE_TABLES

    @property
    def table(self) -> Table:
        return WRITE_TABLES[self.function] if self.is_write else READ_TABLES[self.function]

    def read(self) -> Read:
        return Read(self.table, self.address, self.count)

    def write(self, coil_on: int) -> Write:
        """The write as the bus sends it (FC05 with the device's ON word)."""
        values = self.values
        if self.function == 5:
            values = (coil_on if values[0] else 0,)
        return Write(self.function, self.table, self.address, values)


@dataclass(frozen=True, slots=True)
class Route:
    """Where a unit of the gateway goes: a unit on a bus, the configured device there if
    any."""

    bus: str
    unit: int
    device: str | None = None


def check_request(request: ProxyRequest) -> Code | None:
    """Why ``request`` cannot be served (its exception code), or None."""
    function = request.function
    if function not in READ_TABLES and function not in WRITE_TABLES:
        return Code.ILLEGAL_FUNCTION
    if request.is_write:
        limit = (
            1
            if function in (5, 6)
            else (MAX_WRITE_COILS if function == 15 else MAX_WRITE_REGISTERS)
        )
        if len(request.values) != request.count:
            return Code.ILLEGAL_VALUE
        top = 1 if request.table is Table.COIL else 0xFFFF
        if any(not 0 <= v <= top for v in request.values):
            return Code.ILLEGAL_VALUE
    else:
        limit = MAX_READ_BITS if request.table.is_bits else MAX_READ_REGISTERS
    if not 1 <= request.count <= limit:
        return Code.ILLEGAL_VALUE
    if not request.address >= 0 or request.address + request.count > 0x10000:
        return Code.ILLEGAL_ADDRESS
    return None


def code_for(error: BridgeError) -> int:
    """The exception code a failure is answered with (module docstring)."""
    if isinstance(error, DeviceExceptionError):
        return error.code
    if isinstance(error, DeviceTimeoutError | FrameError | PartialWriteError):
        return Code.TARGET_NO_RESPONSE
    if isinstance(error, BusError):
        return Code.PATH_UNAVAILABLE
    if isinstance(error, CommandExpiredError):
        return Code.BUSY
    if isinstance(error, ValueRejectedError):  # by its kind, never by its wording
        return Code.ILLEGAL_FUNCTION if error.forbidden else Code.ILLEGAL_VALUE
    return Code.DEVICE_FAILURE


def cached_words(
    read: Read,
    image: Mapping[tuple[Table, int], int],
    read_at: Mapping[tuple[Table, int], float],
    now: float,
    max_age: float,
) -> tuple[int, ...] | None:
    """The words (or bits) of ``read`` from the image when every one of them was read or
    written within ``max_age`` seconds of ``now``; else None (read the bus)."""
    if max_age <= 0:
        return None
    words = []
    for address in read.span:
        cell = (read.table, address)
        when = read_at.get(cell)
        if when is None or now - when > max_age or cell not in image:
            return None
        words.append(image[cell])
    return tuple(words)


def header_problem(buffer: bytes) -> str | None:
    """Why the bytes waiting on a connection cannot start a Modbus TCP frame, or None
    (they may, or too few have come to tell)."""
    if len(buffer) < MBAP_HEADER:
        return None
    protocol = int.from_bytes(buffer[2:4], "big")
    length = int.from_bytes(buffer[4:6], "big")
    if protocol != 0:
        return f"protocol id {protocol}, not 0 (Modbus)"
    if not 2 <= length <= MAX_MBAP_LENGTH:
        return f"length {length}: a Modbus TCP frame carries 2..{MAX_MBAP_LENGTH}"
    return None


@dataclass(slots=True)
class ClientCounters:
    """What one client (peer address) asked of the gateway."""

    connections: int = 0  # accepted
    rejected: int = 0  # connections turned away (too many clients)
    dropped: int = 0  # connections ended for broken frames or idleness
    requests: int = 0
    served: int = 0  # answered with values or a write's echo (cached ones included)
    cached: int = 0  # answered from the bridge's image, no bus transaction
    refused: int = 0  # answered with an exception the gateway chose (guard, limits, busy)
    failed: int = 0  # the device's exception, silence or a bus fault
    queued: int = 0  # waiting or on the bus now
    delayed: int = 0  # slots its requests gave to the bridge's polls (the fair share)
    busy: int = 0  # answered 0x06: still waiting for the bus after its timeout

    def as_dict(self) -> dict[str, Any]:
        return {
            "connections": self.connections,
            "rejected": self.rejected,
            "dropped": self.dropped,
            "requests": self.requests,
            "served": self.served,
            "cached": self.cached,
            "refused": self.refused,
            "failed": self.failed,
            "queued": self.queued,
            "delayed": self.delayed,
            "busy": self.busy,
        }


class ClientBook:
    """The counters of every client by peer address, the most recent ``MAX_CLIENTS_KEPT``
    (a client that comes back keeps its counters; the oldest idle one is forgotten)."""

    def __init__(self, kept: int = MAX_CLIENTS_KEPT) -> None:
        self.kept = kept
        self.clients: dict[str, ClientCounters] = {}

    def of(self, peer: str) -> ClientCounters:
        counters = self.clients.pop(peer, None) or ClientCounters()
        self.clients[peer] = counters  # the most recent last
        while len(self.clients) > self.kept:
            oldest = next((p for p, c in self.clients.items() if c.queued == 0), None)
            if oldest is None or oldest == peer:
                break
            del self.clients[oldest]
        return counters

    def totals(self) -> ClientCounters:
        total = ClientCounters()
        for counters in self.clients.values():
            for name in total.__slots__:
                setattr(total, name, getattr(total, name) + getattr(counters, name))
        return total
