"""Registers and bits <-> values. Pure functions; nothing here mutates its input.

The codec reads from a register *image*: a mapping ``(table, wire address) -> word`` (or
0/1 for bit tables) holding what was last read from a device. ``decode(point, image)``
returns the engineering value of one point (``None`` for a sentinel; an enum code the
mapping has no label for is ``code_<n>``, never lost); ``encode(point, value, image)``
returns the writes that put ``value`` on the device, or raises ``ValueRejectedError`` and
nothing is written (an enum is written by its labels only).
"""

from __future__ import annotations

import contextlib
import math
import struct
import sys
from collections.abc import Mapping as AnyMapping
from collections.abc import Sequence
from decimal import ROUND_HALF_UP, Decimal, InvalidOperation

from bridge.core.entity import MAX_EXPONENT, DataType, Entity, Order, Table
from bridge.core.mapping import Point
from bridge.core.request import Write
from bridge.errors import MissingDataError, ValueRejectedError, WriteForbiddenError

Image = AnyMapping[tuple[Table, int], int]
Value = bool | int | float | str | None

# What a command may say (DESIGN.md, MQTT contract): a switch takes only its on/off words
# (any case), a button only its press payload; nothing else turns a switch on or presses.
COMMAND_ON = "ON"
COMMAND_OFF = "OFF"
COMMAND_PRESS = "PRESS"
_TRUE = {"on", "true", "1"}
_FALSE = {"off", "false", "0"}
UNKNOWN_CODE = "code_"  # prefix of an enum code the mapping has no label for: code_23


def unknown_code(raw: int) -> str:
    """How an enum code the mapping does not know is published: ``code_23``."""
    return f"{UNKNOWN_CODE}{raw}"


def is_unknown_code(entity: Entity, value: object) -> bool:
    """True when ``value`` is an enum code ``entity`` has no label for (``code_23``)."""
    return (
        entity.enum is not None
        and isinstance(value, str)
        and value.startswith(UNKNOWN_CODE)
        and value not in entity.enum.values()
    )


# --- raw words <-> integers -----------------------------------------------------------


def words_of(point: Point, image: Image) -> tuple[int, ...]:
    """The raw words (or bits) of ``point``; MissingDataError if any has not been read."""
    try:
        return tuple(image[(point.table, address)] for address in point.span)
    except KeyError as exc:
        table, address = exc.args[0]
        raise MissingDataError(f"{point.key}: {table.value} {address} has not been read") from None


def join_words(words: Sequence[int], order: Order, radix: int = 65536) -> int:
    """Combine words (high word first for ``big``, last for ``little``: the words reversed,
    Home Assistant's ``swap: word``) into one unsigned integer."""
    number = 0
    for word in words if order is Order.BIG else reversed(words):
        number = number * radix + word
    return number


def split_words(number: int, order: Order, radix: int = 65536, count: int = 2) -> tuple[int, ...]:
    """``count`` words of ``number``, in ``order`` (the inverse of ``join_words``)."""
    words: list[int] = []
    for _ in range(count - 1):
        number, word = divmod(number, radix)
        words.append(word)
    words.append(number)  # the high word: a u32 of radix 10000 holds up to 65535 there
    return tuple(reversed(words)) if order is Order.BIG else tuple(words)


def _swap_bytes(word: int) -> int:
    return ((word & 0xFF) << 8) | (word >> 8)


def _to_bytes(words: Sequence[int], byte_order: Order) -> bytes:
    if byte_order is Order.LITTLE:
        words = [_swap_bytes(w) for w in words]
    return b"".join(w.to_bytes(2, "big") for w in words)


def _from_bytes(data: bytes, byte_order: Order) -> tuple[int, ...]:
    words = [int.from_bytes(data[i : i + 2], "big") for i in range(0, len(data), 2)]
    return tuple(_swap_bytes(w) if byte_order is Order.LITTLE else w for w in words)


