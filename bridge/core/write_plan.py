"""Planning a command's frames (pure: bridge/modbus/writer.py sends them).

What a write reads first, the words a write leaves in the register image, whether an
EEPROM write would change anything, one frame per word when keys share a register (bit
fields), and the frames that undo a compound write half done.
"""

from __future__ import annotations

from bridge.core.entity import Table
from bridge.core.mapping import Point
from bridge.core.request import Read, Write

Address = tuple[Table, int]


def dependencies(point: Point, required: list[Point]) -> list[Read]:
    """What a write of ``point`` must read fresh first: the word of a bit field (even of a
    write-only bit), a sign register, limit registers, an EEPROM parameter's current value,
    the state a toggle flips, the values it ``requires``."""
    entity = point.entity
    linked = (point.sign, point.min_source, point.max_source, point.state_source)
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
    return result


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
