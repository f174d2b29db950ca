"""Whole-mapping checks: keys, addresses, references, options, function codes, overlaps;
apart, the presentation conventions (``convention``: names, manufacturer, enabled
defaults), which are warnings for a user's mapping.

Each check returns rows ``entities.<key>.<field>: message``; ``check_mapping`` runs them all
so a user sees every problem of a file at once. The checks read the parts of a mapping
they need (``MappingParts``), not the model: ``mapping.Mapping`` runs them when it
validates, so it sits above this module.

Overlaps: any number of entities may share registers, as Home Assistant lets a sensor,
a switch and a select share one word: a raw value, a scaled reading, an enum (select),
a switch with its ``words``, bit fields, derived booleans, a u32 and its raw words. They
are views of the one value the device holds: one read serves them all (the planner
merges them into one atom), each decodes the image its own way. Each value takes a
*footprint*, its cells with the bits of each (a whole register all 16, a field its own).
What is refused is only what contradicts itself:

- readers whose footprints cross (share bits, neither inside the other): a u32 starting
  inside another value's registers (the classic off-by-one), bit fields 0-3 and 2-5;
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
"""

from __future__ import annotations

import itertools
import re
import typing
from collections.abc import Iterator
from collections.abc import Mapping as AnyMapping

from pydantic import ValidationError

from bridge.core.address import to_wire
from bridge.core.convention import convention_problems
from bridge.core.entity import DataType, Entity, StateLink, Table
from bridge.core.hass import presentation_problems
from bridge.core.protocol import OptionSpec, Protocol, write_function
from bridge.core.variant import option_combinations, when_matches

KEY_PATTERN = re.compile(r"^[a-z][a-z0-9_]*$")
RESERVED_KEYS = frozenset(
    {"status", "alarms", "availability", "set", "get", "error", "event", "last_reset"}
)
Cell = tuple[Table, int]
Footprint = dict[Cell, int]  # cell -> the bits of it a value takes
WHOLE = 0xFFFF
_UNSIGNED_MAX = {DataType.U32: 0xFFFFFFFF, DataType.S32: 0xFFFFFFFF, DataType.F32: 0xFFFFFFFF}


class MappingParts(typing.Protocol):
    """What the checks read of a mapping (``mapping.Mapping`` has all of it)."""

    @property
    def manufacturer(self) -> str: ...
    @property
    def protocol(self) -> Protocol: ...
    @property
    def options(self) -> AnyMapping[str, OptionSpec]: ...
    @property
    def status(self) -> str | None: ...
    @property
    def entities(self) -> AnyMapping[str, Entity]: ...


def check_mapping(mapping: MappingParts) -> list[str]:
    """Every cross-entity problem of ``mapping``, as ``location: message`` rows."""
    basis = [*_addresses(mapping), *_options(mapping)]
    rows = [*_keys(mapping), *basis]
    for check in (_references, _function_codes, _sentinels, _presentation):
        rows.extend(check(mapping))
    if not basis:  # overlap checks need valid addresses and options, nothing else
        rows.extend(_overlaps(mapping))
    if mapping.status is not None and mapping.status not in mapping.entities:
        rows.append(f"status: no entity {mapping.status!r}")
    return rows


def check_conventions(mapping: MappingParts) -> list[str]:
    """The presentation conventions (``convention``) ``mapping`` breaks: errors for the
    shipped mappings (their tests), warnings for a user's own, which load all the same
    (a bridge upgrade does not stop a working site over a name). Names are compared per
    option combination, so none are checked while options or variants are invalid."""
    if any(_options(mapping)):
        return []
    combinations = option_combinations(mapping.options)
    return list(convention_problems(mapping.manufacturer, mapping.entities, combinations))


def _keys(mapping: MappingParts) -> Iterator[str]:
    for key in mapping.entities:
        if not KEY_PATTERN.match(key):
            yield f"entities.{key}: keys are snake_case (a-z, 0-9, _), starting with a letter"
        elif key in RESERVED_KEYS and key != mapping.status:
            reserved = ", ".join(sorted(RESERVED_KEYS))
            yield f"entities.{key}: '{key}' is reserved in the state JSON and topics ({reserved})"


