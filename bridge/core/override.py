"""A user mapping that extends another: ``extends: <shipped name or path>`` plus entities.

An override file adds entities to a base mapping (a shipped one is never edited in
place) and may change a base entity's presentation: its name, unit, precision, poll
interval, note, simulator range and Home Assistant classes (``OVERRIDABLE``,
``HA_OVERRIDABLE``). It can never weaken a guard: a base entity that is dangerous,
secret, write-only, read-only or guarded otherwise (``dangerous_below``, ``requires``)
stays so; an override may only make a guard stronger (``dangerous: true``,
``secret: true``, ``access: r`` on a read-write entity). A new entity is read-only
unless it says ``access``; it is refused on any register of a guarded base entity (it
would publish a secret, or write around the guard), and a writable one on any register
of a read-only base entity. The base may not extend another (one level).

``merge_override(base_data, base, addressing, data)`` returns the flat mapping data the override
stands for, validated then by the mapping loader as any file (cross-entity and overlap
checks included): an override loads exactly as that flat file would. Pure.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

from bridge.core.address import Addressing, PrintedAddress, to_wire
from bridge.core.entity import Access, Entity, Table

Cell = tuple[Table, int]
EXTENDS = "extends"
OVERRIDABLE = frozenset({"name", "unit", "precision", "poll", "note", "simulate", "ha"})
HA_OVERRIDABLE = frozenset(
    {"device_class", "state_class", "icon", "enabled", "enabled_reason", "display_precision"}
)
_TOP = frozenset({EXTENDS, "entities"})
_LISTED = ", ".join(sorted(OVERRIDABLE))
_HA_LISTED = ", ".join(sorted(HA_OVERRIDABLE))


def merge_override(
    base_data: dict[str, Any],
    base: Mapping[str, Entity],
    addressing: Addressing,
    data: dict[str, Any],
) -> dict[str, Any]:
    """The flat mapping data of override ``data`` on the entities ``base`` (``base_data``
    is the base file as parsed, ``addressing`` its rule); ValueError with one
    ``path: message`` row per line on a refusal."""
    rows = [
        f"{key}: an override file holds only extends and entities" for key in data.keys() - _TOP
    ]
    entities = data.get("entities", {})
    if not isinstance(entities, dict) or not all(isinstance(e, dict) for e in entities.values()):
        rows.append("entities: a mapping of entity key -> fields")
        entities = {}
    merged = dict(base_data["entities"])
    guarded = _guarded_cells(base, addressing)
    for key, fields in entities.items():
        if key in base:
            rows += _changes_refused(str(key), base[key], fields)
            merged[key] = _with_changes(merged[key], fields)
        else:
            rows += _new_refused(str(key), fields, addressing, guarded)
            merged[key] = fields
    if rows:
        raise ValueError("\n".join(rows))
    flat = {k: v for k, v in base_data.items() if k != "library"}  # not the library's file
    return flat | {"entities": merged}


def _with_changes(base_fields: dict[str, Any], fields: dict[str, Any]) -> dict[str, Any]:
    changed = base_fields | fields
    if isinstance(fields.get("ha"), dict):
        changed["ha"] = dict(base_fields.get("ha") or {}) | fields["ha"]
    return changed


def _changes_refused(key: str, base: Entity, fields: dict[str, Any]) -> Iterator[str]:
    where = f"entities.{key}"
    for name, value in fields.items():
        if name in OVERRIDABLE:
            if name == "ha" and isinstance(value, dict):
                for ha_field in value.keys() - HA_OVERRIDABLE:
                    yield f"{where}.ha.{ha_field}: an override may change only {_HA_LISTED}"
            continue
        if value == getattr(base, name, object()) or _stronger(base, name, value):
            continue
        guard = _guard_of(base)
        if guard is not None and name in _GUARD_FIELDS:
            yield f"{where}.{name}: the base marks it {guard}; an override cannot weaken a guard"
        else:
            yield f"{where}.{name}: an override may change only {_LISTED} of a base entity"


_GUARD_FIELDS = frozenset({"access", "dangerous", "dangerous_below", "secret", "requires"})


def _stronger(base: Entity, name: str, value: object) -> bool:
    """A change that guards more: dangerous or secret on, a read-write entity read-only."""
    if name in ("dangerous", "secret"):
        return value is True
    return name == "access" and value == Access.READ.value and base.access is Access.READ_WRITE


def _guard_of(entity: Entity) -> str | None:
    """What guards ``entity``, in words, or None."""
    if entity.dangerous:
        return "dangerous"
    if entity.secret:
        return "secret"
    if entity.access is Access.WRITE:
        return "write-only"
    if entity.access is Access.READ:
        return "read-only"
    if entity.dangerous_below is not None or entity.requires:
        return "guarded"
    return None


def _new_refused(
    key: str, fields: dict[str, Any], addressing: Addressing, guarded: dict[Cell, tuple[str, str]]
) -> Iterator[str]:
    """A new entity on a register of a guarded base entity (it would publish a secret or
    write around a guard), or a writable one on a register of a read-only base entity; its
    ``write_address`` counts as its own register."""
    try:
        entity = Entity.model_validate(fields)
        spans = {"address": _cells(entity, addressing)}
        if entity.writable and entity.write_address is not None:
            spans["write_address"] = _cells(entity, addressing, entity.write_address)
    except ValueError:
        return  # the loader reports the entity's own problems
    for field, cells in spans.items():
        for cell in sorted(cells & guarded.keys()):
            (table, wire), (owner, guard) = cell, guarded[cell]
            where = f"{table.value} {wire} (wire) is the base's {owner}, {guard}"
            if guard != "read-only":
                yield f"entities.{key}.{field}: {where}: a new entity may not read or write it"
                return
            if entity.writable:
                yield f"entities.{key}.access: {where}: a new entity there is read-only"
                return


def _guarded_cells(
    base: Mapping[str, Entity], addressing: Addressing
) -> dict[Cell, tuple[str, str]]:
    """Every cell a base entity covers (whatever the device's options) that is read-only
    or guarded -> that entity's key and guard (a guard before read-only)."""
    cells: dict[Cell, tuple[str, str]] = {}
    for key, entity in base.items():
        guard = _guard_of(entity)
        if guard is None:
            continue
        written = entity.write_address if entity.writable else None
        both = _cells(entity, addressing) | _cells(entity, addressing, written)
        for cell in both:
            if cells.get(cell, ("", "read-only"))[1] == "read-only":
                cells[cell] = (key, guard)
    return cells


def _cells(
    entity: Entity, addressing: Addressing, printed: PrintedAddress | None = None
) -> set[Cell]:
    """The registers (or bits) of ``entity`` from its address (or ``printed``) on."""
    start = to_wire(entity.address if printed is None else printed, addressing)
    return {(entity.table, a) for a in range(start, start + entity.register_count)}
