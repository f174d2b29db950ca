"""The SunSpec model definitions, as data: pysunspec2's bundled JSON, typed and immutable.

Source: the ``model_<id>.json`` files pysunspec2 ships (``sunspec2/models/json``), read
through ``importlib.resources``, never copied. Why those: they are the SunSpec Alliance's
own files (``sunspec2/models`` is github.com/sunspec/models, a git submodule of the
Alliance's pysunspec2, shipped in its wheel), so pinning pysunspec2 to one minor
(pyproject.toml) pins the definitions, the tests can use pysunspec2 itself as the
reference reader of the same files, and nothing is fetched at run time or copied into this
repository. The spreadsheets and SMDX XML of the models repository say the same in older
formats.

``load_model(id)`` returns a ``ModelDef``; ``layout(model, length, counts)`` places every
point of one model instance at its offset from the model's ID register, repeating groups
expanded the way pysunspec2 expands them (sunspec2/device.py ``Group.__init__`` and
``_init_repeating_group``): a count is a number, or the top-level point it names, and a
count of 0 means "as many as the model's length holds" (legacy models such as 160, 64xxx).
Model 1 of length 65 (an old common model) has no ``Pad``, as pysunspec2 allows.
``scale_factor(placed, points)`` finds the point that scales a placed point as pysunspec2
does (``Point.get_value``): in the point's own group instance, else at the model's top.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from typing import Any, Literal, get_args

PointType = Literal[
    "int16", "uint16", "count", "acc16", "enum16", "bitfield16", "pad", "sunssf",
    "int32", "uint32", "acc32", "enum32", "bitfield32", "ipaddr", "float32",
    "int64", "uint64", "acc64", "float64", "eui48", "ipv6addr", "string",
]  # fmt: skip
Access = Literal["R", "RW"]
ID_POINT = "ID"  # every model's first point: its ID
LENGTH_POINT = "L"  # every model's second point: its length after ID and L
HEADER = 2  # ID and L: not counted in L
_LEGACY_COMMON_LENGTH = 65  # model 1 without its Pad (pysunspec2 device.py: Group.__init__)
_PACKAGE = "sunspec2.models.json"


class ModelDefinitionError(ValueError):
    """A model id without a definition, or a definition this module cannot read."""


@dataclass(frozen=True, slots=True)
class Symbol:
    """One value of an enum or one bit of a bitfield."""

    name: str
    value: int
    label: str = ""
    desc: str = ""


@dataclass(frozen=True, slots=True)
class PointDef:
    """One point; ``offset`` counts registers from the start of its group instance."""

    name: str
    type: PointType
    size: int  # registers
    offset: int
    sf: str | int | None = None  # the sunssf point that scales it, or a fixed exponent
    units: str = ""
    access: Access = "R"
    mandatory: bool = False
    static: bool = False
    symbols: tuple[Symbol, ...] = ()
    label: str = ""
    desc: str = ""
    value: int | None = None  # a fixed value (the ID point's)


@dataclass(frozen=True, slots=True)
class GroupDef:
    """A group: once (``count`` None), or repeated ``count`` times (a number; the name of
    the model's top-level point that holds it; 0: as many as the model's length holds)."""

    name: str
    points: tuple[PointDef, ...]
    groups: tuple[GroupDef, ...] = ()
    count: int | str | None = None
    label: str = ""
    desc: str = ""

    @property
    def points_length(self) -> int:
        """Registers of this group's own points (nested groups left out)."""
        return sum(p.size for p in self.points)

    def point(self, name: str) -> PointDef:
        for p in self.points:
            if p.name == name:
                return p
        raise KeyError(f"group {self.name} has no point {name!r}")


@dataclass(frozen=True, slots=True)
class ModelDef:
    """One SunSpec model definition."""

    id: int
    group: GroupDef

    @property
    def name(self) -> str:
        return self.group.name

    @property
    def label(self) -> str:
        return self.group.label

    @property
    def desc(self) -> str:
        return self.group.desc

    @property
    def fixed_length(self) -> int | None:
        """The model's L (registers after ID and L) when no group repeats a variable
        number of times; None when the length depends on the device."""
        total = _fixed(self.group)
        return None if total is None else total - HEADER

    @property
    def count_points(self) -> tuple[str, ...]:
        """The top-level points whose values ``layout`` needs (they count groups)."""
        return tuple(sorted(_count_points(self.group)))


@dataclass(frozen=True, slots=True)
class PlacedPoint:
    """A point of one model instance: ``offset`` from the model's ID register; ``path``
    names the groups it sits in below the model, each with its instance (1-based; 0 for a
    group that does not repeat): ``(("module", 2),)`` for model 160's second module."""

    point: PointDef
    offset: int
    path: tuple[tuple[str, int], ...] = ()


def model_ids() -> tuple[int, ...]:
    """The ids of every bundled definition, ascending."""
    files = resources.files(_PACKAGE).iterdir()
    names = (f.name for f in files if f.name.startswith("model_") and f.name.endswith(".json"))
    return tuple(sorted(int(n.removeprefix("model_").removesuffix(".json")) for n in names))


@functools.cache
def load_model(model_id: int) -> ModelDef:
    """The definition of ``model_id`` (ModelDefinitionError: none bundled, or unreadable)."""
    source = resources.files(_PACKAGE).joinpath(f"model_{model_id}.json")
    try:
        raw = json.loads(source.read_text(encoding="utf-8"))
    except (FileNotFoundError, json.JSONDecodeError) as e:
        raise ModelDefinitionError(f"SunSpec model {model_id}: no readable definition") from e
    try:
        model = ModelDef(id=int(raw["id"]), group=_group(raw["group"]))
    except (KeyError, TypeError, ValueError) as e:
        raise ModelDefinitionError(f"SunSpec model {model_id}: {e!r}") from e
    if model.id != model_id:
        raise ModelDefinitionError(f"model_{model_id}.json defines model {model.id}")
    return model