def _addresses(mapping: MappingParts) -> Iterator[str]:
    rule = mapping.protocol.addressing
    for key, e in mapping.entities.items():
        for name, printed in (("address", e.address), ("write_address", e.write_address)):
            if printed is None:
                continue
            try:
                wire = to_wire(printed, rule)
            except ValueError as exc:
                yield f"entities.{key}.{name}: {exc}"
                continue
            if name == "address" and wire + e.register_count > 0x10000:
                yield f"entities.{key}.address: the value runs past address 65535"
    ranges = [("segments", s.start, s.end) for s in mapping.protocol.segments]
    ranges += [("reserved", r.start, r.end or r.start) for r in mapping.protocol.reserved]
    for index, (name, start, end) in enumerate(ranges):
        try:
            if to_wire(start, rule) > to_wire(end, rule):
                yield f"protocol.{name}: start {start!r} is after end {end!r}"
        except ValueError as exc:
            yield f"protocol.{name}[{index}]: {exc}"
    unlock = mapping.protocol.unlock
    if unlock is not None:
        for name, printed in (("address", unlock.address), ("lock", unlock.lock)):
            try:
                if printed is not None:
                    to_wire(printed, rule)
            except ValueError as exc:
                yield f"protocol.unlock.{name}: {exc}"


def _options(mapping: MappingParts) -> Iterator[str]:
    for name, spec in mapping.options.items():
        if spec.default not in spec.choices:
            yield f"options.{name}.default: {spec.default!r} is not one of {list(spec.choices)}"
    for key, e in mapping.entities.items():
        for index, variant in enumerate(e.variants):
            yield from _when_problems(mapping, f"entities.{key}.variants.{index}", variant.when)
            try:
                e.with_variant(variant)
            except ValidationError as exc:
                for error in exc.errors():
                    message = error["msg"].removeprefix("Value error, ")
                    yield f"entities.{key}.variants.{index}: {message}"
        yield from _when_problems(mapping, f"entities.{key}", e.when)


def _when_problems(
    mapping: MappingParts, location: str, when: AnyMapping[str, str | list[str]]
) -> Iterator[str]:
    for option, wanted in when.items():
        if option not in mapping.options:
            yield f"{location}.when: unknown option {option!r}"
            continue
        for value in [wanted] if isinstance(wanted, str) else wanted:
            if value not in mapping.options[option].choices:
                yield f"{location}.when: {option}={value!r} is not a choice"


def _references(mapping: MappingParts) -> Iterator[str]:
    entities = mapping.entities
    wants = {
        "unit_from": ("enum", "an enum entity"),
        "sign_from": ("sign", "a 1-bit field of a register"),
        "min_from": ("number", "a number entity"),
        "max_from": ("number", "a number entity"),
    }
    for key, e in entities.items():
        yield from _toggle_and_requires(mapping, key, e)
        for field_name, (kind, description) in wants.items():
            ref = getattr(e, field_name)
            if ref is None:
                continue
            target = entities.get(ref)
            if target is None:
                yield f"entities.{key}.{field_name}: no entity {ref!r}"
            elif not _is_kind(target, kind):
                yield f"entities.{key}.{field_name}: {ref!r} must be {description}"
            elif not target.readable:
                yield f"entities.{key}.{field_name}: {ref!r} must be readable"
            elif not _implies(e.when, target.when, mapping):
                yield f"entities.{key}.{field_name}: {ref!r} is missing for some option values"


def _toggle_and_requires(mapping: MappingParts, key: str, e: Entity) -> Iterator[str]:
    """``toggle_of`` names a readable boolean; ``requires`` readable entities, each with
    values of its kind (booleans for a boolean, labels for an enum)."""
    entities = mapping.entities
    if e.toggle_of is not None:
        target = entities.get(e.toggle_of)
        if target is None or target.kind != "bool" or not target.readable:
            yield f"entities.{key}.toggle_of: {e.toggle_of!r} must be a readable boolean"
        elif not _implies(e.when, target.when, mapping):
            yield f"entities.{key}.toggle_of: {e.toggle_of!r} is missing for some option values"
    if e.state_from is not None:
        yield from _state_link_problems(mapping, key, e, e.state_from)
    for ref, wanted in e.requires.items():
        target = entities.get(ref)
        values = wanted if isinstance(wanted, list) else [wanted]
        if target is None or not target.readable:
            yield f"entities.{key}.requires: {ref!r} must be a readable entity"
        elif not _implies(e.when, target.when, mapping):
            yield f"entities.{key}.requires: {ref!r} is missing for some option values"
        elif target.kind == "bool" and not all(isinstance(v, bool) for v in values):
            yield f"entities.{key}.requires.{ref}: a boolean entity takes true or false"
        elif target.kind == "enum" and not set(values) <= set((target.enum or {}).values()):
            yield f"entities.{key}.requires.{ref}: not one of {ref!r}'s labels"
        elif target.kind not in ("bool", "enum"):
            yield f"entities.{key}.requires: {ref!r} must be a boolean or an enum"


