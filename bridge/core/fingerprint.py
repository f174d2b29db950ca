"""A mapping's ``fingerprint:``: what a unit reads that tells it is this device model.

A fingerprint is a few probes (``MAX_PROBES`` at most), each one read of the device: a
register (or bit) named by an entity key of the mapping or by ``table`` + ``address``
(printed, as the entities give it), and one test of what it reads: ``equals`` a value,
within ``min``..``max``, ``one_of`` a set (a device-code enum), an ``ascii`` ID string
(a shell pattern: ``HGM61*``), ``unit`` (reads the unit id it was asked at), or only
``answers`` (any values, no exception). Numeric tests look at the raw word of one
register (or one bit). Each probe has a ``weight`` (0 < w <= 1): how sure a match alone
makes us that the unit is this model.

``score`` turns the probes' outcomes into a confidence:

    confidence = (1 - prod(1 - w) over matched probes) * (sum of matched w / sum of all w)

the strength of what matched, times the share of the evidence that matched: a unit
that matches every probe scores ``1 - prod(1 - w)``; a probe that fails costs its share,
a ``required`` probe that fails makes it 0. A fingerprint with ``identifies: false`` (the
manual names nothing only this device has) scores that times ``LIKE_CAP`` (0.4): the
answer is "unit answers like X", low confidence.
"""

from __future__ import annotations

import fnmatch
import math
from collections.abc import Mapping as AnyMapping
from collections.abc import Sequence
from typing import Literal, Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

from bridge.core.address import PrintedAddress, to_wire
from bridge.core.entity import Entity, Table
from bridge.core.protocol import Protocol
from bridge.core.request import Read

MAX_PROBES = 4
LIKE_CAP = 0.4
HIGH, MEDIUM = 0.75, 0.45
Level = Literal["high", "medium", "low"]


class Probe(BaseModel):
    """One read and the test of what it reads (exactly one test; ``min``/``max`` is one)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    entity: str | None = Field(None, description="key of an entity: its table, address, size")
    table: Table | None = Field(None, description="with address, when no entity names it")
    address: PrintedAddress | None = Field(None, description="as printed, like an entity's")
    count: int = Field(1, ge=1, le=125, description="registers read (an ascii string's)")
    equals: int | None = Field(None, ge=0, le=0xFFFF)
    min: int | None = Field(None, ge=0, le=0xFFFF)
    max: int | None = Field(None, ge=0, le=0xFFFF)
    one_of: tuple[int, ...] | None = Field(None, min_length=1, max_length=64)
    ascii: str | None = Field(None, min_length=1, max_length=250, description="shell pattern")
    unit: bool = Field(False, description="the register reads the unit id it was asked at")
    answers: bool = Field(False, description="any values (no exception) match")
    weight: float = Field(gt=0, le=1, description="how sure a match alone makes us")
    required: bool = Field(False, description="a unit failing it is not this model")
    note: str | None = None

    @model_validator(mode="after")
    def _one_test(self) -> Self:
        if (self.entity is None) == (self.address is None):
            raise ValueError("name the register by entity or by address (one of them)")
        if self.entity is not None and (self.table is not None or "count" in self.model_fields_set):
            raise ValueError("an entity probe takes the entity's table and size")
        if len(self._tests()) != 1:
            raise ValueError(
                "give exactly one test: equals, min/max, one_of, ascii, unit or answers"
            )
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ValueError(f"min {self.min} is above max {self.max}")
        return self

    def _tests(self) -> list[str]:
        given = [n for n in ("equals", "min", "one_of", "ascii") if getattr(self, n) is not None]
        given += [name for name in ("unit", "answers") if getattr(self, name)]
        return [*given, "min"] if self.max is not None and self.min is None else given

    @property
    def test(self) -> str:
        """The test's name (``min`` for a range)."""
        return self._tests()[0]

    def describe(self) -> str:
        """The test in words: ``reads 0x1234``, ``reads 1..247``, ``reads 'HGM61*'``."""
        if self.equals is not None:
            return f"reads 0x{self.equals:04X}"
        if self.one_of is not None:
            return "reads one of " + ", ".join(str(v) for v in self.one_of)
        if self.ascii is not None:
            return f"reads {self.ascii!r}"
        if self.unit:
            return "reads its own unit id"
        if self.answers:
            return "answers"
        low = 0 if self.min is None else self.min
        high = 0xFFFF if self.max is None else self.max
        return f"reads {low}..{high}"