def unsigned_raw(entity: Entity, words: Sequence[int]) -> int:
    """The raw unsigned integer the words carry (before sign, field, scale)."""
    if entity.register_count in (2, 4) and entity.data_type is not DataType.ASCII:
        ordered = _from_bytes(_to_bytes(words, entity.byte_order), Order.BIG)
        return join_words(ordered, entity.word_order, entity.word_radix)
    word = words[0]
    return _swap_bytes(word) if entity.byte_order is Order.LITTLE else word


def raw_bounds(entity: Entity) -> tuple[int, int]:
    """Inclusive range of the integer an entity stores (after field and sign handling)."""
    if entity.field_width is not None:
        return 0, (1 << entity.field_width) - 1
    return {
        DataType.U16: (0, 0xFFFF),
        DataType.S16: (-0x8000, 0x7FFF),
        DataType.U32: (0, 0xFFFF * entity.word_radix + entity.word_radix - 1),
        DataType.S32: (-0x80000000, 0x7FFFFFFF),
        DataType.U64: (0, (1 << 64) - 1),
        DataType.S64: (-(1 << 63), (1 << 63) - 1),
        DataType.BOOL: (0, 1),
    }.get(entity.data_type, (0, 0))


def to_signed(raw: int, bits: int) -> int:
    return raw - (1 << bits) if raw >= 1 << (bits - 1) else raw


# --- decode ---------------------------------------------------------------------------


def decode(point: Point, image: Image) -> Value:
    """The engineering value of ``point`` from the image."""
    entity = point.entity
    words = words_of(point, image)
    kind = entity.data_type
    if kind is DataType.ASCII:
        if 0 in entity.sentinels and not any(words):  # all zero: no text (SunSpec)
            return None
        text = _to_bytes(words, entity.byte_order).decode("latin-1")
        return text.rstrip("\x00 ").lstrip("\x00")
    if kind is DataType.BOOL:
        if entity.words is not None:
            return entity.words.state(words[0])
        return _finish(entity, int(bool(words[0])))
    unsigned = unsigned_raw(entity, words)
    if unsigned in entity.sentinels:
        return None
    if kind.is_float:
        number = float_of(kind, unsigned)
        return None if number is None else _scaled_float(entity, number)
    raw = _integer(entity, unsigned)
    if entity.kind == "number" and point.sign is not None and decode(point.sign, image):
        raw = -raw
    if point.scale_source is not None:
        exponent = scale_exponent(point.scale_source, image)
        return None if exponent is None else scale_value(entity, raw, True, exponent)
    return _finish(entity, raw)


def scale_exponent(source: Point, image: Image) -> int | None:
    """The power of ten a ``scale_by`` register holds (a SunSpec ``sunssf``), or None
    when it is not one: 0x8000 (not implemented), a sentinel, beyond -10..10."""
    exponent = decode(source, image)
    if not isinstance(exponent, int) or isinstance(exponent, bool):
        return None
    return exponent if -MAX_EXPONENT <= exponent <= MAX_EXPONENT else None


# struct format, bytes and the significant digits that always read back the same float
_FLOATS = {DataType.F16: (">e", 2, 5), DataType.F32: (">f", 4, 9), DataType.F64: (">d", 8, 17)}


def float_of(kind: DataType, bits: int) -> float | None:
    """The float ``bits`` hold as the shortest decimal that maps back to them (3.14, not
    3.1400001); None for NaN and infinity (a value the device does not have)."""
    form, size, most = _FLOATS[kind]
    packed = bits.to_bytes(size, "big")
    number: float = struct.unpack(form, packed)[0]
    if not math.isfinite(number):
        return None
    for digits in range(3, most + 1):
        candidate = float(f"{number:.{digits}g}")
        with contextlib.suppress(OverflowError):  # rounded up beyond the type's largest
            if struct.pack(form, candidate) == packed:
                return candidate
    return number


