"""A device mapping: one YAML file per device model, validated as a whole.

``load_mapping(path)`` reads, validates and returns a ``Mapping``; every error names the
file, the entity key and the field. ``Mapping.points(options)`` resolves the entities
active for a device's option values into ``Point`` objects with wire addresses, which
the codec and the planner work on.

A ``Mapping`` runs the checks across entities (``checks``) when it validates; which
entities a device has for its option values, and as which variant, is ``variant``'s.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable
from collections.abc import Mapping as AnyMapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Self, TypeVar

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError, model_validator

from bridge.core import checks
from bridge.core.address import format_address, to_wire
from bridge.core.convention import name_problems
from bridge.core.entity import Entity, Table
from bridge.core.fingerprint import Fingerprint, check_fingerprint
from bridge.core.library import Library, disagreement_problems
from bridge.core.override import EXTENDS, merge_override
from bridge.core.protocol import OptionSpec, Protocol, write_function
from bridge.core.variant import active_entities
from bridge.core.yaml_source import parse_yaml
from bridge.errors import MappingError

T = TypeVar("T")


class Source(BaseModel):
    """The manual the mapping was written from."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    title: str
    seed: str | None = None
    document: str | None = None
    version: str | None = Field(None, description="the document's version or date")
    url: str | None = Field(None, description="where the document is published")


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
    fingerprint: Fingerprint | None = Field(
        None, description="what a unit reads that tells it is this model (identify)"
    )
    library: Library | None = Field(None, description="the device library's index entry")

    @model_validator(mode="after")
    def _check_whole(self) -> Self:
        errors = checks.check_mapping(self)
        if self.fingerprint is not None:
            errors += check_fingerprint(self.fingerprint, self.entities, self.protocol)
        if self.library is not None:
            errors += disagreement_problems(self.library, self.entities)
        if errors:
            raise ValueError("\n".join(errors))
        return self

    def default_options(self) -> dict[str, str]:
        return {name: spec.default for name, spec in self.options.items()}

    def active(self, options: dict[str, str] | None = None) -> dict[str, Entity]:
        """Entities present for these option values (unset options take their default)."""
        return active_entities(self.entities, self.default_options() | (options or {}))

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
                scale_source=plain.get(e.scale_by or ""),
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
    scale_source: Point | None = field(default=None, repr=False)  # its exponent (scale_by)
    # (table, wire address) of each register: worked out once, asked at every decode
    addresses: frozenset[tuple[Table, int]] = field(init=False, repr=False, compare=False)
    # the registers a decode reads: its own and its scale_by exponent's, read in one request
    footprint: frozenset[tuple[Table, int]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        span = range(self.address, self.address + self.entity.register_count)
        own = frozenset((self.entity.table, a) for a in span)
        object.__setattr__(self, "addresses", own)
        extra = self.scale_source.addresses if self.scale_source is not None else frozenset()
        object.__setattr__(self, "footprint", own | extra)

    @property
    def table(self) -> Table:
        return self.entity.table

    @property
    def count(self) -> int:
        return self.entity.register_count

    @property
    def span(self) -> range:
        return range(self.address, self.address + self.count)

    @property
    def extent(self) -> range:
        """The registers one request reads for this point: its span, or with ``scale_by``
        everything from the first to the last register of it and its exponent."""
        source = self.scale_source
        if source is None:
            return self.span
        return range(min(self.address, source.address), max(self.span.stop, source.span.stop))


def _plain_point(key: str, entity: Entity, protocol: Protocol) -> Point:
    address = to_wire(entity.address, protocol.addressing)
    return Point(
        key=key,
        entity=entity,
        address=address,
        write_address=address,
        write_function=write_function(entity, protocol) if entity.writable else None,
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


@dataclass(frozen=True, slots=True)
class MappingReport:
    """Every problem of one mapping file: ``errors`` refuse it; ``warnings`` (the shipped
    library's conventions: names, manufacturer, enabled defaults; only for a file checked
    as one of the library's) do not. ``mapping`` is the mapping loaded, None when there
    are errors."""

    source: str
    mapping: Mapping | None
    errors: tuple[str, ...]
    warnings: tuple[str, ...]


def check_mapping_text(text: str, source: str, *, library: bool = False) -> MappingReport:
    """Every layer of checks in one run: the YAML, the fields, the checks across
    entities and the protocol (on the parts that validate when some do not), and with
    ``library`` (a file of the shipped library) its conventions. Only a file that is not
    YAML, or not a mapping at the top, stops early."""
    try:
        data = parse_yaml(text, source)
    except ValueError as exc:
        return MappingReport(source, None, (str(exc),), ())
    if not isinstance(data, dict):
        top = "the file must hold a mapping (key: value) at the top"
        return MappingReport(source, None, (top,), ())
    if EXTENDS in data:
        try:
            data = _extended(data, source)
        except MappingError as exc:
            return MappingReport(source, None, tuple(exc.issues), ())
    try:
        mapping = Mapping.model_validate(data)
    except ValidationError as exc:
        rows = list(format_validation_errors(exc))
    else:
        warned = library_problems(mapping) if library else []
        return MappingReport(source, mapping, (), tuple(warned))
    more, warnings = _rows_of_valid_parts(data)
    warned = ([_NO_ENTRY] if "library" not in data else []) + warnings if library else []
    return MappingReport(source, None, tuple(dict.fromkeys(rows + more)), tuple(warned))


def _extended(data: dict[str, Any], source: str) -> dict[str, Any]:
    """The flat data of an override file (bridge/core/override.py): its base (a shipped
    name, or a path relative to the file's folder) loaded and checked, then merged."""
    ref = data[EXTENDS]
    if not isinstance(ref, str) or not ref:
        raise MappingError(source, [f"{EXTENDS}: a shipped mapping name or a .yaml path"])
    try:
        path = resolve_mapping_path(ref, Path(source).parent)
        text = path.read_text(encoding="utf-8")
        base_data = parse_yaml(text, str(path))
    except MappingError as exc:
        raise MappingError(source, [f"{EXTENDS}: {issue}" for issue in exc.issues]) from None
    except (OSError, ValueError) as exc:
        raise MappingError(source, [f"{EXTENDS}: {ref}: {exc}"]) from None
    if not isinstance(base_data, dict) or EXTENDS in base_data:
        raise MappingError(source, [f"{EXTENDS}: {path} extends another mapping (one level only)"])
    report = check_mapping_text(text, str(path))
    if report.mapping is None:
        raise MappingError(source, [f"{EXTENDS}: {path}: {row}" for row in report.errors])
    try:
        base = report.mapping
        return merge_override(base_data, base.entities, base.protocol.addressing, data)
    except ValueError as exc:
        raise MappingError(source, str(exc).splitlines()) from None


def parse_mapping(text: str, source: str) -> Mapping:
    """Validate mapping YAML text; raise MappingError with ``entity.field: message`` rows
    (the library's conventions are not checked: ``library_problems``)."""
    report = check_mapping_text(text, source)
    if report.mapping is None:
        raise MappingError(source, list(report.errors))
    return report.mapping


def library_problems(mapping: Mapping) -> list[str]:
    """The shipped library's conventions ``mapping`` breaks (``checks.check_conventions``;
    an index entry, ``library:``), as rows: for the library's files only, never a user's
    or an imported mapping."""
    return ([_NO_ENTRY] if mapping.library is None else []) + checks.check_conventions(mapping)


_NO_ENTRY = "library: a shipped mapping has its index entry (docs/mappings.md, Library)"


def _rows_of_valid_parts(data: dict[str, Any]) -> tuple[list[str], list[str]]:
    """Errors across entities and the library's convention rows of the parts of an invalid
    mapping that validate (an invalid entity left out, an invalid protocol field at its
    default), so that a file's problems are reported in one run. A reference to an invalid entity is
    not reported twice; the checks across entities wait for a valid addressing rule and
    valid options (addresses and option values would be guessed)."""
    raw = data.get("entities")
    entities: dict[str, Any] = raw if isinstance(raw, dict) else {}
    kept = {key: e for key, e in ((k, _valid(Entity, v)) for k, v in entities.items()) if e}
    protocol = _valid_protocol(data.get("protocol", {}))
    options = _valid(_OPTIONS, data.get("options", {}))
    status = data.get("status")
    partial = Mapping.model_construct(
        manufacturer=_text(data, "manufacturer"),
        model=_text(data, "model"),
        description=_text(data, "description"),
        source=Source(title=""),
        protocol=protocol or Protocol(),
        options=options or {},
        status=status if isinstance(status, str) else None,
        entities=kept,
    )
    invalid = [key for key in entities if key not in kept]
    warnings = checks.check_conventions(partial) + [
        f"entities.{key}.name: {problem}"
        for key in invalid
        if isinstance(entities[key], dict) and isinstance(name := entities[key].get("name"), str)
        for problem in name_problems(name)
    ]
    if not kept or protocol is None or options is None:
        return [], warnings
    gone = tuple(f"no entity {key!r}" for key in invalid)
    return [row for row in checks.check_mapping(partial) if not row.endswith(gone)], warnings


_OPTIONS: TypeAdapter[dict[str, OptionSpec]] = TypeAdapter(dict[str, OptionSpec])


def _valid(model: Any, data: object) -> Any:
    """``data`` validated as ``model`` (a model class or a TypeAdapter), or None."""
    validate = model.validate_python if isinstance(model, TypeAdapter) else model.model_validate
    try:
        return validate(data)
    except ValidationError:
        return None


def _valid_protocol(data: object) -> Protocol | None:
    """The protocol with its invalid fields at their defaults; None when the addressing
    rule is invalid (or the section is not a mapping)."""
    if not isinstance(data, dict):
        return None
    try:
        return Protocol.model_validate(data)
    except ValidationError as exc:
        dropped = {str(error["loc"][0]) for error in exc.errors() if error["loc"]}
    if "addressing" in dropped:
        return None
    found: Protocol | None = _valid(Protocol, {k: v for k, v in data.items() if k not in dropped})
    return found


def _text(data: dict[str, Any], name: str) -> str:
    value = data.get(name)
    return value if isinstance(value, str) else "Generic"


def load_mapping(path: Path) -> Mapping:
    """Read and validate one mapping file."""
    report = check_mapping_file(path)
    if report.mapping is None:
        raise MappingError(report.source, list(report.errors))
    return report.mapping


def check_mapping_file(path: Path, *, library: bool = False) -> MappingReport:
    """Read one mapping file and report all its problems (``check_mapping_text``)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        return MappingReport(
            str(path), None, (f"cannot read {path.absolute()}: {exc.strerror}",), ()
        )
    return check_mapping_text(text, str(path), library=library)


def mappings_folder() -> Path:
    """The shipped mappings: ``bridge/mappings`` in a wheel, ``mappings/`` in a checkout."""
    package = Path(__file__).resolve().parent.parent
    installed = package / "mappings"
    return installed if installed.is_dir() else package.parent / "mappings"


def library_index() -> dict[str, Path]:
    """Every shipped mapping's name (its file's stem) and file, found at any depth of
    ``mappings_folder`` (the seeds at the top, the library in ``library/<category>/``),
    sorted by name; two files of one name are an error naming both."""
    return _index_of(mappings_folder())


@functools.cache
def _index_of(folder: Path) -> dict[str, Path]:
    found: dict[str, Path] = {}
    for path in sorted(folder.rglob("*.yaml")):
        if path.stem in found:
            both = f"{found[path.stem]} and {path}"
            raise MappingError(path.stem, [f"two shipped mappings have this name: {both}"])
        found[path.stem] = path
    return dict(sorted(found.items()))


def in_library(path: Path) -> bool:
    """True for a file of the shipped library (a ``.yaml`` at any depth of
    ``mappings_folder``), the only files the library's conventions are checked on."""
    try:
        return path.resolve() in library_index().values()
    except (OSError, RuntimeError):  # a symlink loop: not the library's
        return False


def builtin_mapping_names() -> list[str]:
    """Names of the mappings shipped with the bridge (file stems)."""
    return list(library_index())


@functools.cache
def shipped_library() -> dict[str, Mapping]:
    """Every shipped mapping by name, loaded once (what ``identify`` compares with)."""
    return {name: load_mapping(path) for name, path in library_index().items()}


def builtin_mapping_path(name: str) -> Path:
    found = library_index().get(name)
    return found if found is not None else mappings_folder() / f"{name}.yaml"


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