class Fingerprint(BaseModel):
    """The probes that tell this device model from others on a bus."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    identifies: bool = Field(
        True,
        description="false: nothing the manual names is only this device's; a match "
        f"says 'answers like' it, its confidence times {LIKE_CAP}",
    )
    note: str | None = None
    probes: tuple[Probe, ...] = Field(min_length=1, max_length=MAX_PROBES)


def probe_read(probe: Probe, entities: AnyMapping[str, Entity], protocol: Protocol) -> Read:
    """The read ``probe`` sends (wire address; KeyError/ValueError when it cannot be)."""
    if probe.entity is not None:
        entity = entities[probe.entity]
        address = to_wire(entity.address, protocol.addressing)
        return Read(entity.table, address, entity.register_count)
    assert probe.address is not None  # the model's validator saw to it
    table = probe.table or Table.HOLDING
    return Read(table, to_wire(probe.address, protocol.addressing), probe.count)


def check_fingerprint(
    fingerprint: Fingerprint, entities: AnyMapping[str, Entity], protocol: Protocol
) -> list[str]:
    """Rows ``fingerprint.probes.<i>.<field>: message``: a probe names no entity, reads a
    table the device has no function code for, more than it reads at once, a reserved
    address, across a segment, or tests a value in a way its read cannot hold."""
    rows: list[str] = []
    for index, probe in enumerate(fingerprint.probes):
        where = f"fingerprint.probes.{index}"
        if probe.entity is not None and probe.entity not in entities:
            rows.append(f"{where}.entity: no entity {probe.entity!r}")
            continue
        try:
            read = probe_read(probe, entities, protocol)
        except ValueError as exc:
            rows.append(f"{where}.address: {exc}")
            continue
        rows.extend(f"{where}.{row}" for row in _read_problems(read, protocol))
        numeric = probe.test in ("equals", "min", "one_of", "unit")
        if numeric and read.count != 1:
            rows.append(f"{where}.{probe.test}: a number is tested on 1 register, not {read.count}")
        if read.table.is_bits and probe.test not in ("answers", "equals", "one_of"):
            rows.append(f"{where}.{probe.test}: a bit reads 0 or 1: test it with equals or one_of")
    return rows


def _read_problems(read: Read, protocol: Protocol) -> list[str]:
    rule, table = protocol.addressing, read.table
    last = read.address + read.count - 1
    if table.read_function not in protocol.function_codes:
        return [
            f"table: reading {table.value} needs function {table.read_function}, which "
            "the device does not support"
        ]
    if last > 0xFFFF:
        return [f"count: {read.count} from wire {read.address} runs past 65535"]
    limit = protocol.max_read_bits if table.is_bits else protocol.max_read_registers
    rows = []
    for segment in protocol.segments:
        low, high = to_wire(segment.start, rule), to_wire(segment.end, rule)
        if segment.table is not table or not (low <= read.address <= high or low <= last <= high):
            continue
        if not low <= read.address <= last <= high:
            rows.append(f"address: the read crosses the edge of segment {segment.name!r}")
        if segment.max_read_registers is not None and not table.is_bits:
            limit = min(limit, segment.max_read_registers)
    if read.count > limit:
        rows.append(f"count: {read.count} is more than the device reads at once ({limit})")
    for reserved in protocol.reserved:
        low = to_wire(reserved.start, rule)
        high = to_wire(reserved.end if reserved.end is not None else reserved.start, rule)
        if reserved.table is table and read.address <= high and low <= last:
            rows.append("address: the read covers a reserved address (protocol.reserved)")
    return rows


# --- judging and scoring -----------------------------------------------------------------


def matches(probe: Probe, unit: int, values: Sequence[int] | None) -> bool:
    """Whether what the unit answered (``values``; None for an exception or no answer)
    passes ``probe``'s test."""
    if values is None or not values:
        return False
    first = values[0]
    if probe.answers:
        return True
    if probe.equals is not None:
        return first == probe.equals
    if probe.one_of is not None:
        return first in probe.one_of
    if probe.unit:
        return first == unit
    if probe.ascii is not None:
        return fnmatch.fnmatchcase(ascii_text(values), probe.ascii)
    low = 0 if probe.min is None else probe.min
    high = 0xFFFF if probe.max is None else probe.max
    return low <= first <= high


def ascii_text(values: Sequence[int]) -> str:
    """Registers as text, high byte first, trailing NULs and spaces dropped; a byte that
    is not printable ASCII reads as ``?``."""
    raw = b"".join(v.to_bytes(2, "big") for v in values).rstrip(b"\x00 ")
    return "".join(chr(b) if 0x20 <= b < 0x7F else "?" for b in raw)


def score(fingerprint: Fingerprint, matched: Sequence[bool]) -> float:
    """The confidence (0..1) of the probes' outcomes (``matched[i]`` for probe i); the
    formula is the module's docstring's."""
    weights = [probe.weight for probe in fingerprint.probes]
    if len(matched) != len(weights):
        raise ValueError(f"{len(matched)} outcomes for {len(weights)} probes")
    hits = [w for w, hit in zip(weights, matched, strict=True) if hit]
    missed = (p.required for p, hit in zip(fingerprint.probes, matched, strict=True) if not hit)
    if not hits or any(missed):
        return 0.0
    strength = 1 - math.prod(1 - w for w in hits)
    confidence = strength * sum(hits) / sum(weights)
    if not fingerprint.identifies:
        confidence *= LIKE_CAP
    return round(confidence, 3)


def level(confidence: float) -> Level:
    """``high`` from 0.75, ``medium`` from 0.45, else ``low``."""
    if confidence >= HIGH:
        return "high"
    return "medium" if confidence >= MEDIUM else "low"
