"""The bridge's fair share of a device's request slots against other masters. Pure.

Requests of other masters through the gateway (``Priority.PROXY``) go before the bridge's
routine polls. On a device that allows one request a second (the Smartgen), masters that
send faster would take every slot and the bridge's own values would go stale while the
device still looks online. So when a gateway request and a due poll could both take the
same slot, the slot is *contested*, and the poll takes it whenever the polls' part of the
recent contested slots is below ``share``: with 0.5 they alternate, with 0 the masters
always go first (as before), with 1 the polls do. Commands, keepalives and reads on
request are never contested: they go first whatever the share.

A contest is decided per unit (a device's slots) when a poll of the same unit is ready;
else per bus (a poll of another unit waits for the line). The window is the last
``WINDOW`` contests of each, so an hour of masters alone does not buy them the next
minute.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

WINDOW = 20  # contested slots remembered per unit (and per bus)
BUS = -1  # the key of the bus's own contests (units are 0..255)


@dataclass(slots=True)
class FairShare:
    """Who takes the next contested slot: the bridge's poll or a master's request."""

    share: float = 0.5  # the polls' part of the contested slots (0..1)
    shares: dict[int, float] = field(default_factory=dict)  # a unit's own share
    _won: dict[int, deque[bool]] = field(default_factory=dict)  # True: the poll took it
    yielded: int = 0  # contests the masters lost
    won: int = 0  # contests the masters won

    def poll_turn(self, key: int) -> bool:
        """True when the poll takes the contested slot of ``key`` (a unit, or ``BUS``)."""
        recent = self._won.get(key, ())
        share = self.shares.get(key, self.share)
        return sum(recent) < share * (len(recent) + 1)

    def decide(self, key: int) -> bool:
        """Decide one contest of ``key`` and remember it: True when the poll takes it."""
        poll = self.poll_turn(key)
        self._won.setdefault(key, deque(maxlen=WINDOW)).append(poll)
        if poll:
            self.yielded += 1
        else:
            self.won += 1
        return poll
