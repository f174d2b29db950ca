"""A register proposed as a new entity on the page, and its value as Home Assistant shows it.

``EntityProposal`` is what the page sends (bounded: a key, a name, a wire address and the
decoding fields a user picks); ``entity_fields`` turns it into the entity of a mapping
file (the address as the mapping's manual prints it). The entity is validated by the
mapping loader itself (bridge/core/mapping.py, override.py), never by a copy of its
rules; ``preview`` then decodes the registers a commissioning read gave with the codec
the poller uses. Pure.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from bridge.core.address import Addressing
from bridge.core.codec import decimals_of, decode
from bridge.core.entity import DataType, Order, Table
from bridge.core.mapping import Mapping
from bridge.core.wording import value_text

MAX_WORDS = 125  # registers a preview may carry (one read)
Word = Annotated[int, Field(ge=0, le=0xFFFF)]


class EntityProposal(BaseModel):
    """A new read-only entity of a device's mapping, as the page proposes it."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    device: str = Field(min_length=1, max_length=100)
    key: str = Field(pattern=r"^[a-z][a-z0-9_]*$", max_length=64)
    name: str = Field(min_length=1, max_length=100)
    table: Literal["holding", "input", "coil", "discrete"] = "holding"
    address: int = Field(ge=0, le=0xFFFF, description="wire address, 0-based, as read")
    type: DataType | None = None
    count: int | None = Field(None, ge=1, le=32, description="registers of an ascii value")
    word_order: Order = Order.BIG
    byte_order: Order = Order.BIG
    scale: float = Field(1.0, allow_inf_nan=False)
    offset: float = Field(0.0, allow_inf_nan=False)
    precision: int | None = Field(None, ge=0, le=6)
    unit: str | None = Field(None, min_length=1, max_length=20)
    device_class: str | None = Field(None, pattern=r"^[a-z_]+$", max_length=40)
    state_class: str | None = Field(None, max_length=40)
    words: tuple[Word, ...] | None = Field(
        None, min_length=1, max_length=MAX_WORDS, description="registers read from address on"
    )


def entity_fields(proposal: EntityProposal, addressing: Addressing) -> dict[str, Any]:
    """The mapping file's entity: the fields that differ from their defaults, the wire
    address as printed (the addressing rule's offset undone)."""
    fields: dict[str, Any] = {
        "name": proposal.name,
        "address": proposal.address - addressing.offset,
        "table": Table(proposal.table).value,
    }
    chosen = proposal.model_dump(
        include={"type", "count", "word_order", "byte_order", "scale", "offset", "precision"},
        exclude_defaults=True,
        mode="json",
    )
    fields |= chosen
    if proposal.unit is not None:
        fields["unit"] = proposal.unit
    ha = proposal.model_dump(include={"device_class", "state_class"}, exclude_none=True)
    if ha:
        fields["ha"] = ha
    if fields["table"] == Table.HOLDING.value:
        del fields["table"]
    return fields


def preview(mapping: Mapping, key: str, words: Sequence[int]) -> dict[str, Any]:
    """Entity ``key`` of ``mapping`` decoded from ``words`` (the registers, or bits, read
    from its wire address on): ``value`` as published, ``text`` and ``unit`` as Home
    Assistant shows them. ValueError when fewer registers were read than it spans."""
    point = mapping.points()[key]
    if len(words) < point.count:
        raise ValueError(f"words: {key} spans {point.count} registers, {len(words)} given")
    image = {(point.table, point.address + i): word for i, word in enumerate(words)}
    value = decode(point, image)
    decimals = decimals_of(point, image)
    entity = point.entity
    return {
        "key": key,
        "value": value,
        "text": value_text(entity, value, decimals, allow_dangerous_writes=False),
        "unit": entity.unit,
        "decimals": decimals,
        "component": entity.component.value,
        "registers": point.count,
    }
