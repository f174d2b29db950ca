"""What a simulated device holds and accepts: pure logic behind ``bridge.modbus.simulator``.

* ``initial_image(mapping, points)``: a plausible register image (status running, alarms
  off, settings inside their limits, limit registers consistent, counters in the thousands);
* ``words_for(point, value, image)``: the words that store ``value`` at the point's READ
  address, whatever its access (a read-only measurement can be set this way);
* ``build_rules(mapping, points, quirks)``: which reads and writes the device answers with
  an exception, and which;
* ``build_movers(points, image)`` / ``advance(movers, image, rng, seconds)``: measurements
  that wander inside their plausible range (``simulation_range``), counters that rise at
  their plausible rate (energy by the simulated power) and values that follow another
  (``simulate: {follows: KEY}``), deterministic for a seeded ``rng``.

One piece, at about 570 lines, for now: the image and the movers share the helpers that
store a value at a point and keep limits consistent (``words_for``, ``number_range``, the
limit roles, who owns a value). The seam, if it grows: the rules (``Quirks``, ``Rules``,
``build_rules``, ``read_limit_code``) share only ``Cell`` and could stand alone.
"""

from __future__ import annotations

import contextlib
import dataclasses
import random
import re
from collections.abc import Mapping as AnyMapping
from dataclasses import dataclass

from bridge.core.address import to_wire
from bridge.core.codec import (
    UNKNOWN_CODE,
    Image,
    Value,
    decode,
    encode,
    is_unknown_code,
    limits_of,
    raw_bounds,
    scale_value,
)
from bridge.core.counters import counter_width
from bridge.core.entity import Access, DataType, Table
from bridge.core.mapping import Mapping, Point
from bridge.core.protocol import Protocol
from bridge.core.request import Write
from bridge.core.simulation_range import COUNTER_CLASSES, energy_source, plausible
from bridge.errors import ValueRejectedError

Cell = tuple[Table, int]

_COUNTER_CLASSES = COUNTER_CLASSES
_SMALL_RAW = 100
_FAULT_WORDS = ("fault", "alarm", "error", "trip", "fail")
_TRUE_WORDS = ("ready", "normal")
_NUMBERED = re.compile(r"^(.*?)_?(\d+)$")
_AS_REGISTER = {  # a read-write copy of an entity, without limits, writing where it reads
    "access": Access.READ_WRITE,
    "press": None,
    "pulse": False,
    "min": None,
    "max": None,
    "write_function": None,
    "write_address": None,
}
_TYPICAL = {  # a setting's value per unit, used when it fits the entity's range (readings:
    # simulation_range)
    "V": 230, "Hz": 50, "A": 12, "W": 1500, "kW": 15, "kvar": 4, "kVA": 16, "°C": 40,
    "%": 50, "rpm": 1480, "kPa": 350, "bar": 3, "s": 10, "min": 30, "h": 120, "Ω": 120,
}  # fmt: skip


@dataclass(frozen=True, slots=True)
class Quirks:
    """How a simulated unit deviates from a well-behaved device (switchable at runtime)."""

    max_read_registers: int | None = None  # None: the mapping's (and its segments') limits
    refuse_gaps: bool | None = None  # None: not protocol.readable_gaps
    refused: frozenset[int] = frozenset()  # holding addresses that answer exception 02
    failing_writes: frozenset[int] = frozenset()  # holding addresses whose writes answer 04
    exception_code: int | None = None  # answer every request with this code
    coil_on_value: int | None = None  # None: protocol.coil_on_value
    latency: float = 0.0  # seconds added before every answer
    write_latency: float = 0.0  # seconds added before answering a write (on top of latency)
    dead: bool = False  # no answer at all
    two_byte_count: bool = False  # RTU FC03 replies carry a 2-byte byte count (P2 F9.05 = 0)
    password: int | None = None  # locked (protocol.unlock) until this is written to unlock
    count_on_read: int | None = None  # counters count one step after each read of this
    # holding address (a counter that rolls over between the reads of its two words)


# --- storing values -------------------------------------------------------------------


