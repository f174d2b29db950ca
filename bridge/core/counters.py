"""Counters that never go backwards by accident. Pure.

Home Assistant's long-term statistics read any drop of a ``total_increasing`` sensor as a
meter reset and add the whole new value again: one reading of 0 after a power cycle, a
torn 32-bit read or a jitter of one digit puts thousands of phantom kWh in the energy
dashboard. A ``Counter`` stands between what a device reads and what is published:

- a reading at or above the published value is published (``RISE``);
- a reading that rolled over the counter's width (from its top eighth into its bottom
  eighth, not 0) continues it: the width is added from then on (``WRAP``);
- a lower reading is held back (``HELD``): the published value stays. A decrease of at
  most ``jitter`` least significant digits never becomes anything else; a larger one
  becomes a reset only when ``confirm`` readings in a row are below the published value
  and none of them below the one before it (the same lower value, or a new count rising
  from it): then the latest is published once (``RESET``);
- a reading that is not a number (a failed read, a sentinel) is held too: a counter is
  never published as 0 or null because a read failed.

``seed`` sets the value published before a restart (read back from the retained state),
so the first reading after a start is checked like any other.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import StrEnum

from bridge.core.entity import DataType
from bridge.core.mapping import Point

CONFIRM = 3  # lower readings in a row that confirm a decrease, unless an entity says
JITTER = 3  # decreases of at most this many least significant digits are only held
COUNTER_CLASSES = frozenset({"total", "total_increasing"})


class Kind(StrEnum):
    """What became of one reading."""

    FIRST = "first"  # nothing published before: published as read
    RISE = "rise"  # same or higher: published
    WRAP = "wrap"  # rolled over its width: published as a continuation
    HELD = "held"  # lower and not confirmed, or not a number: the published value stays
    RESET = "reset"  # a decrease confirmed: published once, the start of a new count


@dataclass(frozen=True, slots=True)
class Reading:
    """One reading's outcome: ``value`` is what the counter publishes now."""

    kind: Kind
    value: float | None
    before: float | None = None  # the value published before (for a hold or a reset)
    reason: str = ""  # why a reading was held: "zero", "lower", "jitter", "not a number"
    read: object = None  # what was read (for a hold)

    @property
    def published(self) -> bool:
        """True when ``value`` is new to publish."""
        return self.kind is not Kind.HELD


@dataclass(frozen=True, slots=True)
class CounterRule:
    """How one counter is read: confirmations, width and smallest step."""

    confirm: int = CONFIRM
    wrap: float | None = None  # the published value at which it rolls over; None: never
    lsb: float = 1.0  # one least significant digit, in published units
    jitter: int = JITTER

    @classmethod
    def of(cls, point: Point, confirm: int | None = None) -> CounterRule:
        """The rule of a mapping point: width from its type, step from its scale (a
        ``scale_by`` counter's step moves with its exponent: no rollover is continued)."""
        entity = point.entity
        lsb = abs(entity.scale) or 1.0
        width = counter_width(point)
        fixed = not entity.offset and point.scale_source is None
        wrap = width * lsb if width and fixed else None
        return cls(confirm=confirm or CONFIRM, wrap=wrap, lsb=lsb)


def counter_width(point: Point) -> int | None:
    """Raw values a counter holds before it rolls over (unsigned 16 and 32-bit only)."""
    entity = point.entity
    if entity.kind != "number" or entity.bit is not None:
        return None
    if entity.data_type is DataType.U16:
        return 1 << 16
    if entity.data_type is DataType.U32:
        return (1 << 16) * point.entity.word_radix
    return None


@dataclass(slots=True)
class Counter:
    """One counter's published value and the lower readings waiting for confirmation."""

    rule: CounterRule
    published: float | None = None
    offset: float = 0.0  # widths added by rollovers since the count started
    lower: list[float] = field(default_factory=list)  # lower raw readings in a row

    def seed(self, value: float) -> bool:
        """Take ``value`` as published before (a retained state at start); True when it
        is now the published value (nothing, or less, was published since)."""
        if not _is_number(value) or (self.published is not None and value <= self.published):
            return False
        self.published = float(value)
        wrap = self.rule.wrap
        self.offset = math.floor(value / wrap) * wrap if wrap else 0.0
        self.lower.clear()
        return True

    def read(self, value: object) -> Reading:
        """The outcome of one reading (the decoded value, or None when the read failed)."""
        if not _is_number(value):
            return Reading(Kind.HELD, self.published, self.published, "not a number", value)
        raw = float(value)  # type: ignore[arg-type]
        if self.published is None:
            return self._publish(Kind.FIRST, raw)
        if raw + self.offset >= self.published:
            return self._publish(Kind.RISE, raw)
        if self._wraps(raw):
            self.offset += self.rule.wrap or 0.0
            return self._publish(Kind.WRAP, raw)
        return self._lower(raw)

    def _publish(self, kind: Kind, raw: float) -> Reading:
        before = self.published
        self.published = raw + self.offset
        self.lower.clear()
        return Reading(kind, self.published, before)

    def _wraps(self, raw: float) -> bool:
        wrap = self.rule.wrap
        if not wrap or raw <= 0 or self.published is None:
            return False
        last = self.published - self.offset
        return last >= wrap * 7 / 8 and raw < wrap / 8

    def _lower(self, raw: float) -> Reading:
        before = self.published
        assert before is not None
        if before - (raw + self.offset) <= self.rule.jitter * self.rule.lsb * (1 + 1e-9):
            self.lower.clear()
            return Reading(Kind.HELD, before, before, "jitter", raw)
        if self.lower and raw < self.lower[-1]:
            self.lower.clear()
        self.lower.append(raw)
        if len(self.lower) < self.rule.confirm:
            return Reading(Kind.HELD, before, before, "zero" if raw == 0 else "lower", raw)
        self.offset = 0.0
        self.published = raw
        self.lower.clear()
        return Reading(Kind.RESET, raw, before)


def _is_number(value: object) -> bool:
    """A finite int or float a float can hold (a retained document may carry 10**400)."""
    if not isinstance(value, int | float) or isinstance(value, bool):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def is_counter(point: Point) -> bool:
    """True for a readable number Home Assistant sums: state class total or total_increasing."""
    entity = point.entity
    return entity.readable and entity.kind == "number" and entity.ha.state_class in COUNTER_CLASSES


def counters_of(
    points: Iterable[Point], confirm: dict[str, int] | None = None
) -> dict[str, Counter]:
    """A counter for every counter point, with its confirmation count (``confirm`` by key,
    else the entity's own ``confirm_reset``, else ``CONFIRM``)."""
    confirm = confirm or {}
    return {
        point.key: Counter(
            CounterRule.of(point, confirm.get(point.key) or point.entity.confirm_reset)
        )
        for point in points
        if is_counter(point)
    }
