"""The one module that speaks pymodbus' PDU and framer API (pinned to 3.16).

It turns the core's ``Read``/``Write`` value objects into pymodbus PDUs, frames them as
RTU or ASCII, and parses response frames back into registers or bits. FC05 is sent as
an explicit 16-bit word (``CoilWordRequest``) so that devices printing ``00 FF`` for ON
(the Smartgen HGM6100) get exactly that on the wire.
"""

from __future__ import annotations

import struct
from typing import Any, Literal

from pymodbus.exceptions import ModbusException
from pymodbus.framer import FramerAscii, FramerRTU
from pymodbus.pdu import DecodePDU, ExceptionResponse, ModbusPDU
from pymodbus.pdu import bit_message as bits
from pymodbus.pdu import register_message as registers

from bridge.core.entity import Table
from bridge.core.request import Read, Write
from bridge.errors import FrameError

FramerName = Literal["rtu", "ascii"]


class CoilWordRequest(ModbusPDU):
    """FC05 with the 16-bit value given explicitly (0xFF00, 0x00FF or 0x0000)."""

    function_code = 5
    rtu_frame_size = 8

    def encode(self) -> bytes:
        self.verifyAddress()
        return struct.pack(">HH", self.address, self.registers[0])

    def decode(self, data: bytes) -> None:
        self.address, value = struct.unpack(">HH", data[:4])
        self.registers = [value]
        self.bits = [value != 0]


class TolerantRegistersResponse(registers.ReadHoldingRegistersResponse):
    """FC03 reply that also takes a 2-byte byte count (the P2 drive with F9.05 = 0).

    A standard reply never carries a byte count of 0, so a 0 there marks the long form
    ``unit 03 00 nn data... crc`` unambiguously; both forms decode to the same registers.
    """

    @classmethod
    def calculateRtuFrameSize(cls, data: bytes) -> int:  # noqa: N802 - pymodbus' name
        if len(data) < 4:
            return 0
        if data[2] == 0:
            return data[3] + 6
        return data[2] + 5

    def decode(self, data: bytes) -> None:
        if len(data) >= 2 and data[0] == 0:
            data = data[1:]
        super().decode(data)


_READS: dict[Table, type[ModbusPDU]] = {
    Table.COIL: bits.ReadCoilsRequest,
    Table.DISCRETE: bits.ReadDiscreteInputsRequest,
    Table.HOLDING: registers.ReadHoldingRegistersRequest,
    Table.INPUT: registers.ReadInputRegistersRequest,
}


def request_pdu(request: Read | Write, unit: int) -> ModbusPDU:
    """The pymodbus request PDU for one core transaction."""
    if isinstance(request, Read):
        return _READS[request.table](dev_id=unit, address=request.address, count=request.count)
    kwargs: dict[str, Any] = {"dev_id": unit, "address": request.address}
    match request.function:
        case 5:
            return CoilWordRequest(registers=list(request.values), **kwargs)
        case 6:
            return registers.WriteSingleRegisterRequest(registers=list(request.values), **kwargs)
        case 15:
            return bits.WriteMultipleCoilsRequest(bits=[bool(v) for v in request.values], **kwargs)
        case 16:
            return registers.WriteMultipleRegistersRequest(registers=list(request.values), **kwargs)
    raise FrameError(f"function {request.function} is not a write")


CUSTOM_PDUS: tuple[type[ModbusPDU], ...] = (CoilWordRequest,)
CLIENT_RESPONSES: tuple[type[ModbusPDU], ...] = (CoilWordRequest, TolerantRegistersResponse)


def _decoder(is_server: bool) -> DecodePDU:
    decoder = DecodePDU(is_server)
    for custom in CUSTOM_PDUS if is_server else CLIENT_RESPONSES:
        decoder.register(custom)
    return decoder


def _framer(name: FramerName, is_server: bool) -> FramerRTU | FramerAscii:
    return (FramerRTU if name == "rtu" else FramerAscii)(_decoder(is_server))


def build_frame(request: Read | Write, unit: int, framer: FramerName = "rtu") -> bytes:
    """The bytes a client puts on the line for ``request`` (address, PDU, CRC or LRC)."""
    return bytes(_framer(framer, is_server=False).buildFrame(request_pdu(request, unit)))


def parse_frame(data: bytes, framer: FramerName = "rtu", *, response: bool = True) -> ModbusPDU:
    """Parse one whole frame; FrameError if it is incomplete or fails its check."""
    try:
        used, pdu = _framer(framer, is_server=not response).handleFrame(data, 0, 0)
    except ModbusException as exc:
        raise FrameError(f"cannot decode frame {data.hex(' ')}: {exc}") from None
    if pdu is None or used != len(data):
        raise FrameError(f"not one valid {framer} frame: {data.hex(' ')}")
    return pdu


def response_values(pdu: ModbusPDU, request: Read) -> tuple[int, ...]:
    """Registers (or 0/1 bits) a read response carries, checked against the request."""
    if isinstance(pdu, ExceptionResponse):
        raise FrameError(f"exception response, code {pdu.exception_code}")
    if request.table.is_bits:
        whole_bytes = -(-request.count // 8) * 8  # bits come in whole bytes
        if len(pdu.bits) != whole_bytes:
            raise FrameError(f"asked for {request.count} bits, got {len(pdu.bits)} bits")
        values = tuple(int(bool(b)) for b in pdu.bits[: request.count])
    else:
        values = tuple(pdu.registers)
    if len(values) != request.count:
        raise FrameError(f"asked for {request.count} values, got {len(values)}")
    return values


def exception_code(pdu: ModbusPDU) -> int | None:
    """The exception code of an exception response, else None."""
    return int(pdu.exception_code) if isinstance(pdu, ExceptionResponse) else None
