"""Which entities may share registers: the overlap checks of a mapping. Pure.

Any number of entities may share registers, as Home Assistant lets a sensor,
a switch and a select share one word: a raw value, a scaled reading, an enum (select),
a switch with its ``words``, bit fields, derived booleans, a u32 and its raw words. They
are views of the one value the device holds: one read serves them all (the planner
merges them into one atom), each decodes the image its own way. Each value takes a
*footprint*, its cells with the bits of each (a whole register all 16, a field its own).
What is refused is only what contradicts itself:

- readers whose footprints cross (share bits, neither inside the other): a u32 starting
  inside another value's registers, bit fields 0-3 and 2-5. The planner could read them
  (one atom of three registers, never torn), but no manual lays out two values sharing
  half their registers: it is the classic off-by-one, caught here rather than published;
  an imported package that has one gets it reported by name;
- a secret beside a published reader of its register (the reader would publish it);
- writers (at their write address) whose footprints cross: a write of one would change
  part of the other's value;
- two selects on the same register(s) that write one option as different codes, and two
  switches that read the same words as on and off but write different ones (the same
  state, two ways to write it).

Different words for different meanings are fine (a "force charge" switch writing 1 and a
"force discharge" switch writing 2 on one mode register, each reading the other's word
as neither on nor off). What a command asks of several entities of one register at once
is checked when it is written (``write_plan.contradictions``).

How the rest treats a shared register: a command's keys that ask it for different words
are refused whole and one read back publishes every view (``write_plan``, the writer);
the guard follows the register, not the entity (``guard``: a harmless writer beside a
dangerous one writes only the words harmless buttons and switches there declare); a
gateway master's words are a command of every entity that takes them
(``gateway_writes``); the simulator holds one value per register (``simulation``).
docs/mappings.md, "Many entities on one register", says it for mapping authors.

Rows are ``entities.<key>.<field>: message``; ``checks.check_mapping`` runs them once the
addresses and options are valid.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from collections.abc import Mapping as AnyMapping
from dataclasses import dataclass

from bridge.core.address import to_wire
from bridge.core.entity import Entity, Table
from bridge.core.protocol import OptionSpec, Protocol
from bridge.core.variant import option_combinations, when_matches

Cell = tuple[Table, int]
Footprint = dict[Cell, int]  # cell -> the bits of it a value takes
WHOLE = 0xFFFF


@dataclass(frozen=True, slots=True)
class _Parts:
    protocol: Protocol
    options: AnyMapping[str, OptionSpec]
    entities: AnyMapping[str, Entity]


def overlap_problems(
    protocol: Protocol, options: AnyMapping[str, OptionSpec], entities: AnyMapping[str, Entity]
) -> Iterator[str]:
    """Every overlap problem of a mapping's entities, for any option combination, once."""
    mapping = _Parts(protocol, options, entities)
    seen: set[str] = set()
    for chosen in option_combinations(mapping.options):
        for row in _overlaps_for(mapping, chosen):
            if row not in seen:
                seen.add(row)
                yield row


def _overlaps_for(mapping: _Parts, chosen: dict[str, str]) -> Iterator[str]:
    rule = mapping.protocol.addressing
    present = {k: e for k, e in mapping.entities.items() if when_matches(e.when, chosen)}
    owners: dict[Cell, list[tuple[str, Entity, int]]] = {}
    reads: dict[str, Footprint] = {}
    writes: dict[str, Footprint] = {}
    for key, e in present.items():
        if e.writable:
            writes[key] = footprint(e, to_wire(e.write_address or e.address, rule))
        if not e.readable:
            continue
        start = to_wire(e.address, rule)
        reads[key] = footprint(e, start)
        for offset in range(e.register_count):
            owners.setdefault((e.table, start + offset), []).append((key, e, start))
    yield from _reserved_hits(mapping, owners)
    yield from _segment_crossings(mapping, owners)
    for k1, k2, (table, address) in _sharing(reads):
        where = f"{table.value} {address}"
        problem = _read_clash(k1, present[k1], reads[k1], present[k2], reads[k2])
        if problem:
            yield f"entities.{k2}.address: {problem} ({where})"
    for k1, k2, (table, address) in _sharing(writes):
        where = f"{table.value} {address}"
        found = _write_clash(k1, present[k1], writes[k1], present[k2], writes[k2])
        if found and found[0] == "address" and all(reads.get(k) == writes[k] for k in (k1, k2)):
            continue  # written where read: the readers' row says it
        if found:
            yield f"entities.{k2}.{found[0]}: {found[1]} ({where})"


def footprint(e: Entity, start: int) -> Footprint:
    """The cells of a value starting at wire ``start``, each with the bits it takes (all
    16 of a whole register, a field's own, 1 for a coil or discrete input)."""
    if e.table.is_bits:
        bits = 1
    elif e.field_width is None:
        bits = WHOLE
    else:
        bits = ((1 << e.field_width) - 1) << (e.bit or 0)
    return {(e.table, start + offset): bits for offset in range(e.register_count)}