def layout(
    model: ModelDef, length: int, counts: Mapping[str, int] | None = None
) -> tuple[PlacedPoint, ...]:
    """Every point of an instance of ``model`` whose L is ``length``, in register order;
    ``counts`` gives the values of the top-level points that count repeating groups.
    ModelDefinitionError when they do not fill ``length`` exactly."""
    points = model.group.points
    if model.id == 1 and length == _LEGACY_COMMON_LENGTH:
        points = tuple(p for p in points if p.name != "Pad")
    top = GroupDef(model.group.name, points, model.group.groups, model.group.count)
    placed = _place(top, 0, (), _Sizing(model, length, counts or {}))
    end = placed[-1].offset + placed[-1].point.size if placed else 0
    if end != length + HEADER:
        raise ModelDefinitionError(
            f"SunSpec model {model.id}: its points take {end - HEADER} registers, L says {length}"
        )
    return placed


def scale_factor(placed: PlacedPoint, points: Sequence[PlacedPoint]) -> PlacedPoint | int | None:
    """What scales ``placed`` among ``points`` (one model's ``layout``): its sunssf point
    (in its own group instance, else at the model's top), a fixed exponent, or None.
    ModelDefinitionError when the named point is in neither."""
    sf = placed.point.sf
    if sf is None or isinstance(sf, int):
        return sf
    for path in (placed.path, ()):
        for other in points:
            if other.path == path and other.point.name == sf:
                return other
    raise ModelDefinitionError(f"point {placed.point.name}: scale factor {sf} is not placed")


@dataclass(frozen=True, slots=True)
class _Sizing:
    model: ModelDef
    length: int
    counts: Mapping[str, int]

    def count(self, group: GroupDef) -> int:
        count = group.count
        if isinstance(count, str):
            if count not in self.counts:
                raise ModelDefinitionError(
                    f"SunSpec model {self.model.id}: group {group.name} needs point {count}"
                )
            count = self.counts[count]
        if count is None:
            return 1
        if count != 0:
            return count
        fixed = sum(p.size for p in self.model.group.points) - HEADER
        if group.points_length == 0 or (self.length - fixed) % group.points_length:
            raise ModelDefinitionError(
                f"SunSpec model {self.model.id}: L {self.length} is no whole number of "
                f"{group.name} groups"
            )
        return max(0, (self.length - fixed) // group.points_length)


def _place(
    group: GroupDef, start: int, path: tuple[tuple[str, int], ...], sizing: _Sizing
) -> tuple[PlacedPoint, ...]:
    placed = [PlacedPoint(p, start + p.offset, path) for p in group.points]
    at = start + group.points_length
    for child in group.groups:
        repeats = child.count is not None
        for index in range(sizing.count(child)):
            inner = _place(child, at, (*path, (child.name, index + 1 if repeats else 0)), sizing)
            placed.extend(inner)
            at = inner[-1].offset + inner[-1].point.size if inner else at
            if at > sizing.length + HEADER or (repeats and not inner):
                # counts a device read that the length cannot hold: stop at once (a count
                # of 65535 curves of 65535 points is not laid out before it is refused)
                raise ModelDefinitionError(
                    f"SunSpec model {sizing.model.id}: its counts ({_shown(sizing.counts)}) "
                    f"need more than L {sizing.length}"
                )
    return tuple(placed)


def _shown(counts: Mapping[str, int]) -> str:
    return ", ".join(f"{name} {value}" for name, value in sorted(counts.items())) or "none"


def _count_points(group: GroupDef) -> set[str]:
    names = {group.count} if isinstance(group.count, str) else set()
    for child in group.groups:
        names |= _count_points(child)
    return names


def _fixed(group: GroupDef) -> int | None:
    """Registers of one instance of ``group``; None when a count is read from the device."""
    total = group.points_length
    for child in group.groups:
        inner = _fixed(child)
        if inner is None or isinstance(child.count, str) or child.count == 0:
            return None
        total += inner * (1 if child.count is None else child.count)
    return total


def _group(raw: dict[str, Any]) -> GroupDef:
    points: list[PointDef] = []
    offset = 0
    for p in raw.get("points", []):
        points.append(_point(p, offset))
        offset += points[-1].size
    count = raw.get("count")
    return GroupDef(
        name=str(raw["name"]),
        points=tuple(points),
        groups=tuple(_group(g) for g in raw.get("groups", [])),
        count=count if isinstance(count, int | str) else None,
        label=str(raw.get("label", "")),
        desc=str(raw.get("desc", "")),
    )


def _point(raw: dict[str, Any], offset: int) -> PointDef:
    kind = raw["type"]
    if kind not in get_args(PointType):
        raise ValueError(f"point {raw['name']}: unknown type {kind!r}")
    sf = raw.get("sf")
    value = raw.get("value")
    return PointDef(
        name=str(raw["name"]),
        type=kind,
        size=int(raw["size"]),
        offset=offset,
        sf=sf if isinstance(sf, str | int) else None,
        units=str(raw.get("units", "")),
        access="RW" if raw.get("access") == "RW" else "R",
        mandatory=raw.get("mandatory") == "M",
        static=raw.get("static") == "S",
        symbols=tuple(
            Symbol(str(s["name"]), int(s["value"]), str(s.get("label", "")), str(s.get("desc", "")))
            for s in raw.get("symbols", [])
        ),
        label=str(raw.get("label", "")),
        desc=str(raw.get("desc", "")),
        value=value if isinstance(value, int) else None,
    )
