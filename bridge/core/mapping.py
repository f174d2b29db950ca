"""A device mapping: one YAML file per device model, validated as a whole.

``load_mapping(path)`` reads, validates and returns a ``Mapping``; every error names the
file, the entity key and the field. ``Mapping.points(options)`` resolves the entities
active for a device's option values into ``Point`` objects with wire addresses, which
the codec and the planner work on.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from collections.abc import Mapping as AnyMapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Self, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from bridge.core import checks
from bridge.core.address import format_address, to_wire
from bridge.core.entity import Entity, Table
from bridge.core.protocol import OptionSpec, Protocol
from bridge.core.yaml_source import parse_yaml
from bridge.errors import MappingError

T = TypeVar("T")


class Source(BaseModel):
    """The manual the mapping was written from."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    title: str
    seed: str | None = None
    document: str | None = None


class Mapping(BaseModel):
    """Everything the bridge knows about one device model."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    manufacturer: str
    model: str
    description: str
    source: Source
    protocol: Protocol = Protocol()
    options: dict[str, OptionSpec] = Field(default_factory=dict)
    status: str | None = Field(None, description="key of the entity that is the device status")
    entities: dict[str, Entity] = Field(min_length=1)

    @model_validator(mode="after")
    def _check_whole(self) -> Self:
        errors = checks.check_mapping(self)
        if errors:
            raise ValueError("\n".join(errors))
        return self

    def default_options(self) -> dict[str, str]:
        return {name: spec.default for name, spec in self.options.items()}

    def active(self, options: dict[str, str] | None = None) -> dict[str, Entity]:
        """Entities present for these option values (unset options take their default)."""
        chosen = self.default_options() | (options or {})
        return {
            key: checks.apply_variants(entity, chosen)
            for key, entity in self.entities.items()
            if checks.when_matches(entity.when, chosen)
        }

    def memo(self, key: object, build: Callable[[], T]) -> T:
        """What ``build`` returns, built once per mapping (many devices of one model share
        their points, guard and read limits: they are immutable)."""
        if key not in self.shared:
            self.shared[key] = build()
        found: T = self.shared[key]
        return found

    @cached_property
    def shared(self) -> dict[object, Any]:
        """``memo``'s store: not a field, so two equal mappings stay equal."""
        return {}

    def model_copy(self, *, update: AnyMapping[str, Any] | None = None, deep: bool = False) -> Self:
        """A copy that builds its own shared facts (its protocol may differ)."""
        copy = super().model_copy(update=update, deep=deep)
        copy.__dict__.pop("shared", None)
        return copy

    def points(self, options: dict[str, str] | None = None) -> dict[str, Point]:
        """Resolve the active entities into points with wire addresses and linked sources
        (a dict of its own; the points in it are shared by every device of these options)."""
        chosen = self.default_options() | (options or {})
        key = ("points", tuple(sorted(chosen.items())))
        return dict(self.memo(key, lambda: self._resolve(chosen)))

    def _resolve(self, options: dict[str, str]) -> dict[str, Point]:
        active = self.active(options)
        rule = self.protocol.addressing
        plain = {key: _plain_point(key, entity, self.protocol) for key, entity in active.items()}
        resolved: dict[str, Point] = {}
        for key, point in plain.items():
            e = point.entity
            resolved[key] = Point(
                key=key,
                entity=e,
                address=point.address,
                write_address=to_wire(e.write_address, rule)
                if e.write_address is not None
                else point.address,
                write_function=point.write_function,
                coil_on_value=self.protocol.coil_on_value,
                sign=plain.get(e.sign_from or ""),
                unit_source=plain.get(e.unit_from or ""),
                min_source=plain.get(e.min_from or ""),
                max_source=plain.get(e.max_from or ""),
                state_source=plain.get(e.toggle_of or ""),
            )
        return resolved


@dataclass(frozen=True, slots=True)
class Point:
    """An entity resolved for one device: wire addresses and the points it depends on."""

    key: str
    entity: Entity
    address: int
    write_address: int
    write_function: int | None
    coil_on_value: int = 0xFF00
    sign: Point | None = field(default=None, repr=False)
    unit_source: Point | None = field(default=None, repr=False)
    min_source: Point | None = field(default=None, repr=False)
    max_source: Point | None = field(default=None, repr=False)
    state_source: Point | None = field(default=None, repr=False)  # what a toggle flips

    @property
    def table(self) -> Table:
        return self.entity.table

    @property
    def count(self) -> int:
        return self.entity.register_count

    @property
    def span(self) -> range:
        return range(self.address, self.address + self.count)


