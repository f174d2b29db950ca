"""Whole-mapping checks: keys, addresses, references, options, function codes, overlaps;
apart, the shipped library's presentation conventions (``convention``: names,
manufacturer, enabled defaults), which a user's mapping is not held to.

Each check returns rows ``entities.<key>.<field>: message``; ``check_mapping`` runs them all
so a user sees every problem of a file at once. The checks read the parts of a mapping
they need (``MappingParts``), not the model: ``mapping.Mapping`` runs them when it
validates, so it sits above this module.

Which entities may share registers is decided in ``overlap``.
"""

from __future__ import annotations

import re
import typing
from collections.abc import Iterator
from collections.abc import Mapping as AnyMapping

from pydantic import ValidationError

from bridge.core.address import to_wire
from bridge.core.convention import convention_problems
from bridge.core.entity import DataType, Entity, StateLink
from bridge.core.hass import presentation_problems
from bridge.core.overlap import overlap_problems
from bridge.core.protocol import OptionSpec, Protocol, write_function
from bridge.core.variant import option_combinations, when_matches

KEY_PATTERN = re.compile(r"^[a-z][a-z0-9_]*$")
RESERVED_KEYS = frozenset(
    {"status", "alarms", "availability", "set", "get", "error", "event", "last_reset"}
)
_UNSIGNED_MAX = {DataType.U32: 0xFFFFFFFF, DataType.S32: 0xFFFFFFFF, DataType.F32: 0xFFFFFFFF}
_UNSIGNED_MAX |= dict.fromkeys((DataType.U64, DataType.S64, DataType.F64), (1 << 64) - 1)


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
    if not basis:  # the read limits at an address need valid addresses
        rows.extend(_whole_reads(mapping))
    if not basis:  # overlap checks need valid addresses and options, nothing else
        rows.extend(overlap_problems(mapping.protocol, mapping.options, mapping.entities))
    if mapping.status is not None and mapping.status not in mapping.entities:
        rows.append(f"status: no entity {mapping.status!r}")
    return rows


def check_conventions(mapping: MappingParts) -> list[str]:
    """The shipped library's presentation conventions (``convention``) ``mapping``
    breaks: errors in the library's tests, warnings from ``mappings validate`` for a file
    of the library; never run on a user's or an imported mapping. Names are compared per
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
        yield from _scale_source(mapping, key, e)
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


def _scale_source(mapping: MappingParts, key: str, e: Entity) -> Iterator[str]:
    """``scale_by`` names a readable whole s16 number of the same table, unscaled itself,
    present whenever the scaled entity is."""
    ref = e.scale_by
    if ref is None:
        return
    target = mapping.entities.get(ref)
    where = f"entities.{key}.scale_by"
    if ref == key:
        yield f"{where}: an entity cannot scale itself"
    elif target is None:
        yield f"{where}: no entity {ref!r}"
    elif target.data_type is not DataType.S16 or target.kind != "number" or target.bit is not None:
        yield f"{where}: {ref!r} must be a whole s16 number (a power-of-ten exponent)"
    elif not target.readable:
        yield f"{where}: {ref!r} must be readable"
    elif target.table is not e.table:
        yield f"{where}: {ref!r} must be on the same table ({e.table.value}), read with it"
    elif target.scale != 1 or target.offset != 0 or target.scale_by is not None:
        yield f"{where}: {ref!r} holds the exponent as it is: no scale, offset or scale_by"
    elif not _implies(e.when, target.when, mapping):
        yield f"{where}: {ref!r} is missing for some option values"


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


def wide_keys(entities: AnyMapping[str, Entity]) -> list[str]:
    """The readable 64-bit numbers: each is read whole, in one request of 4 registers
    (no tear check joins words read apart, as for a two-register value)."""
    return [
        k
        for k, e in entities.items()
        if e.readable and e.register_count == 4 and e.kind == "number"
    ]


def _whole_reads(mapping: MappingParts) -> Iterator[str]:
    """A 64-bit number where the device (or a segment) reads fewer than 4 registers (a
    ``scale_by`` number and its exponent that one request cannot read together is no
    error: the planner reads it bracketed, bridge/core/bracket.py)."""
    for key in wide_keys(mapping.entities):
        e = mapping.entities[key]
        limit = _read_limit(mapping, e, to_wire(e.address, mapping.protocol.addressing))
        if limit < e.register_count:
            yield (
                f"entities.{key}.type: a {e.data_type.value} is read whole, in one request of "
                f"4 registers; the device reads at most {limit} there"
            )


def _read_limit(mapping: MappingParts, e: Entity, wire: int) -> int:
    """Registers one request may read at ``wire`` of the entity's table."""
    protocol, rule = mapping.protocol, mapping.protocol.addressing
    return min(
        [protocol.max_read_registers]
        + [
            s.max_read_registers
            for s in protocol.segments
            if s.table is e.table
            and s.max_read_registers is not None
            and to_wire(s.start, rule) <= wire <= to_wire(s.end, rule)
        ]
    )


def _sentinels(mapping: MappingParts) -> Iterator[str]:
    for key, e in mapping.entities.items():
        top = _UNSIGNED_MAX.get(e.data_type, 0xFFFF)
        if e.data_type is DataType.ASCII and set(e.sentinels) - {0}:
            yield f"entities.{key}.sentinels: text takes only 0 (every register 0: no text)"
            continue
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