def words_for(point: Point, value: object, image: Image) -> dict[Cell, int]:
    """The cells that hold ``value`` at the point's read address (ValueRejectedError if the
    register cannot hold it, e.g. a sentinel). Access, write address and limits are ignored;
    an enum takes a code it has no label for as the codec publishes it (``code_23``)."""
    update: dict[str, object] = dict(_AS_REGISTER)
    enum = point.entity.enum
    if enum is not None and isinstance(value, str) and is_unknown_code(point.entity, value):
        update["enum"] = enum | {int(value.removeprefix(UNKNOWN_CODE)): value}
    entity = point.entity.model_copy(update=update)
    plain = dataclasses.replace(
        point,
        entity=entity,
        write_address=point.address,
        write_function=None,
        min_source=None,
        max_source=None,
    )
    cells: dict[Cell, int] = {}
    for write in encode(plain, value, image):
        cells |= stored_cells(write)
    if point.table is Table.DISCRETE:  # encoded as a coil write: the bit is the input's
        return {(Table.DISCRETE, address): bit for (_, address), bit in cells.items()}
    return cells


def stored_cells(write: Write) -> dict[Cell, int]:
    """What a write leaves in the image: FC05 stores a bit (any non-zero word is ON)."""
    if write.function == 5:
        return {(write.table, write.address): int(write.values[0] != 0)}
    return {(write.table, write.address + i): value for i, value in enumerate(write.values)}


# --- initial values ---------------------------------------------------------------------


def initial_image(mapping: Mapping, points: AnyMapping[str, Point]) -> dict[Cell, int]:
    """Every readable cell of ``points``, holding a plausible value."""
    image = {(p.table, a): 0 for p in points.values() if p.entity.readable for a in p.span}
    roles = _limit_roles(points)
    slots = _slots(points)
    for key, point in points.items():
        if not _owns_value(point, points):
            continue
        value = _initial_value(point, key == mapping.status, roles.get(key, ""))
        if key in slots and point.entity.enum:  # history slots: one past alarm each
            labels = list(point.entity.enum.values())
            value = labels[slots[key] % len(labels)]
        image |= _nearest_storable(point, value, image)
    for _ in range(len(roles) + 1):  # limit chains settle in a few passes
        if not _respect_limits(points, image):
            break
    image |= _alarms_off(points, image)
    for point in points.values():  # a set value in use shows the set value
        followed = (
            points.get(point.entity.simulate.follows or "") if point.entity.simulate else None
        )
        if followed is not None and point.entity.readable:
            image |= _nearest_storable(point, decode(followed, image), image)
    return image


def _alarms_off(points: AnyMapping[str, Point], image: dict[Cell, int]) -> dict[Cell, int]:
    """A healthy device: the words an alarm's ``on_when`` reads hold 0 where a value given
    to another entity on them (a fault word shown as a number) would raise the alarm."""
    cleared: dict[Cell, int] = {}
    for point in points.values():
        when = point.entity.on_when
        if not point.entity.alarm or when is None or decode(point, image) is not True:
            continue
        if (when.min is not None and when.min > 0) or (when.max is not None and when.max < 0):
            cleared |= {(point.table, a): 0 for a in point.span}
    return cleared


def numbered(key: str) -> tuple[str, int] | None:
    """``alarm_history_3`` -> ``("alarm_history", 3)``; None for a key without a number."""
    match = _NUMBERED.match(key)
    return None if match is None else (match.group(1), int(match.group(2)))


def _slots(points: AnyMapping[str, Point]) -> dict[str, int]:
    """Keys of numbered enums sharing their labels (``alarm_history_1``..``_8``): their
    place among them, so that each slot holds another label."""
    families: dict[tuple[str, tuple[str, ...]], list[tuple[int, str]]] = {}
    for key, point in points.items():
        found = numbered(key)
        if found and point.entity.enum and not point.entity.alarm:
            stem, number = found
            labels = tuple(point.entity.enum.values())
            families.setdefault((stem, labels), []).append((number, key))
    slots: dict[str, int] = {}
    for members in families.values():
        if len(members) > 1:
            slots |= {key: index for index, (_, key) in enumerate(sorted(members))}
    return slots