def _plain_point(key: str, entity: Entity, protocol: Protocol) -> Point:
    address = to_wire(entity.address, protocol.addressing)
    return Point(
        key=key,
        entity=entity,
        address=address,
        write_address=address,
        write_function=checks.write_function(entity, protocol) if entity.writable else None,
        coil_on_value=protocol.coil_on_value,
    )


def printed_address(points: Iterable[Point], table: Table, wire: int, protocol: Protocol) -> str:
    """A wire address as the manual prints it: the address of the point that holds it
    (``F0.01``, ``0x00A0``; ``+n`` for the n-th register of a longer value), else the
    addressing rule's offset undone."""
    rule = protocol.addressing
    for point in points:
        if point.table is table and wire in point.span:
            printed, step = point.entity.address, wire - point.address
            if step and isinstance(printed, int):
                return format_address(printed + step, rule)
            return format_address(printed, rule) + (f"+{step}" if step else "")
    return format_address(wire - rule.offset, rule)


# --- loading ------------------------------------------------------------------------


def parse_mapping(text: str, source: str) -> Mapping:
    """Validate mapping YAML text; raise MappingError with ``entity.field: message`` rows."""
    try:
        data = parse_yaml(text, source)
    except ValueError as exc:
        raise MappingError(source, [str(exc)]) from None
    if not isinstance(data, dict):
        raise MappingError(source, ["the file must hold a mapping (key: value) at the top"])
    try:
        return Mapping.model_validate(data)
    except ValidationError as exc:
        rows = list(format_validation_errors(exc))
    rows += _whole_mapping_rows(data, rows)
    raise MappingError(source, list(dict.fromkeys(rows)))


def _whole_mapping_rows(data: dict[str, Any], rows: list[str]) -> list[str]:
    """When only some entities are invalid, the checks across entities (references,
    overlaps, function codes...) still run on the valid ones, so that a file's problems
    are reported in one run. References to an invalid entity are not reported twice."""
    entities = data.get("entities")
    if not isinstance(entities, dict) or any(not r.startswith("entities.") for r in rows):
        return []  # the header or protocol is wrong: checks across entities would guess
    valid, invalid = {}, set()
    for key, raw in entities.items():
        try:
            Entity.model_validate(raw)
            valid[key] = raw
        except ValidationError:
            invalid.add(key)
    if not valid or not invalid:
        return []
    try:
        Mapping.model_validate(data | {"entities": valid})
    except ValidationError as exc:
        gone = tuple(f"no entity {key!r}" for key in invalid)
        return [row for row in format_validation_errors(exc) if not row.endswith(gone)]
    return []


def load_mapping(path: Path) -> Mapping:
    """Read and validate one mapping file."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise MappingError(str(path), [f"cannot read {path.absolute()}: {exc.strerror}"]) from None
    return parse_mapping(text, str(path))


def mappings_folder() -> Path:
    """The shipped mappings: ``bridge/mappings`` in a wheel, ``mappings/`` in a checkout."""
    package = Path(__file__).resolve().parent.parent
    installed = package / "mappings"
    return installed if installed.is_dir() else package.parent / "mappings"


def builtin_mapping_names() -> list[str]:
    """Names of the mappings shipped with the bridge (file stems)."""
    return sorted(path.stem for path in mappings_folder().glob("*.yaml"))


def builtin_mapping_path(name: str) -> Path:
    return mappings_folder() / f"{name}.yaml"


def resolve_mapping_path(ref: str, base: Path | None = None) -> Path:
    """A mapping reference is a shipped name (``nastec_vasco``) or a path to a YAML file,
    relative to ``base`` (a config file's folder), else to the current directory. An error
    names the path it tried."""
    if ref in builtin_mapping_names():
        return builtin_mapping_path(ref)
    path = Path(ref)
    if not path.is_absolute():
        path = (base if base is not None else Path.cwd()) / path
    if path.is_file():
        if path.suffix in (".yaml", ".yml"):
            return path
        raise MappingError(ref, [f"{path.absolute()} is not a .yaml file"])
    known = ", ".join(builtin_mapping_names())
    raise MappingError(
        ref, [f"no shipped mapping of that name ({known}) and no file {path.absolute()}"]
    )


def format_validation_errors(exc: ValidationError) -> Iterable[str]:
    """Turn pydantic errors into ``entities.<key>.<field>: message`` rows."""
    for error in exc.errors():
        location = ".".join(str(part) for part in error["loc"])
        message = error["msg"].removeprefix("Value error, ")
        for line in message.splitlines():
            yield f"{location}: {line}" if location else line


def mapping_schema() -> dict[str, Any]:
    """JSON Schema of the mapping format (for editor completion)."""
    return Mapping.model_json_schema()
