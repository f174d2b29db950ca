"""What answers at a unit: the library's fingerprints against what the unit read. Pure.

After scan's probe ``identify`` walks a SunSpec device's model chain (bridge/sunspec/
walk.py: the marker at 40000, 50000, 0, then the models; ``SunSpecDevice`` is what it
found), else reads each
mapping's fingerprint reads (``probes_of``: required probes first; a mapping a failed
required probe rules out gets no more reads; a read two mappings share is sent once:
``probe_plan`` lists them all). ``rank`` scores each mapping
(bridge/core/fingerprint.py) on the answers and orders the matches; ``Identity`` is one
unit's answer, with the config snippet to paste.

Bound: at most ``1 + max(walk, bases + MAX_PROBES x mappings)`` requests per unit
(``request_bound``; 47 with the five shipped mappings); a unit that does not answer scan's
probe costs that one timeout; a unit that answered and then leaves ``MAX_SILENT`` reads
unanswered is left.
"""

from __future__ import annotations

from collections.abc import Mapping as AnyMapping
from dataclasses import dataclass
from typing import Any

from bridge.core.fingerprint import (
    MAX_PROBES,
    Level,
    Probe,
    level,
    matches,
    probe_read,
    score,
)
from bridge.core.mapping import Mapping
from bridge.core.request import Read

MAX_SILENT = 2
MAX_MATCHES = 3
Answers = AnyMapping[Read, tuple[int, ...] | None]  # None: refused, garbled or silent


def request_bound(library: AnyMapping[str, Mapping], walk: int, bases: int) -> int:
    """The most requests ``identify`` sends one unit (scan's probe included): a SunSpec
    device's walk (at most ``walk`` requests) or, where ``bases`` reads found no marker,
    the library's probes."""
    return 1 + max(walk, bases + MAX_PROBES * len(library))


@dataclass(frozen=True, slots=True)
class SunSpecDevice:
    """A SunSpec device as its walk found it: the marker's base, the common model's
    strings (None where unimplemented), the model ids in chain order; ``note`` when the
    chain could not be walked to its end (the marker is there all the same)."""

    base: int
    manufacturer: str | None = None
    model: str | None = None
    version: str | None = None
    serial_number: str | None = None
    models: tuple[int, ...] = ()
    note: str | None = None

    def describe(self) -> str:
        named = " ".join(p for p in (self.manufacturer, self.model) if p) or "unnamed"
        extra = [f"serial {self.serial_number}"] if self.serial_number else []
        extra += [f"version {self.version}"] if self.version else []
        extra += [f"models {', '.join(map(str, self.models))}"] if self.models else []
        extra += [f"marker at {self.base}"]
        return f"SunSpec device {named} ({'; '.join(extra)})"

    def as_dict(self) -> dict[str, Any]:
        return {
            "base": self.base,
            "manufacturer": self.manufacturer,
            "model": self.model,
            "version": self.version,
            "serial_number": self.serial_number,
            "models": list(self.models),
            "note": self.note,
        }


def probes_of(mapping: Mapping) -> tuple[tuple[Probe, Read], ...]:
    """A mapping's probes with their reads, the required ones first: once one of those
    fails the mapping is ruled out and its other reads need not be sent."""
    if mapping.fingerprint is None:
        return ()
    probes = sorted(mapping.fingerprint.probes, key=lambda probe: not probe.required)
    return tuple((p, probe_read(p, mapping.entities, mapping.protocol)) for p in probes)


def probe_plan(library: AnyMapping[str, Mapping]) -> tuple[Read, ...]:
    """Every distinct fingerprint read of the library, in table and address order."""
    reads = {
        probe_read(probe, mapping.entities, mapping.protocol)
        for mapping in library.values()
        if mapping.fingerprint is not None
        for probe in mapping.fingerprint.probes
    }
    return tuple(sorted(reads, key=lambda r: (r.table.value, r.address, r.count)))


@dataclass(frozen=True, slots=True)
class Match:
    """One mapping's score at a unit: ``like`` when its fingerprint does not identify."""

    mapping: str
    manufacturer: str
    model: str
    confidence: float
    level: Level
    like: bool
    matched: tuple[str, ...]
    failed: tuple[str, ...]

    def describe(self) -> str:
        """``Nastec VASCO (nastec_vasco): 0.78 high``; ``answers like ...`` when it only
        answers like it."""
        what = f"{self.manufacturer} {self.model} ({self.mapping})"
        prefix = "answers like " if self.like else ""
        return f"{prefix}{what}: {self.confidence:.2f} {self.level}"

    def as_dict(self) -> dict[str, Any]:
        return {
            "mapping": self.mapping,
            "manufacturer": self.manufacturer,
            "model": self.model,
            "confidence": self.confidence,
            "level": self.level,
            "answers_like": self.like,
            "matched": list(self.matched),
            "failed": list(self.failed),
        }


def rank(library: AnyMapping[str, Mapping], unit: int, answers: Answers) -> tuple[Match, ...]:
    """The mappings whose fingerprints the answers match (confidence above 0), best first
    (ties by name), at most ``MAX_MATCHES``. A read not in ``answers`` counts as failed."""
    found = []
    for name, mapping in library.items():
        if mapping.fingerprint is None:
            continue
        outcomes, said = [], []
        for probe in mapping.fingerprint.probes:
            read = probe_read(probe, mapping.entities, mapping.protocol)
            outcomes.append(matches(probe, unit, answers.get(read)))
            where = probe.entity or f"{read.table.value} {read.address}"
            said.append(f"{where} {probe.describe()}")
        confidence = score(mapping.fingerprint, outcomes)
        if confidence > 0:
            hit = tuple(s for s, ok in zip(said, outcomes, strict=True) if ok)
            miss = tuple(s for s, ok in zip(said, outcomes, strict=True) if not ok)
            like = not mapping.fingerprint.identifies
            found.append(
                Match(name, mapping.manufacturer, mapping.model, confidence, level(confidence),
                      like, hit, miss)
            )  # fmt: skip
    found.sort(key=lambda m: (-m.confidence, m.mapping))
    return tuple(found[:MAX_MATCHES])


def snippet(bus: str, unit: int, mapping: str) -> str:
    """The device entry to paste into the config's ``devices:``."""
    return f"- id: {mapping}_{unit}\n  bus: {bus}\n  unit: {unit}\n  mapping: {mapping}\n"


@dataclass(frozen=True, slots=True)
class Identity:
    """What one unit is: a SunSpec device (``sunspec``), library matches, or neither.
    ``requests``: the requests sent to it; ``note``: why probing stopped early, if it did."""

    unit: int
    bus: str
    sunspec: SunSpecDevice | None
    matches: tuple[Match, ...]
    requests: int
    note: str | None = None

    @property
    def best(self) -> str | None:
        """The mapping to configure: ``sunspec`` for a SunSpec device, else the best match."""
        if self.sunspec is not None:
            return "sunspec"
        return self.matches[0].mapping if self.matches else None

    def summary(self) -> str:
        """One line for people."""
        if self.sunspec is not None:
            return self.sunspec.describe()
        if not self.matches:
            return "answers, but matches no mapping of the library"
        return self.matches[0].describe()

    def as_dict(self) -> dict[str, Any]:
        best = self.best
        return {
            "unit": self.unit,
            "summary": self.summary(),
            "sunspec": None if self.sunspec is None else self.sunspec.as_dict(),
            "matches": [m.as_dict() for m in self.matches],
            "requests": self.requests,
            "note": self.note,
            "config": None if best is None else snippet(self.bus, self.unit, best),
        }