def _owns_value(point: Point, points: AnyMapping[str, Point]) -> bool:
    """False for write-only points, derived booleans, whole words that only show the bit
    fields other points own (those follow from the fields), and a whole value another
    readable value on its registers shows better: a longer one (a u32 over its raw words),
    else an enum (a code's number beside its labels, a raw mode word beside its select),
    else a switch. The register holds one value; the others are views of it."""
    entity = point.entity
    if not entity.readable or entity.on_when is not None:
        return False
    if entity.field_width is not None:
        return True
    order = {key: index for index, key in enumerate(points)}
    rank = _rank(point, order)
    for other in points.values():
        view = other.entity
        if other is point or other.table is not point.table or not view.readable:
            continue
        if view.on_when is not None or not set(point.span) <= set(other.span):
            continue
        if view.field_width is not None:
            if other.span == point.span:
                return False
        elif _rank(other, order) > rank:
            return False
    return True


def _rank(point: Point, order: dict[str, int]) -> tuple[int, int, int]:
    """Which whole value of a register holds it: the longest, then an enum, a switch with
    its words, a boolean, a number; then the first in the mapping."""
    entity = point.entity
    kind = 3 if entity.enum is not None else 2 if entity.words is not None else 0
    kind = kind or (1 if entity.kind == "bool" else 0)
    return len(point.span), kind, -order.get(point.key, 0)


def _limit_roles(points: AnyMapping[str, Point]) -> dict[str, str]:
    """Keys that hold another's limit (``min``, ``max``) or exponent (``scale``: 0, so the
    values it scales read as they are; it never moves)."""
    roles: dict[str, str] = {}
    for point in points.values():
        if point.scale_source is not None:
            roles[point.scale_source.key] = "scale"
        if point.max_source is not None:
            roles[point.max_source.key] = "max"
        if point.min_source is not None:
            roles.setdefault(point.min_source.key, "min")
    return roles


def _initial_value(point: Point, is_status: bool, role: str) -> Value:
    entity = point.entity
    if entity.enum is not None:
        return _initial_label(point, is_status)
    if entity.kind == "text":
        return f"SIM{point.key.upper()}"[: entity.register_count * 2]
    if entity.kind == "bool":
        words = point.key.split("_")
        return not entity.alarm and (is_status or any(word in words for word in _TRUE_WORDS))
    if role == "scale":
        return 0
    low, high = number_range(point)
    value = _plausible_number(point, low, high) * {"min": 0.5, "max": 2.0}.get(role, 1.0)
    return round(min(max(value, low), high), entity.decimals)


def _initial_label(point: Point, is_status: bool) -> Value:
    entity = point.entity
    enum = entity.enum or {}
    if entity.simulate is not None and entity.simulate.state is not None:
        return entity.simulate.state
    if entity.alarm:
        normal = [raw for raw in entity.normal if raw in enum]
        return enum[normal[0]] if normal else entity.normal[0]
    labels = list(enum.values())
    if is_status:
        running = [label for label in labels if "running" in label and "stop" not in label]
        labels = running or labels
    calm = [label for label in labels if not any(word in label for word in _FAULT_WORDS)]
    return (calm or labels)[0]


def number_range(point: Point) -> tuple[float, float]:
    """Engineering range a number can take: its register, narrowed by static min/max and
    by physics (a power factor is within -1..1, or -100..100 %)."""
    entity = point.entity
    if entity.data_type.is_float:  # a half float reaches 65504 only
        low, high = (-6e4, 6e4) if entity.data_type is DataType.F16 else (-1e6, 1e6)
    else:
        ends = [scale_value(entity, raw) for raw in raw_bounds(entity)]
        low, high = min(ends), max(ends)
    if point.sign is not None:
        low = -high
    if entity.ha.device_class == "power_factor":
        bound = 100.0 if entity.unit == "%" else 1.0
        low, high = max(low, -bound), min(high, bound)
    if entity.min is not None:
        low = max(low, entity.min)
    if entity.max is not None:
        high = min(high, entity.max)
    return low, high


