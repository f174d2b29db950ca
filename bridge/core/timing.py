"""Wire time of Modbus transactions: what one read or write costs a bus, in seconds. Pure.

The poll planner minimises this figure and the scheduler reports bus utilisation with it.
Frame sizes (``body`` = unit address + PDU, the part every framing shares):

* RTU: body + CRC (2 bytes); a 3.5-character silence before and after each frame, fixed
  at 1.75 ms above 19200 bit/s (Modbus over Serial Line v1.02, §2.5.1.1).
* ASCII: ':' + two hex characters per byte of body and LRC (1 byte) + CR LF; a gap of one
  character between frames instead of the 3.5-character silence.
* TCP: MBAP header (7 bytes, holding the unit address) + PDU. A TCP exchange costs one
  round trip whatever its size (bytes are negligible on Ethernet), so merging reads always
  pays up to the device limits. RTU carried over TCP (``rtu-over-tcp``) still crosses a
  serial line behind the gateway: model it as ``rtu`` at that line's baud rate.

One exchange = request + response characters on the line + two silences + ``turnaround``
(the device's response latency). Broadcasts (no response) are not modelled.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from bridge.core.request import Read, Write

Mode = Literal["rtu", "ascii", "tcp"]

FAST_BAUDRATE = 19200
FAST_SILENCE = 0.00175  # t3.5 above 19200 bit/s, seconds
_READ_REQUEST_BODY = 6  # unit, function, address (2), quantity (2)
_READ_RESPONSE_HEAD = 3  # unit, function, byte count
_WRITE_MULTIPLE_HEAD = 7  # unit, function, address (2), quantity (2), byte count
_WRITE_ECHO_BODY = 6  # FC05/06 echo; FC15/16 answer address + quantity


@dataclass(frozen=True, slots=True)
class LinkTiming:
    """The timing of one link: framing, speed, character size and the device's latency."""

    mode: Mode = "rtu"
    baudrate: int = 9600
    bits_per_char: int = 10
    turnaround: float = 0.0
    tcp_round_trip: float = 0.005

    def __post_init__(self) -> None:
        if self.baudrate <= 0 or self.bits_per_char <= 0:
            raise ValueError("baudrate and bits_per_char must be positive")
        if self.turnaround < 0 or self.tcp_round_trip < 0:
            raise ValueError("turnaround and tcp_round_trip cannot be negative")

    @classmethod
    def for_serial(
        cls,
        baudrate: int,
        parity: Literal["N", "E", "O"] = "N",
        stopbits: int = 1,
        bytesize: int = 8,
        *,
        mode: Mode = "rtu",
    ) -> LinkTiming:
        """Timing of a serial line: 1 start bit + data bits + parity bit (if any) + stop bits
        per character (8N1 = 10 bits; 8E1 and 8N2 = 11)."""
        parity_bits = 0 if parity == "N" else 1
        return cls(
            mode=mode, baudrate=baudrate, bits_per_char=1 + bytesize + parity_bits + stopbits
        )

    @property
    def char_time(self) -> float:
        """Seconds one character takes on the line."""
        return self.bits_per_char / self.baudrate

    @property
    def silence(self) -> float:
        """The gap that ends a frame: t3.5 (RTU), one character (ASCII), none (TCP)."""
        if self.mode == "rtu":
            return FAST_SILENCE if self.baudrate > FAST_BAUDRATE else 3.5 * self.char_time
        if self.mode == "ascii":
            return self.char_time
        return 0.0

    def frame_bytes(self, body: int) -> int:
        """Bytes (ASCII: characters) on the wire of a frame carrying ``body`` bytes of unit
        address + PDU."""
        if self.mode == "rtu":
            return body + 2
        if self.mode == "ascii":
            return 1 + 2 * (body + 1) + 2
        return 7 + body - 1

    def request_bytes(self, read: Read) -> int:  # noqa: ARG002 - one size for every read
        return self.frame_bytes(_READ_REQUEST_BODY)

    def response_bytes(self, read: Read) -> int:
        return self.frame_bytes(_READ_RESPONSE_HEAD + _data_bytes(read))

    def read_bytes(self, read: Read) -> int:
        """Request + response bytes of one read."""
        return self.request_bytes(read) + self.response_bytes(read)

    def read_cost(self, read: Read) -> float:
        """Seconds the bus is busy with one read, request to end of response."""
        return self._exchange(self.read_bytes(read))

    def write_bytes(self, write: Write) -> int:
        """Request + response bytes of one write (FC05, 06, 15 or 16)."""
        if write.function in (5, 6):
            request = _WRITE_ECHO_BODY
        elif write.function == 15:
            request = _WRITE_MULTIPLE_HEAD + (len(write.values) + 7) // 8
        elif write.function == 16:
            request = _WRITE_MULTIPLE_HEAD + 2 * len(write.values)
        else:
            raise ValueError(f"function {write.function} is not a write")
        return self.frame_bytes(request) + self.frame_bytes(_WRITE_ECHO_BODY)

    def write_cost(self, write: Write) -> float:
        """Seconds the bus is busy with one write."""
        return self._exchange(self.write_bytes(write))

    def _exchange(self, characters: int) -> float:
        if self.mode == "tcp":
            return self.tcp_round_trip + self.turnaround
        return characters * self.char_time + 2 * self.silence + self.turnaround


def _data_bytes(read: Read) -> int:
    """Bytes of data in a read response: two per register, one per eight bits."""
    return (read.count + 7) // 8 if read.table.is_bits else 2 * read.count