def _state_link_problems(
    mapping: MappingParts, key: str, e: Entity, link: StateLink
) -> Iterator[str]:
    """``state_from`` names a readable enum present whenever the select is, by labels it
    has."""
    ref = link.entity
    target = mapping.entities.get(ref)
    if target is None or target.kind != "enum" or not target.readable:
        yield f"entities.{key}.state_from.entity: {ref!r} must be a readable enum"
    elif not _implies(e.when, target.when, mapping):
        yield f"entities.{key}.state_from.entity: {ref!r} is missing for some option values"
    else:
        labels = set((target.enum or {}).values())
        for label in link.labels:
            if label not in labels:
                yield f"entities.{key}.state_from.labels: {label!r} is not one of {ref!r}'s labels"


def _is_kind(entity: Entity, kind: str) -> bool:
    if kind == "sign":
        return entity.field_width == 1 and entity.enum is None
    return entity.kind == kind


def _implies(
    when: AnyMapping[str, str | list[str]],
    other: AnyMapping[str, str | list[str]],
    mapping: MappingParts,
) -> bool:
    return all(
        when_matches(other, chosen)
        for chosen in option_combinations(mapping.options)
        if when_matches(when, chosen)
    )


def _function_codes(mapping: MappingParts) -> Iterator[str]:
    supported = mapping.protocol.function_codes
    for key, e in mapping.entities.items():
        if e.readable and e.table.read_function not in supported:
            yield (
                f"entities.{key}.table: reading {e.table.value} needs function "
                f"{e.table.read_function}, which the device does not support"
            )
        if e.writable:
            code = write_function(e, mapping.protocol)
            if code not in supported:
                yield f"entities.{key}.access: a write needs function {code}, not supported"
            if e.table.is_bits != (code in (5, 15)):
                yield f"entities.{key}.write_function: {code} does not write {e.table.value}"
            if code in (5, 6) and e.register_count > 1:
                yield f"entities.{key}.write_function: {code} writes one register only"


def _sentinels(mapping: MappingParts) -> Iterator[str]:
    for key, e in mapping.entities.items():
        top = _UNSIGNED_MAX.get(e.data_type, 0xFFFF)
        for raw in e.sentinels:
            if not 0 <= raw <= top:
                yield f"entities.{key}.sentinels: {raw} is outside the raw range 0..{top}"


def _presentation(mapping: MappingParts) -> Iterator[str]:
    for key, e in mapping.entities.items():
        for problem in presentation_problems(e):
            yield f"entities.{key}.ha: {problem}"
        for index, variant in enumerate(e.variants):
            try:
                applied = e.with_variant(variant)
            except ValidationError:
                continue  # reported by _options
            for problem in presentation_problems(applied):
                yield f"entities.{key}.variants.{index}.ha: {problem}"


def _overlaps(mapping: MappingParts) -> Iterator[str]:
    seen: set[str] = set()
    for chosen in option_combinations(mapping.options):
        for row in _overlaps_for(mapping, chosen):
            if row not in seen:
                seen.add(row)
                yield row


def _overlaps_for(mapping: MappingParts, chosen: dict[str, str]) -> Iterator[str]:
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
    mapping: MappingParts, owners: dict[tuple[Table, int], list[tuple[str, Entity, int]]]
) -> Iterator[str]:
    rule = mapping.protocol.addressing
    for r in mapping.protocol.reserved:
        start, end = to_wire(r.start, rule), to_wire(r.end or r.start, rule)
        for address in range(start, end + 1):
            for key, _, _ in owners.get((r.table, address), []):
                yield f"entities.{key}.address: reads reserved {r.table.value} {address}"


def _segment_crossings(
    mapping: MappingParts, owners: dict[tuple[Table, int], list[tuple[str, Entity, int]]]
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