def _plausible_number(point: Point, low: float, high: float) -> float:
    entity = point.entity
    found = plausible(point)
    if found is not None:
        return min(max(found.typical, low), high)
    typical = _TYPICAL.get(entity.unit or "")
    if typical is not None and low <= typical <= high:
        return typical
    if entity.min is not None and entity.max is not None:
        return (entity.min + entity.max) / 2
    return min(max(float(scale_value(entity, _SMALL_RAW)), low), high)


def _nearest_storable(point: Point, value: Value, image: Image) -> dict[Cell, int]:
    """``value``, or a neighbour one raw step away when ``value`` is a sentinel."""
    candidates: list[Value] = [value]
    if isinstance(value, int | float) and not isinstance(value, bool):
        step = point.entity.scale
        candidates += [value + step, value - step]
    for candidate in candidates:
        try:
            return words_for(point, candidate, image)
        except ValueRejectedError:
            continue
    return {}


def _respect_limits(points: AnyMapping[str, Point], image: dict[Cell, int]) -> bool:
    """Move values inside their limit registers; True if anything moved."""
    moved = False
    for point in points.values():
        if point.min_source is None and point.max_source is None:
            continue
        value = decode(point, image)
        if not isinstance(value, int | float) or isinstance(value, bool):
            continue
        low, high = limits_of(point, image)
        inside = max(value, low) if low is not None else value
        inside = min(inside, high) if high is not None else inside
        if inside != value:
            image |= _nearest_storable(point, inside, image)
            moved = True
    return moved


# --- what the device accepts --------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Rules:
    """The answers of one simulated unit: ``check_read``/``check_write`` return the
    exception code the device answers with, or None when it serves the request."""

    function_codes: frozenset[int]
    readable: frozenset[Cell]
    writable: frozenset[Cell]
    commands: frozenset[int]  # coil addresses that are commands: writes leave the bit alone
    forbidden: tuple[tuple[Table, int, int], ...]  # reserved and refused ranges
    segments: tuple[tuple[Table, int, int, int | None], ...]
    max_read: int
    max_bits: int
    max_write: int
    limit_code: int
    refuse_gaps: bool
    coil_on_value: int
    fixed_limit: bool  # a quirk set the read limit: segments' own limits do not apply
    failing_writes: frozenset[int] = frozenset()  # holding writes answered "device failure"
    toggles: tuple[tuple[int, Cell], ...] = ()  # toggle coil -> the state cell an ON flips
    # (table, write address, read address, count): a set point written at one address and
    # read back at another (ABB Terra AC: written at 4100h, applied at 4022h)
    echoes: tuple[tuple[Table, int, int, int], ...] = ()

    def echoed(self, write: Write) -> dict[Cell, int]:
        """The read-back cells a write to a separate write address sets too."""
        found: dict[Cell, int] = {}
        for table, at, read, count in self.echoes:
            if table is write.table and write.address <= at < write.address + len(write.values):
                offset = at - write.address
                words = write.values[offset : offset + count]
                found |= {(table, read + i): int(word) for i, word in enumerate(words)}
        return found

    def toggled(self, write: Write, image: Image) -> dict[Cell, int]:
        """What a toggle write changes (``toggle_of``: the breaker closes or opens)."""
        if write.table is not Table.COIL or not write.values or write.values[0] == 0:
            return {}
        return {
            cell: 1 - image.get(cell, 0) for coil, cell in self.toggles if coil == write.address
        }

    def check_read(self, table: Table, address: int, count: int) -> int | None:
        last = address + count - 1
        if count > self._read_limit(table, address):
            return self.limit_code
        if self._forbidden(table, address, last) or self._crosses_segment(table, address, last):
            return 2
        if self.refuse_gaps and any(
            (table, a) not in self.readable for a in range(address, last + 1)
        ):
            return 2
        return None

    def check_write(self, write: Write) -> int | None:
        count = len(write.values)
        last = write.address + count - 1
        if write.function in (15, 16) and count > self.max_write:
            return 3
        if self._forbidden(write.table, write.address, last):
            return 2
        if any((write.table, a) not in self.writable for a in range(write.address, last + 1)):
            return 2
        if write.function == 5 and write.values[0] not in (0, self.coil_on_value):
            return 3
        if write.table is Table.HOLDING and self.failing_writes.intersection(
            range(write.address, last + 1)
        ):
            return 4
        return None

    def _read_limit(self, table: Table, first: int) -> int:
        limit = self.max_bits if table.is_bits else self.max_read
        if self.fixed_limit:
            return limit
        for seg_table, low, high, seg_max in self.segments:
            if seg_table is table and low <= first <= high and seg_max is not None:
                limit = min(limit, seg_max)
        return limit

    def _forbidden(self, table: Table, first: int, last: int) -> bool:
        return any(t is table and first <= high and low <= last for t, low, high in self.forbidden)

    def _crosses_segment(self, table: Table, first: int, last: int) -> bool:
        return any(
            t is table and (low <= first <= high) != (low <= last <= high)
            for t, low, high, _ in self.segments
        )