def nested(inner: Footprint, outer: Footprint) -> bool:
    """Every bit of ``inner`` is one of ``outer``'s (a word inside a u32, a bit inside a
    nibble field, the same register twice)."""
    return all(cell in outer and not bits & ~outer[cell] for cell, bits in inner.items())


def _sharing(footprints: dict[str, Footprint]) -> Iterator[tuple[str, str, Cell]]:
    """Each pair of values that share a bit, in mapping order, with the first cell they
    share."""
    by_cell: dict[Cell, list[str]] = {}
    for key, cells in footprints.items():
        for cell in cells:
            by_cell.setdefault(cell, []).append(key)
    order = {key: index for index, key in enumerate(footprints)}
    pairs: dict[tuple[str, str], Cell] = {}
    for cell, keys in sorted(by_cell.items()):
        for k1, k2 in itertools.combinations(keys, 2):
            if footprints[k1][cell] & footprints[k2][cell]:
                pairs.setdefault((k1, k2), cell)
    for (k1, k2), cell in sorted(pairs.items(), key=lambda item: order[item[0][1]]):
        yield k1, k2, cell


def _crossing(k1: str, f1: Footprint, f2: Footprint) -> str | None:
    """Why two values that share bits make no sense together: neither holds the other."""
    if nested(f1, f2) or nested(f2, f1):
        return None
    if f1.keys() <= f2.keys() or f2.keys() <= f1.keys():
        return f"overlapping bit fields: shares bits with {k1!r}, neither inside the other"
    return f"starts inside {k1!r} and ends past it (an off-by-one? a u32 takes two addresses)"


def _read_clash(k1: str, e1: Entity, f1: Footprint, e2: Entity, f2: Footprint) -> str | None:
    """Two readable values on shared bits: views of one value (a raw word, its bits, a
    switch, an enum, a scaled reading, a u32 and its words) unless their spans cross, or
    one is secret (the other would publish it)."""
    if e1.secret and not e2.secret:
        return f"reads the register of secret {k1!r}: it would publish the secret"
    if e2.secret and not e1.secret:
        return f"a secret on a register {k1!r} reads: it would publish the secret"
    return _crossing(k1, f1, f2)


def _write_clash(
    k1: str, e1: Entity, f1: Footprint, e2: Entity, f2: Footprint
) -> tuple[str, str] | None:
    """Two writers of shared bits that contradict each other: (field, why). One writes
    part of the other's value; two selects write one option as different codes; two
    switches read the same words as on and off and write different ones."""
    crossing = _crossing(k1, f1, f2)
    if crossing:
        return "address", f"written across the writes of {k1!r}: {crossing}"
    if f1 != f2:
        return None
    if e1.enum is not None and e2.enum is not None and e1.press is None and e2.press is None:
        codes = {label: code for code, label in e1.enum.items()}
        for code, label in e2.enum.items():
            if codes.get(label, code) != code:
                return "enum", f"option {label!r} written as {code}, as {codes[label]} by {k1!r}"
    w1, w2 = e1.words, e2.words
    if (
        w1 is not None
        and w2 is not None
        and (set(w1.on_words), set(w1.off_words)) == (set(w2.on_words), set(w2.off_words))
        and (w1.write_on, w1.write_off) != (w2.write_on, w2.write_off)
    ):
        return "words", (
            f"writes {w2.write_on}/{w2.write_off} for on/off, {k1!r} "
            f"{w1.write_on}/{w1.write_off} for the same words read"
        )
    return None


def _reserved_hits(
    mapping: _Parts, owners: dict[tuple[Table, int], list[tuple[str, Entity, int]]]
) -> Iterator[str]:
    rule = mapping.protocol.addressing
    for r in mapping.protocol.reserved:
        start, end = to_wire(r.start, rule), to_wire(r.end or r.start, rule)
        for address in range(start, end + 1):
            for key, _, _ in owners.get((r.table, address), []):
                yield f"entities.{key}.address: reads reserved {r.table.value} {address}"


def _segment_crossings(
    mapping: _Parts, owners: dict[tuple[Table, int], list[tuple[str, Entity, int]]]
) -> Iterator[str]:
    rule = mapping.protocol.addressing
    bounds = [
        (s.table, to_wire(s.start, rule), to_wire(s.end, rule)) for s in mapping.protocol.segments
    ]
    for (table, address), items in owners.items():
        for key, e, start in items:
            if address != start:
                continue
            last = start + e.register_count - 1
            for seg_table, low, high in bounds:
                if seg_table is table and (low <= start <= high) != (low <= last <= high):
                    yield f"entities.{key}.address: the value crosses a segment boundary"
