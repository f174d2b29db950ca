"""Planning a command's frames (pure: bridge/modbus/writer.py sends them).

What a write reads first, the words a write leaves in the register image, whether an
EEPROM write would change anything, the keys of one command that contradict each other,
one frame per word when keys share a register (bit fields, or a switch and the raw word
of its register), and the frames that undo a compound write half done.
"""

from __future__ import annotations

from bridge.core.entity import Table
from bridge.core.mapping import Point
from bridge.core.request import Read, Write

Address = tuple[Table, int]


def dependencies(point: Point, required: list[Point]) -> list[Read]:
    """What a write of ``point`` must read fresh first: the word of a bit field (even of a
    write-only bit), a sign register, limit registers, an EEPROM parameter's current value,
    the state a toggle flips, the values it ``requires``, the exponent of a ``scale_by``
    value (encoded with the device's exponent of now)."""
    entity = point.entity
    linked = (
        point.sign,
        point.min_source,
        point.max_source,
        point.state_source,
        point.scale_source,
    )
    sources = [p for p in linked if p is not None] + required
    reads = [Read(p.table, p.address, p.count) for p in sources]
    if entity.field_width is not None or (entity.eeprom and entity.readable):
        reads.append(Read(point.table, point.address, point.count))
    return list(dict.fromkeys(reads))


def stored(write: Write) -> dict[Address, int]:
    """The words a register write leaves in the image; coil commands leave nothing (they
    may live in another space than the status bits)."""
    if write.function in (5, 15):
        return {}
    return {(write.table, write.address + i): word for i, word in enumerate(write.values)}


def unchanged(point: Point, writes: tuple[Write, ...], image: dict[Address, int]) -> bool:
    """The device already holds what these writes would put there (EEPROM skip)."""
    return (
        point.write_address == point.address
        and all(image.get(cell) == word for w in writes for cell, word in stored(w).items())
        and all(w.function not in (5, 15) for w in writes)
    )


def contradictions(points: list[Point], encoded: dict[str, tuple[Write, ...]]) -> dict[str, str]:
    """The keys of one command that ask for other bits than a key before them asks of the
    same register or coil (a switch ON and the raw word 0 of its register; two bit fields
    agree where they do not overlap): key -> why. ``encoded``: each key's writes, encoded
    over what the keys before it leave."""
    claimed: dict[Address, tuple[int, int, str]] = {}  # cell -> bits set, their value, by
    refused: dict[str, str] = {}
    for point in points:
        mask = _mask(point)
        final: dict[Address, int] = {}
        for write in encoded.get(point.key, ()):
            final |= _cells(write)  # a pulse: what it leaves
        clash = next(
            (
                (cell, by)
                for cell, word in final.items()
                for bits, value, by in [claimed.get(cell, (0, 0, ""))]
                if (word ^ value) & bits & mask
            ),
            None,
        )
        if clash is not None:
            (table, address), by = clash
            refused[point.key] = (
                f"{point.key} asks {table.value} {address} for another value than {by} in the "
                "same command: send one of them"
            )
            continue
        for cell, word in final.items():
            bits, value, by = claimed.get(cell, (0, 0, point.key))
            claimed[cell] = (bits | mask, (value & ~mask) | (word & mask), point.key)
    return refused


def _mask(point: Point) -> int:
    """The bits of each written cell that are the point's own."""
    width = point.entity.field_width
    if point.table.is_bits:
        return 1
    return 0xFFFF if width is None else ((1 << width) - 1) << (point.entity.bit or 0)


def _cells(write: Write) -> dict[Address, int]:
    """The cells a write sets, coils as 0/1 (FC05 sends the device's ON word)."""
    values = write.values
    if write.function == 5:
        values = (int(values[0] != 0),)
    return {(write.table, write.address + i): v for i, v in enumerate(values)}


def frames_of(plan: dict[str, tuple[Write, ...]], pulses: set[str]) -> list[Write]:
    """The frames of a command in key order. Where several keys write the same register
    (bit fields of one word), the word goes out once, at the first key's place, holding
    every key's bits (each key was encoded over the word the keys before it left): one
    EEPROM write, not several. Registers a pulse writes keep every frame."""
    frames = [(key, w) for key, writes in plan.items() for w in writes]
    pulsed = {(w.table, w.address) for key, w in frames if key in pulses}
    final: dict[tuple[Table, int, int], Write] = {}
    for key, w in frames:
        if key not in pulses and w.function in (6, 16) and (w.table, w.address) not in pulsed:
            final[(w.table, w.address, len(w.values))] = w
    result: list[Write] = []
    sent: set[tuple[Table, int, int]] = set()
    for key, w in frames:
        place = (w.table, w.address, len(w.values))
        if key in pulses or place not in final:
            result.append(w)
        elif place not in sent:
            sent.add(place)
            result.append(final[place])
    kept = list(final.values())  # not a pulse's: a pulse keeps every frame
    mergeable = {id(w) for w in kept}
    return [w for w in result if id(w) not in mergeable or not any(_inside(w, o) for o in kept)]


def _inside(write: Write, other: Write) -> bool:
    """``write`` sets a part of the registers ``other`` (a longer frame of the same
    command) sets: a u32's raw word beside the u32. Keys that contradict each other are
    refused before (``contradictions``), so the longer frame holds the same words."""
    return (
        write.function in (6, 16)
        and other.function in (6, 16)
        and write.table is other.table
        and len(write.values) < len(other.values)
        and other.address <= write.address
        and write.address + len(write.values) <= other.address + len(other.values)
    )


def undo_of(writes: list[Write], image: dict[Address, int]) -> tuple[Write | None, ...]:
    """For each write, the write that puts back what the device held before it (as far
    as the image knows; None where it does not: a write-only command register, a coil
    command). Writes earlier in the list are taken into account."""
    before = dict(image)
    undo: list[Write | None] = []
    for write in writes:
        cells = [(write.table, write.address + i) for i in range(len(write.values))]
        if write.function in (5, 15) or any(cell not in before for cell in cells):
            undo.append(None)
        else:
            old = tuple(before[cell] for cell in cells)
            undo.append(Write(write.function, write.table, write.address, old))
        before |= stored(write)
    return tuple(undo)