def build_rules(mapping: Mapping, points: AnyMapping[str, Point], quirks: Quirks) -> Rules:
    protocol = mapping.protocol
    rule = protocol.addressing
    readable = {(p.table, a) for p in points.values() if p.entity.readable for a in p.span}
    writers = [p for p in points.values() if p.entity.writable]
    writable = {
        (p.table, a) for p in writers for a in range(p.write_address, p.write_address + p.count)
    }
    reserved = [
        (r.table, to_wire(r.start, rule), to_wire(r.end or r.start, rule))
        for r in protocol.reserved
    ]
    refused = [(Table.HOLDING, a, a) for a in sorted(quirks.refused)]
    segments = tuple(
        (s.table, to_wire(s.start, rule), to_wire(s.end, rule), s.max_read_registers)
        for s in protocol.segments
    )
    coils = [p for p in writers if p.table is Table.COIL]
    commands = {p.write_address for p in coils if p.entity.access is Access.WRITE}
    commands -= {p.write_address for p in coils if p.entity.readable}
    gaps = protocol.readable_gaps if quirks.refuse_gaps is None else not quirks.refuse_gaps
    on_value = protocol.coil_on_value if quirks.coil_on_value is None else quirks.coil_on_value
    return Rules(
        function_codes=frozenset(protocol.function_codes),
        readable=frozenset(readable),
        writable=frozenset(writable),
        commands=frozenset(commands),
        forbidden=tuple(reserved + refused),
        segments=segments,
        max_read=quirks.max_read_registers or protocol.max_read_registers,
        max_bits=protocol.max_read_bits,
        max_write=protocol.max_write_registers,
        limit_code=read_limit_code(protocol),
        refuse_gaps=not gaps,
        coil_on_value=on_value,
        fixed_limit=quirks.max_read_registers is not None,
        failing_writes=quirks.failing_writes,
        toggles=tuple(
            (p.write_address, (p.state_source.table, p.state_source.address))
            for p in writers
            if p.state_source is not None
        ),
        echoes=tuple(
            (p.table, p.write_address, p.address, p.count)
            for p in writers
            if p.entity.readable and p.write_address != p.address and p.table is not Table.COIL
        ),
    )


def read_limit_code(protocol: Protocol) -> int:
    """The exception a read above the limit gets: a declared code whose name is about the
    register count (the soft starter's 03), else 02 (illegal data address)."""
    for code, meaning in sorted(protocol.exceptions.items()):
        if "count" in meaning.name.lower():
            return code
    return 2


# --- values that move ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Mover:
    """A read-only number that changes over time: a measurement, a counter, or a value
    that shows another (``follows``)."""

    point: Point
    low: float
    high: float
    step: int  # largest move per tick, in raw units
    counter: bool
    per_hour: float = 0.0  # a counter's rise per hour (times the rate source's value)
    rate_source: Point | None = None  # an energy counter's power
    follows: Point | None = None


