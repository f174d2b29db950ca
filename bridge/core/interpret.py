"""Raw registers and bits shown every way a manual might mean them: a commissioning aid.

``interpret(address, words)`` takes registers as read from a unit and returns a JSON-ready
dict: each word as u16, s16, hex, two ASCII characters and its bits, and each adjacent
pair of words as u32, s32 and f32 in the four byte orders a device may use:

    ABCD  big-endian words, big-endian bytes (the Modbus convention)
    CDAB  word swap: the low word first (many PLCs and drives)
    BADC  byte swap inside each word
    DCBA  both: little-endian throughout

The letters name the value's big-endian bytes A (most significant) to D in the order the
unit sends them. An f32 is the shortest decimal that reads back as the same 32-bit float
(``12.5``, ``0.1``), so every finite value re-encodes to the words it came from; NaN and
the infinities, which JSON cannot carry as numbers, are the strings ``"nan"``, ``"inf"``
and ``"-inf"``. ``interpret_bits(address, bits)`` does the same for coils and discrete
inputs. Addresses are wire addresses (0-based). Pure: no I/O.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from typing import Any

ORDERS = ("ABCD", "CDAB", "BADC", "DCBA")
_MAX_ADDRESS = 0xFFFF
_SIGNIFICANT_DIGITS_F32 = 9  # always enough to read back the same float32


def interpret(address: int, words: Sequence[int]) -> dict[str, Any]:
    """Every reading of ``words`` (registers from wire ``address`` on), JSON-ready."""
    registers = [_checked_word(word) for word in words]
    _check_span(address, len(registers))
    return {
        "address": address,
        "count": len(registers),
        "registers": registers,
        "hex": [f"0x{word:04X}" for word in registers],
        "words": [_word(address + i, word) for i, word in enumerate(registers)],
        "pairs": [
            _pair(address + i, registers[i], registers[i + 1]) for i in range(len(registers) - 1)
        ],
    }


def interpret_bits(address: int, bits: Sequence[int]) -> dict[str, Any]:
    """Coils or discrete inputs from wire ``address`` on: the bits, which are on, and the
    data bytes as a read reply carries them (bit 0 of the first byte is ``address``)."""
    values = [_checked_bit(bit) for bit in bits]
    _check_span(address, len(values))
    packed = [
        sum(bit << i for i, bit in enumerate(values[start : start + 8]))
        for start in range(0, len(values), 8)
    ]
    return {
        "address": address,
        "count": len(values),
        "bits": values,
        "on": [address + i for i, bit in enumerate(values) if bit],
        "bytes": [f"0x{byte:02X}" for byte in packed],
    }


def pair_bytes(order: str, first: int, second: int) -> bytes:
    """The value's big-endian bytes (ABCD) from two words sent in ``order``."""
    if order not in ORDERS:
        raise ValueError(f"byte order {order!r} is not one of {', '.join(ORDERS)}")
    wire = first.to_bytes(2, "big") + second.to_bytes(2, "big")
    positions = {"ABCD": (0, 1, 2, 3), "CDAB": (2, 3, 0, 1), "BADC": (1, 0, 3, 2)}
    if order == "DCBA":
        return wire[::-1]
    return bytes(wire[i] for i in positions[order])


def words_of(order: str, value: bytes) -> tuple[int, int]:
    """The two words a unit using ``order`` sends for the big-endian bytes ``value``.

    Every order is its own inverse, so this is ``pair_bytes`` read backwards."""
    wire = pair_bytes(order, int.from_bytes(value[:2], "big"), int.from_bytes(value[2:], "big"))
    return int.from_bytes(wire[:2], "big"), int.from_bytes(wire[2:], "big")


def f32_value(raw: bytes) -> float | str:
    """A big-endian float32 as the shortest decimal that reads back the same; NaN and the
    infinities as ``"nan"``, ``"inf"``, ``"-inf"``."""
    (value,) = struct.unpack(">f", raw)
    if math.isnan(value):
        return "nan"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    for digits in range(1, _SIGNIFICANT_DIGITS_F32 + 1):
        candidate = float(f"{value:.{digits}g}")
        if _float32(candidate) == raw:
            return candidate
    return float(value)  # pragma: no cover - 9 significant digits always read back


def _float32(value: float) -> bytes | None:
    """``value`` packed as a big-endian float32; None when rounding took it out of range."""
    try:
        return struct.pack(">f", value)
    except OverflowError:
        return None


def _word(address: int, word: int) -> dict[str, Any]:
    high, low = word >> 8, word & 0xFF
    bits = f"{word:016b}"
    return {
        "address": address,
        "u16": word,
        "s16": word - 0x10000 if word & 0x8000 else word,
        "hex": f"0x{word:04X}",
        "ascii": _printable(high) + _printable(low),
        "bits": " ".join(bits[i : i + 4] for i in range(0, 16, 4)),
    }


def _pair(address: int, first: int, second: int) -> dict[str, Any]:
    pair: dict[str, Any] = {"address": address}
    for order in ORDERS:
        raw = pair_bytes(order, first, second)
        pair[order] = {
            "u32": int.from_bytes(raw, "big"),
            "s32": int.from_bytes(raw, "big", signed=True),
            "f32": f32_value(raw),
        }
    return pair


def _printable(byte: int) -> str:
    return chr(byte) if 0x20 <= byte < 0x7F else "."


def _checked_word(word: int) -> int:
    if not 0 <= word <= 0xFFFF:
        raise ValueError(f"register value {word} is outside 0..65535")
    return word


def _checked_bit(bit: int) -> int:
    if bit not in (0, 1):
        raise ValueError(f"bit value {bit} is not 0 or 1")
    return int(bit)


def _check_span(address: int, count: int) -> None:
    if not 0 <= address <= _MAX_ADDRESS or address + count - 1 > _MAX_ADDRESS:
        raise ValueError(f"address {address} with {count} values is outside 0..65535")
