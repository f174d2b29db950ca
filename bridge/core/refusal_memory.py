"""Learnt refusals: a map of a device's holes, not a record of its bad moments.

A device refuses a read ("illegal data address", or any code its mapping calls refused)
for one of two reasons. Either the block holds an address the device does not have (a
hole: search the block, remember the address, plan around it), or the device is not
serving reads at all just now (rebooting, a gateway answering every request with 02): a
device fault, counted towards offline like a timeout, from which nothing is learnt.

The poller reads a pass (one poll, or one read-now) and hands the blocks refused whole to
``judge``, with how many addresses the pass answered:

- ``FAULT`` when the blocks it refused, counting only those it had answered in full
  before, hold more addresses than it answered: it refuses what it served a moment ago,
  and nothing else explains that. Nothing is searched or learnt.
- ``SEARCH`` when it answered nothing, but the refused blocks hold addresses it never
  answered: search them (smallest first). The first part that answers proves the device
  alive; a search that answers nothing and finds an address never refused before is a
  fault (``explains`` says when it is only a learnt hole refused again).
- ``LEARN`` otherwise: search every refused block and learn what it refused.

A learnt refusal is forgotten ``recheck`` seconds after it was learnt, so the next plan
reads it again: answered, it is a register again; refused, it is learnt again (quietly:
``learn`` returns only the addresses refused for the first time, for the log).
Pure: the caller passes the monotonic time in.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum

from bridge.core.planner import Address


class Verdict(StrEnum):
    """What a pass's refused blocks mean."""

    FAULT = "fault"  # not serving reads: learn nothing, one failure towards offline
    SEARCH = "search"  # nothing answered yet: search, an answer proves the device alive
    LEARN = "learn"  # the device answers: search the refused blocks, learn the holes


@dataclass(slots=True)
class RefusalMemory:
    """What one device refused (and when), and what it answered since."""

    recheck: float  # seconds a learnt refusal is trusted (HealthPolicy.refusal_recheck)
    learnt: dict[Address, float] = field(default_factory=dict)  # address -> learnt at
    answered: set[Address] = field(default_factory=set)  # answered, not refused since
    refused_before: set[Address] = field(default_factory=set)  # learnt, not answered since

    @property
    def refused(self) -> frozenset[Address]:
        """The addresses plans avoid now."""
        return frozenset(self.learnt)

    def judge(self, answered: int, blocks: Sequence[frozenset[Address]]) -> Verdict:
        """The verdict on a pass that answered ``answered`` addresses and refused ``blocks``."""
        known = sum(len(block) for block in blocks if block and block <= self.answered)
        if known > answered:
            return Verdict.FAULT
        return Verdict.LEARN if answered else Verdict.SEARCH

    def explains(self, refused: Iterable[Address]) -> bool:
        """True when a search that answered nothing found only holes learnt before."""
        found = frozenset(refused)
        return bool(found) and found <= self.refused_before

    def learn(self, addresses: Iterable[Address], now: float) -> frozenset[Address]:
        """Avoid these addresses until ``now + recheck``; return those refused for the
        first time (a re-check refused again is not news)."""
        found = frozenset(addresses)
        for address in found:
            self.learnt[address] = now
        self.answered -= found
        first = found - self.refused_before
        self.refused_before |= found
        return first

    def answer(self, addresses: Iterable[Address]) -> frozenset[Address]:
        """Note addresses the device answered; return those it had refused (now readable)."""
        found = frozenset(addresses)
        self.answered |= found
        back = found & self.refused_before
        self.refused_before -= back
        for address in back:
            self.learnt.pop(address, None)
        return back

    def expire(self, now: float) -> frozenset[Address]:
        """Forget the refusals learnt ``recheck`` seconds ago or more; return them."""
        due = frozenset(a for a, at in self.learnt.items() if now - at >= self.recheck)
        for address in due:
            del self.learnt[address]
        return due