def float_limit(kind: DataType) -> float:
    """The largest finite value a float register of ``kind`` holds."""
    return {DataType.F16: 65504.0, DataType.F32: 3.4028234663852886e38}.get(
        kind, sys.float_info.max
    )


def float_bits(kind: DataType, number: float) -> int:
    """The bits of ``number`` as a float of ``kind``; OverflowError beyond its range."""
    return int.from_bytes(struct.pack(_FLOATS[kind][0], float(number)), "big")


def _scaled_float(entity: Entity, number: float) -> float:
    """A float register's value * scale + offset (the mapping's unit, e.g. Wh -> kWh),
    then clamped and zero-suppressed."""
    if entity.scale != 1 or entity.offset != 0:
        exact = Decimal(repr(number)) * Decimal(repr(entity.scale)) + Decimal(repr(entity.offset))
        digits = _FLOATS[entity.data_type][2]
        number = float(f"{float(exact):.{digits}g}")
    if entity.clamp is None and entity.zero_suppress is None:
        return number
    return float(_shaped(entity, Decimal(repr(number))))


def _shaped(entity: Entity, exact: Decimal) -> Decimal:
    """A reading after scale and offset as Home Assistant's modbus sensor shows it: clamped
    into ``clamp`` (min first, then max), then 0 when its size is at most ``zero_suppress``."""
    limits = entity.clamp
    if limits is not None and limits.min is not None and exact < Decimal(repr(limits.min)):
        exact = Decimal(repr(limits.min))
    if limits is not None and limits.max is not None and exact > Decimal(repr(limits.max)):
        exact = Decimal(repr(limits.max))
    if entity.zero_suppress is not None and abs(exact) <= Decimal(repr(entity.zero_suppress)):
        return Decimal(0)
    return exact


def _unscaled_float(entity: Entity, number: float) -> float:
    """The float a register holds for an engineering value: (value - offset) / scale."""
    if entity.scale == 1 and entity.offset == 0:
        return number
    return (number - entity.offset) / entity.scale


def _integer(entity: Entity, unsigned: int) -> int:
    if entity.field_width is not None:
        return (unsigned >> (entity.bit or 0)) & ((1 << entity.field_width) - 1)
    if entity.data_type is DataType.S16:
        return to_signed(unsigned, 16)
    if entity.data_type is DataType.S32:
        return to_signed(unsigned, 32)
    if entity.data_type is DataType.S64:
        return to_signed(unsigned, 64)
    return unsigned


def _finish(entity: Entity, raw: int) -> Value:
    if entity.on_when is not None:
        low, high = entity.on_when.min, entity.on_when.max
        return (low is None or raw >= low) and (high is None or raw <= high)
    if entity.enum is not None:
        return entity.enum.get(raw, unknown_code(raw))
    if entity.kind == "bool":
        return bool(raw)
    return scale_value(entity, raw, shaped=True)


def scale_value(entity: Entity, raw: int, shaped: bool = False, exponent: int = 0) -> int | float:
    """raw * 10**exponent * scale + offset, exact in decimal, as an int when the entity
    has no decimals (``exponent``: a ``scale_by`` register's, which adds its own decimals);
    ``shaped``: clamped and zero-suppressed before rounding (a reading, not a range end)."""
    factor = _factor(entity, exponent)
    exact = Decimal(raw) * factor + Decimal(repr(entity.offset))
    if shaped:
        exact = _shaped(entity, exact)
    decimals = entity.decimals if exponent == 0 else scaled_decimals(entity, exponent)
    if decimals == 0:
        return int(exact.to_integral_value(ROUND_HALF_UP))
    return float(round(exact, decimals))


def scaled_decimals(entity: Entity, exponent: int) -> int:
    """Decimals of a ``scale_by`` value at this exponent: ``precision`` when given, else
    those of scale x 10**exponent and of offset (sf -2, scale 1: two)."""
    if entity.precision is not None:
        return entity.precision
    return max(_places(_factor(entity, exponent)), _places(Decimal(repr(entity.offset))))