def build_movers(points: AnyMapping[str, Point], image: Image) -> tuple[Mover, ...]:
    """Measurements (state_class measurement), counters (total, total_increasing) and the
    values that follow another."""
    sources = set(_limit_roles(points))
    movers: list[Mover] = []
    for key, point in points.items():
        entity = point.entity
        state = entity.ha.state_class
        followed = points.get(entity.simulate.follows or "") if entity.simulate else None
        if followed is not None and entity.readable and _owns_value(point, points):
            movers.append(Mover(point, 0, 0, 0, counter=False, follows=followed))
            continue
        if (
            entity.access is not Access.READ
            or entity.kind != "number"
            or entity.field_width is not None
            or point.sign is not None
            or key in sources
            or state not in ("measurement", "measurement_angle", *_COUNTER_CLASSES)
            or not _owns_value(point, points)
        ):
            continue
        value = decode(point, image)
        if not isinstance(value, int | float) or isinstance(value, bool):
            continue
        movers.append(_mover(point, value, points))
    return tuple(movers)


def _mover(point: Point, value: float, points: AnyMapping[str, Point]) -> Mover:
    entity = point.entity
    low, high = number_range(point)
    found = plausible(point)
    if entity.ha.state_class in _COUNTER_CLASSES:
        source = energy_source(point, points)
        rate, factor = (source[0], source[1]) if source else (None, 1.0)
        per_hour = factor if rate is not None else (found.per_hour if found else 1.0)
        return Mover(point, low, high, 1, True, per_hour, rate)
    if found is not None:
        low, high = max(low, min(found.low, value)), min(high, max(found.high, value))
    else:
        spread = max(abs(value) * 0.2, abs(entity.scale) * 10)
        low, high = max(low, value - spread), min(high, value + spread)
    step = max(1, round((high - low) / abs(entity.scale) / 20))
    return Mover(point, low, high, step, False)


def advance(
    movers: tuple[Mover, ...], image: Image, rng: random.Random, seconds: float = 1.0
) -> dict[Cell, int]:
    """One tick of ``seconds``: the cells that change. Sentinels are skipped, ranges held;
    a counter rises by its rate, whole raw steps, the fraction by chance (never falls); a
    float counter by the exact amount (a meter's kWh float rises by 0.004 kWh in 10 s)."""
    changes: dict[Cell, int] = {}
    for mover in movers:
        value = decode(mover.point, image)
        if not isinstance(value, int | float) or isinstance(value, bool):
            continue
        scale = mover.point.entity.scale
        if mover.follows is not None:
            target: Value = decode(mover.follows, {**image, **changes})
        elif mover.counter:
            steps = _rate(mover, image) * seconds / 3600 / abs(scale)
            whole = steps if mover.point.entity.data_type.is_float else int(steps)
            target = value + (whole + (rng.random() < steps - whole)) * abs(scale)
        else:
            target = min(
                max(value + rng.randint(-mover.step, mover.step) * scale, mover.low), mover.high
            )
        if target == value or target is None:
            continue
        try:
            changes |= words_for(mover.point, target, image)
        except ValueRejectedError:
            changes |= _rolled_over(mover, target, image)
    return changes


def _rolled_over(mover: Mover, target: Value, image: Image) -> dict[Cell, int]:
    """A counter past its width starts again from 0, as a device's does; nothing else
    moves past what its register holds."""
    width = counter_width(mover.point) if mover.counter else None
    if width is None or not isinstance(target, int | float):
        return {}
    with contextlib.suppress(ValueRejectedError):
        return words_for(mover.point, target - width * abs(mover.point.entity.scale), image)
    return {}


def count_once(movers: tuple[Mover, ...], image: Image) -> dict[Cell, int]:
    """Every counter one raw step up (``Quirks.count_on_read``)."""
    changes: dict[Cell, int] = {}
    for mover in movers:
        value = decode(mover.point, image)
        if mover.counter and isinstance(value, int | float) and not isinstance(value, bool):
            with contextlib.suppress(ValueRejectedError):
                changes |= words_for(mover.point, value + abs(mover.point.entity.scale), image)
    return changes


def _rate(mover: Mover, image: Image) -> float:
    """A counter's rise per hour now: its rate, times its power source's reading."""
    if mover.rate_source is None:
        return mover.per_hour
    power = decode(mover.rate_source, image)
    if not isinstance(power, int | float) or isinstance(power, bool):
        return 0.0
    return max(float(power), 0.0) * mover.per_hour
