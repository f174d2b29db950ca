"""Poll intervals: what each entity's interval is, and when each interval is due. Pure.

An entity polls at ``fast``, ``slow`` (the device config's named defaults), ``once`` or
its own interval in seconds: the mapping's ``poll``, else a device config's
``poll.entities`` (an entity key, or a glob such as ``grid_*``), which wins over the
mapping. ``PollRule`` resolves every entity to seconds (``ONCE``: never again).

A ``Schedule`` keeps one tick per interval, all counted from one origin: the tick ``n``
of an interval is ``origin + n * interval``, so intervals that are multiples of one
another fall on the same instant (a 5 s and a 60 s entity are due together every 60 s,
and read in one pass) and a pass that ran late never shifts the ticks after it. After a
pass, each interval it served moves to its first tick after the pass ended: ticks missed
meanwhile are skipped, not queued.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from fnmatch import fnmatchcase

from bridge.core.entity import MAX_INTERVAL, MIN_INTERVAL, Entity, PollClass, PollSpec, parse_poll

__all__ = ["MAX_INTERVAL", "MIN_INTERVAL", "ONCE", "PollRule", "PollSpec", "Schedule", "parse_poll"]

ONCE = math.inf  # the interval of an entity read once (at start, retried until it answers)
_GLOB = frozenset("*?[")


def is_glob(pattern: str) -> bool:
    return not _GLOB.isdisjoint(pattern)


@dataclass(frozen=True, slots=True)
class PollRule:
    """A device's named intervals and its per-entity choices (key or glob -> spec, in the
    order written: an exact key wins, else the first glob that matches)."""

    fast: float = 2.0
    slow: float = 60.0
    entities: tuple[tuple[str, PollSpec], ...] = ()

    def seconds(self, spec: PollSpec) -> float:
        """The interval a spec stands for on this device."""
        if spec is PollClass.FAST:
            return self.fast
        if spec is PollClass.SLOW:
            return self.slow
        if spec is PollClass.ONCE:
            return ONCE
        return float(spec)

    def spec_of(self, key: str, entity: Entity) -> PollSpec:
        """The device config's choice for ``key``, else the mapping's."""
        chosen = dict(self.entities)
        if key in chosen and not is_glob(key):
            return chosen[key]
        for pattern, spec in self.entities:
            if is_glob(pattern) and fnmatchcase(key, pattern):
                return spec
        return entity.poll_spec

    def interval_of(self, key: str, entity: Entity) -> float:
        return self.seconds(self.spec_of(key, entity))

    def intervals(self, entities: Mapping[str, Entity]) -> dict[str, float]:
        """Every entity's interval in seconds (``ONCE`` for once)."""
        return {key: self.interval_of(key, entity) for key, entity in entities.items()}

    def unmatched(self, keys: Iterable[str]) -> list[str]:
        """The per-entity choices that name no key of ``keys`` (a typo, an old key)."""
        known = list(keys)
        return [
            pattern
            for pattern, _ in self.entities
            if not any(fnmatchcase(k, pattern) if is_glob(pattern) else k == pattern for k in known)
        ]


@dataclass(slots=True)
class Schedule:
    """The next tick of each interval, counted from ``origin`` (monotonic seconds)."""

    origin: float
    next_due: dict[float, float] = field(default_factory=dict)

    @classmethod
    def of(cls, intervals: Iterable[float], origin: float) -> Schedule:
        """Every interval due at ``origin`` (the first pass reads everything)."""
        return cls(origin, dict.fromkeys(sorted(set(intervals)), origin))

    def due(self, now: float) -> frozenset[float]:
        """The intervals whose tick has come."""
        return frozenset(i for i, at in self.next_due.items() if at <= now)

    def served(self, intervals: Iterable[float], ended: float) -> None:
        """These intervals were read in a pass that ended at ``ended``: each moves to its
        first tick after that (``ONCE`` to never)."""
        for interval in intervals:
            self.next_due[interval] = self.tick_after(interval, ended)

    def retry(self, interval: float, at: float) -> None:
        """Be due again at ``at`` (a ``once`` read that got no answer)."""
        self.next_due[interval] = at

    def tick_after(self, interval: float, now: float) -> float:
        """The first tick of ``interval`` after ``now``."""
        if not math.isfinite(interval):
            return math.inf
        step = math.floor((now - self.origin) / interval) + 1
        while self.origin + step * interval <= now:  # float rounding put it on ``now``
            step += 1
        return self.origin + step * interval

    def wake(self) -> float:
        """When the next interval is due (inf when none will be)."""
        return min(self.next_due.values(), default=math.inf)