def decimals_of(point: Point, image: Image) -> int | None:
    """The decimals ``point``'s value is published with: fixed by the mapping, or for a
    ``scale_by`` value those of the exponent in ``image`` (None while it is unknown)."""
    source = point.scale_source
    if source is None:
        return point.entity.decimals
    try:
        exponent = scale_exponent(source, image)
    except MissingDataError:
        exponent = None
    return None if exponent is None else scaled_decimals(point.entity, exponent)


def _places(number: Decimal) -> int:
    """Decimals ``number`` needs: 0.01 two, 100 none."""
    return max(0, -int(number.normalize().as_tuple().exponent))


def _factor(entity: Entity, exponent: int) -> Decimal:
    return Decimal(repr(entity.scale)).scaleb(exponent)


def unscale_value(entity: Entity, value: float, exponent: int = 0) -> int:
    """(value - offset) / (scale * 10**exponent) rounded half away from zero: 4.5 bar at
    0.1 -> 45, not 44. An integer is taken exactly (a 64-bit value beyond a float's 53 bits)."""
    given = Decimal(value) if isinstance(value, int) else Decimal(repr(float(value)))
    try:
        exact = (given - Decimal(repr(entity.offset))) / _factor(entity, exponent)
    except InvalidOperation:
        raise ValueRejectedError(f"{_shown(value)} is not a finite number") from None
    return int(exact.to_integral_value(ROUND_HALF_UP))


def _write_exponent(point: Point, image: Image) -> int:
    """The exponent a write of ``point`` is encoded with: its ``scale_by`` register as
    last read (0 without one); ValueRejectedError when it is unknown or not read."""
    source = point.scale_source
    if source is None:
        return 0
    try:
        exponent = scale_exponent(source, image)
    except MissingDataError:
        exponent = None
    if exponent is None:
        raise ValueRejectedError(
            f"{point.key}: its scale factor {source.key} is unknown (not read, not "
            f"implemented or beyond -{MAX_EXPONENT}..{MAX_EXPONENT}): nothing written"
        )
    return exponent


def unit_of(point: Point, image: Image) -> str | None:
    """The unit of ``point``: fixed in the mapping, or the label of its unit register."""
    if point.unit_source is None:
        return point.entity.unit
    try:
        label = decode(point.unit_source, image)
    except MissingDataError:
        return None
    unknown = is_unknown_code(point.unit_source.entity, label)
    return label if isinstance(label, str) and not unknown else None


def limits_of(point: Point, image: Image) -> tuple[float | None, float | None]:
    """Engineering limits: static min/max, tightened by limit registers when read."""
    entity = point.entity
    low, high = entity.min, entity.max
    for source, is_low in ((point.min_source, True), (point.max_source, False)):
        if source is None:
            continue
        bound = decode(source, image)
        if not isinstance(bound, int | float) or isinstance(bound, bool):
            continue
        if is_low:
            low = bound if low is None else max(low, bound)
        else:
            high = bound if high is None else min(high, bound)
    return low, high


# --- encode ---------------------------------------------------------------------------


