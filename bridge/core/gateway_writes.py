"""What a gateway master's write of words means as a command. Pure.

``items_of(points, image, request)`` turns the words an FC05/06/15/16 writes into the
values of the writable entities they cover, so the write runs as an MQTT command would
(every check of the writer); or None when no word is an entity's (a raw write, which the
gateway allows only under the rule of raw writes). Words that mean no value the entity is
set to by exactly those words, an entity written in part, a toggle or pulse, a button's
register with another word, and entity words mixed with raw ones raise
``GatewayRefusalError`` with the exception code to answer; nothing is written then. On a
register several writable entities share, every entity that takes the words is written
(the writer sends the word once); one that does not take them is left out if another
does.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from bridge.core.codec import COMMAND_PRESS, Value, decode, encode
from bridge.core.entity import Table
from bridge.core.gateway import Code, ProxyRequest
from bridge.core.mapping import Point
from bridge.core.request import Write
from bridge.errors import BridgeError

Cell = tuple[Table, int]


class GatewayRefusalError(BridgeError):
    """A request the gateway refuses itself, with the exception code it answers."""

    def __init__(self, code: Code, reason: str) -> None:
        super().__init__(reason)
        self.code = code


def items_of(
    points: Iterable[Point], image: Mapping[Cell, int], request: ProxyRequest
) -> dict[str, object] | None:
    """The command a write of words amounts to: each writable entity whose words it writes,
    with the value those words mean; None when no word is a writable entity's (a raw write).

    A register several writable entities share (a raw word, a select, a switch with its
    words): every entity that takes the words as a value of its own is in the command, so
    every one's checks apply (range, guard, conditions) and the writer sends the word
    once; one that reads them as no value of its own (a switch, for a mode word that is
    neither its on nor its off) is left out, while another takes them. GatewayRefusalError:
    0x03 for an entity written in part that no entity covers whole, a command word no
    button sends, words no entity of the register takes (``_value``); 0x01 for a toggle or
    pulse, and for entities written with words no entity covers (raw, they would skip the
    checks)."""
    table = request.table
    cells: dict[Cell, int] = {(table, request.address + i): v for i, v in enumerate(request.values)}
    points = tuple(points)
    taken = _taken(points, cells, image)
    items, covered, buttons, declined = taken.items, taken.covered, taken.buttons, taken.declined
    for hit, refused in declined:  # taken by none of the entities sharing its registers
        if not hit <= covered:
            raise refused
    missing = set(cells) - covered
    if missing & buttons:
        raise GatewayRefusalError(
            Code.ILLEGAL_VALUE, "no command of this register writes that word"
        )
    _check_kept_bits([p for p in points if p.key in items], cells, covered, image)
    if missing and covered:  # raw, they would skip the entities' checks (range, spacing)
        raise GatewayRefusalError(
            Code.ILLEGAL_FUNCTION,
            f"{', '.join(items)} written with registers no writable entity covers: write "
            "them on their own",
        )
    return None if missing else items


@dataclass(slots=True)
class _Taken:
    """What the writable entities a request hits make of its words."""

    items: dict[str, object] = field(default_factory=dict)  # key -> the value its words mean
    covered: set[Cell] = field(default_factory=set)  # cells of the entities in ``items``
    buttons: set[Cell] = field(default_factory=set)  # cells of the buttons hit
    declined: list[tuple[set[Cell], GatewayRefusalError]] = field(default_factory=list)


def _taken(points: tuple[Point, ...], cells: dict[Cell, int], image: Mapping[Cell, int]) -> _Taken:
    """Each writable entity the words hit: its value, or why it does not take them (written
    in part, no value of its own); a toggle or pulse refuses the request (0x01)."""
    taken = _Taken()
    for point in points:
        entity = point.entity
        space = Table.COIL if point.table is Table.COIL else Table.HOLDING
        mine = [(space, point.write_address + i) for i in range(point.count)]
        hit = {c for c in mine if c in cells}
        if not entity.writable or not hit:
            continue
        if len(hit) != len(mine):
            part = f"{point.key}: write its {len(mine)} registers at once"
            taken.declined.append((hit, GatewayRefusalError(Code.ILLEGAL_VALUE, part)))
            continue
        if point.state_source is not None or entity.pulse:
            raise GatewayRefusalError(
                Code.ILLEGAL_FUNCTION, f"{point.key}: a toggle or pulse; use MQTT"
            )
        words = tuple(cells[c] for c in mine)
        if entity.press is not None:
            taken.buttons |= set(mine)
            if _presses(point, words, image):
                taken.items[point.key] = COMMAND_PRESS
                taken.covered |= set(mine)
            continue
        try:
            taken.items[point.key] = _value(point, words, image)
        except GatewayRefusalError as refusal:
            taken.declined.append((hit, refusal))
            continue
        taken.covered |= set(mine)
    return taken


def _check_kept_bits(
    points: Iterable[Point], cells: dict[Cell, int], covered: set[Cell], image: Mapping[Cell, int]
) -> None:
    """A register whose writable entities are bit fields: the writer writes their bits
    and keeps the device's others. 0x03 unless the master sent those others as the bridge
    last read them, so a write never answers success for bits that were not written."""
    masks: dict[Cell, int] = {}
    for point in points:
        entity = point.entity
        if not entity.writable or point.table.is_bits:
            continue
        width = entity.field_width
        mask = 0xFFFF if width is None else ((1 << width) - 1) << (entity.bit or 0)
        for offset in range(point.count):
            cell = (Table.HOLDING, point.write_address + offset)
            if cell in covered:
                masks[cell] = masks.get(cell, 0) | mask
    for cell, mask in masks.items():
        kept = ~mask & 0xFFFF
        held = image.get(cell)
        if kept and (held is None or (cells[cell] ^ held) & kept):
            shown = "not read yet" if held is None else f"{held & kept:#06x}"
            raise GatewayRefusalError(
                Code.ILLEGAL_VALUE,
                f"register {cell[1]}: bits {kept:#06x} are no entity's; the device keeps "
                f"them ({shown}): send them as it holds them",
            )


def _presses(point: Point, words: tuple[int, ...], image: Mapping[Cell, int]) -> bool:
    try:
        writes = encode(point, COMMAND_PRESS, image)
    except BridgeError:
        return False
    return len(writes) == 1 and writes[0].values == words


def _value(point: Point, words: tuple[int, ...], image: Mapping[Cell, int]) -> Value:
    """What ``words`` written at the entity's write address mean, read as the entity.

    GatewayRefusalError (0x03) unless they mean a value the entity is set to by exactly
    these words: never a sentinel or a NaN (no value), an enum code without a label, a
    register the value needs that was not read yet, or words the bridge would write
    otherwise (7 to an on/off register, digits beyond the entity's precision). Nothing of
    the request is written then."""
    seen = dict(image)
    for offset, word in enumerate(words):
        seen[(point.table, point.address + offset)] = word
    try:
        value = decode(point, seen)
        writes = encode(point, value, seen)
    except BridgeError as error:
        raise GatewayRefusalError(
            Code.ILLEGAL_VALUE, f"{point.key}: {list(words)} is no value it takes ({error})"
        ) from None
    written = {cell: word for w in writes for cell, word in _cells_of(w).items()}
    space = Table.COIL if point.table is Table.COIL else Table.HOLDING
    wanted = {(space, point.write_address + i): word for i, word in enumerate(words)}
    if written != wanted:
        raise GatewayRefusalError(
            Code.ILLEGAL_VALUE,
            f"{point.key}: {list(words)} reads as {value!r}, which the bridge writes as "
            f"{sorted(written.values())}",
        )
    return value


def _cells_of(write: Write) -> dict[Cell, int]:
    """The cells a write sets, coils as 0/1 (FC05 sends its ON word)."""
    values = write.values
    if write.function == 5:
        values = (1 if values[0] else 0,)
    return {(write.table, write.address + i): v for i, v in enumerate(values)}
