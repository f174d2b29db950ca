"""A mapping's place in the device library: the ``library:`` block.

Category, the other names people search by, the independent sources its registers were
cross-checked against, how sure it is, and every disagreement between the sources with
the choice made. The register document itself is the mapping's ``source`` (title,
version, url) and what the device speaks is ``protocol.transports``: each fact lives in
one place, so the block refuses a second copy of either with a message saying where it
belongs.
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import StrEnum
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator


class Category(StrEnum):
    """What kind of device: the library's first grouping (``mappings list --category``)."""

    METER = "meter"
    INVERTER = "inverter"
    BATTERY = "battery"
    CHARGER = "charger"
    HEAT_PUMP = "heat_pump"
    DRIVE = "drive"
    PUMP = "pump"
    GENSET = "genset"
    MOTOR_STARTER = "motor_starter"


class Disagreement(BaseModel):
    """Where the sources (or the document and a source) differ on one entity."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    entity: str = Field(description="key of the entity the sources disagree on")
    sources: tuple[str, ...] = Field(min_length=1, description="the sources that differ")
    choice: str = Field(min_length=1, description="what differs, what was chosen and why")


_ELSEWHERE = {
    "transports": "what the device speaks is protocol.transports (a config is checked against it)",
    "document": "the register document is the mapping's source: {title, version, url}",
}


class Library(BaseModel):
    """The index entry of a shipped mapping."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    category: Category
    aliases: tuple[str, ...] = Field((), description="other names and variants people search by")
    sources: tuple[str, ...] = Field(
        (), description="independent sources cross-checked (tests/library/sources)"
    )
    confidence: Literal["high", "medium", "low"] = "medium"
    disagreements: tuple[Disagreement, ...] = ()

    @model_validator(mode="before")
    @classmethod
    def _one_place(cls, data: Any) -> Any:
        if isinstance(data, dict):
            misplaced = [f"{name}: {_ELSEWHERE[name]}" for name in _ELSEWHERE if name in data]
            if misplaced:
                raise ValueError("\n".join(misplaced))
        return data


def disagreement_problems(library: Library, keys: Iterable[str]) -> list[str]:
    """Rows for each disagreement naming an entity the mapping does not have, or a
    source the block does not list."""
    known = set(keys)
    rows = []
    for index, row in enumerate(library.disagreements):
        where = f"library.disagreements.{index}"
        if row.entity not in known:
            rows.append(f"{where}.entity: no entity {row.entity!r}")
        rows += [
            f"{where}.sources: {name!r} is not in library.sources"
            for name in row.sources
            if name not in library.sources and name != "vendor"
        ]
    return rows