def encode(point: Point, value: object, image: Image) -> tuple[Write, ...]:
    """The writes that set ``point`` to ``value``; ValueRejectedError if it is not allowed."""
    entity = point.entity
    if not entity.writable:
        raise WriteForbiddenError(f"{point.key} is read-only")
    if point.state_source is not None:
        return _toggle_writes(point, point.state_source, value, image)
    if entity.press is not None:
        value = _press_value(point.key, entity.press, value)
    kind = entity.data_type
    if kind is DataType.ASCII:
        return (_register_write(point, _encode_text(entity, value)),)
    if kind.is_float:
        number = _unscaled_float(entity, _number(point, value, image))
        try:
            bits = float_bits(kind, number)
        except OverflowError:
            raise ValueRejectedError(
                f"{point.key}: {_shown(value)} does not fit a {kind.value} float"
            ) from None
        return (_register_write(point, _ordered(entity, bits)),)
    raw = _raw_for(point, value, image)
    if kind is DataType.BOOL and point.table.is_bits:
        return _coil_writes(point, raw)
    writes: list[Write] = []
    if point.sign is not None:
        if decode(point.sign, image) != (raw < 0):  # sign first, then magnitude
            writes.extend(encode_field(point.sign, int(raw < 0), image))
        raw = abs(raw)
    if entity.field_width is not None:
        if entity.pulse:  # a rising edge: 0 first if the bit was left at 1, then 1, then 0
            was_set = bool(decode(point, image))
            clear = encode_field(point, 0, image) if was_set else ()
            return (
                clear
                + encode_field(point, 1, image, after=0)
                + encode_field(point, 0, image, after=1)
            )
        return tuple(writes) + encode_field(point, raw, image)
    unsigned = raw & ((1 << (16 * entity.register_count)) - 1)  # two's complement for signed types
    if unsigned in entity.sentinels:
        raise ValueRejectedError(f"{point.key}: {_shown(value)} is the device's 'unknown' marker")
    writes.append(_register_write(point, _ordered(entity, unsigned)))
    return tuple(writes)


def encode_field(
    point: Point, raw: int, image: Image, after: int | None = None
) -> tuple[Write, ...]:
    """Write one bit/nibble field, keeping the other bits of the word (read-modify-write).

    ``after`` is the field value an earlier write in the same command left behind (pulses).
    """
    entity = point.entity
    bit, width = entity.bit or 0, entity.field_width or 1
    words = words_of(point, image)
    mask = ((1 << width) - 1) << bit
    current = words[0] if after is None else (words[0] & ~mask) | (after << bit)
    word = (current & ~mask) | (raw << bit)
    return (_register_write(point, (word,)),)


def _raw_for(point: Point, value: object, image: Image) -> int:
    entity = point.entity
    if entity.enum is not None:
        return _enum_raw(point, value)
    if entity.kind == "bool":
        on = parse_bool(point.key, value)
        if entity.words is not None:  # the mapping's words, never one the command names
            return entity.words.write_on if on else entity.words.write_off
        return int(on)
    number = _number(point, value, image)
    raw = unscale_value(entity, number, _write_exponent(point, image))
    low, high = raw_bounds(entity)
    magnitude_low = -high if point.sign is not None else low
    if not magnitude_low <= raw <= high:
        raise ValueRejectedError(f"{point.key}: {_shown(value)} does not fit the register")
    return raw


def _enum_raw(point: Point, value: object) -> int:
    enum = point.entity.enum or {}
    if isinstance(value, str):
        for raw, label in enum.items():
            if label == value or label.casefold() == value.strip().casefold():
                return raw
    if isinstance(value, int) and not isinstance(value, bool) and value in enum:
        return value
    options = ", ".join(repr(label) for label in enum.values())
    raise ValueRejectedError(f"{point.key}: {_shown(value)} is not one of {options}")


def parse_bool(key: str, value: object) -> bool:
    """ON/OFF, true/false, 1/0 (text in any case, or JSON) -> bool; nothing else."""
    if isinstance(value, bool):
        return value
    if isinstance(value, int) and value in (0, 1):
        return bool(value)
    if isinstance(value, str) and value.strip().casefold() in _TRUE | _FALSE:
        return value.strip().casefold() in _TRUE
    raise ValueRejectedError(f"{key}: {_shown(value)} is not ON/OFF (or true/false, 1/0)")


def _press_value(key: str, press: bool | int | float | str, value: object) -> object:
    """``press`` (what the button writes) when the command is the press payload ``PRESS``
    (any case); any other value (OFF, false, 0, ...) presses nothing."""
    if isinstance(value, str) and value.strip().casefold() == COMMAND_PRESS.casefold():
        return press
    raise ValueRejectedError(
        f"{key} is a button: only {COMMAND_PRESS} presses it, not {_shown(value)}"
    )


def _shown(value: object, limit: int = 40) -> str:
    """A value as an error message quotes it: repr, cut to ``limit`` characters."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _number(point: Point, value: object, image: Image) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise ValueRejectedError(f"{point.key}: {_shown(value)} is not a number")
    try:
        number = float(value)
    except ValueError:
        raise ValueRejectedError(f"{point.key}: {_shown(value)} is not a number") from None
    except OverflowError:  # an integer beyond any float (JSON allows 1000 digits)
        raise ValueRejectedError(
            f"{point.key}: {_shown(value)} does not fit the register"
        ) from None
    if not math.isfinite(number):
        raise ValueRejectedError(f"{point.key}: {_shown(value)} is not a finite number")
    low, high = limits_of(point, image)
    if (low is not None and number < low) or (high is not None and number > high):
        raise ValueRejectedError(f"{point.key}: {_shown(value)} is outside {low}..{high}")
    return _exact(value, number)


def _exact(value: int | float | str, number: float) -> float:
    """An integer given (or written as digits) as it is, else ``number``: a 64-bit value is
    written to the last unit, not rounded to a float's 53 bits (an int is a float here)."""
    if isinstance(value, int):
        return value
    text = value.strip() if isinstance(value, str) else ""
    if text.lstrip("+-").isdigit() and len(text) <= 40:
        return int(text)
    return number


def _encode_text(entity: Entity, value: object) -> tuple[int, ...]:
    if not isinstance(value, str):
        raise ValueRejectedError(f"{_shown(value)} is not text")
    try:
        data = value.encode("ascii")
    except UnicodeEncodeError:
        raise ValueRejectedError(f"{_shown(value)} is not ASCII text") from None
    size = entity.register_count * 2
    if len(data) > size:
        raise ValueRejectedError(f"{_shown(value)} is longer than {size} characters")
    return _from_bytes(data.ljust(size, b"\x00"), entity.byte_order)


def _ordered(entity: Entity, unsigned: int) -> tuple[int, ...]:
    count = entity.register_count
    if count > 1:
        words = split_words(unsigned, entity.word_order, entity.word_radix, count)
        return _from_bytes(_to_bytes(words, Order.BIG), entity.byte_order)
    return (_swap_bytes(unsigned) if entity.byte_order is Order.LITTLE else unsigned,)


def _register_write(point: Point, words: tuple[int, ...]) -> Write:
    function = point.write_function or (6 if len(words) == 1 else 16)
    return Write(function, point.table, point.write_address, words)


def _toggle_writes(point: Point, state: Point, value: object, image: Image) -> tuple[Write, ...]:
    """A toggle (``toggle_of``): the ON word when the state read (``state``) differs from
    the one asked for, else nothing (a second toggle would undo the first)."""
    wanted = parse_bool(point.key, value)
    if bool(decode(state, image)) == wanted:
        return ()
    if (point.write_function or 5) == 15:
        return (Write(15, Table.COIL, point.write_address, (1,)),)
    return (Write(5, Table.COIL, point.write_address, (point.coil_on_value,)),)


def _coil_writes(point: Point, raw: int) -> tuple[Write, ...]:
    function = point.write_function or 5
    if function == 15:
        return (Write(15, Table.COIL, point.write_address, (raw,)),)
    value = point.coil_on_value if raw else 0
    if point.entity.pulse:
        return (
            Write(5, Table.COIL, point.write_address, (point.coil_on_value,)),
            Write(5, Table.COIL, point.write_address, (0,)),
        )
    return (Write(5, Table.COIL, point.write_address, (value,)),)
