"""Learning what a device refuses, with real reads (beside its poller,
bridge/modbus/poller.py).

A block the device refuses whole (exception 2, illegal data address) is bisected
(bridge/core/refusal.py) into the parts it answers and the addresses it refuses; those
are avoided until their re-check, and a device that shows it takes fewer registers per
read than mapped gets smaller reads. A device that refuses what it answered before, or
everything, is not learnt from: that is a fault towards offline
(bridge/core/refusal_memory.py).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterable
from typing import TYPE_CHECKING

from bridge.core.entity import Table
from bridge.core.mapping import printed_address
from bridge.core.planner import addresses_of
from bridge.core.refusal import Refusal, refusal_search
from bridge.core.refusal_memory import Verdict
from bridge.core.request import Read
from bridge.errors import DeviceExceptionError, ModbusError
from bridge.modbus.scheduler import Priority

if TYPE_CHECKING:
    from bridge.modbus.poller import DevicePoller

log = logging.getLogger(__name__)
Address = tuple[Table, int]
Refused = tuple[Read, DeviceExceptionError]  # a block refused whole, with the refusal


class RefusalLearner:
    """Learns one device's refused addresses through its poller."""

    def __init__(self, poller: DevicePoller) -> None:
        self.poller = poller

    async def judge(self, refused: list[Refused], priority: Priority, fresh: set[Address]) -> bool:
        """Search the blocks refused whole and learn their holes, unless the device refuses
        what it answered before or everything (bridge/core/refusal_memory.py): then it is a
        failure towards offline and nothing is learnt. True if any part answered."""
        if not refused:
            return False
        verdict = self.poller.refusals.judge(len(fresh), [addresses_of(r) for r, _ in refused])
        if verdict is Verdict.FAULT:
            self._refused_everything()
            return False
        alive, answered = verdict is Verdict.LEARN, False
        for read, exc in sorted(refused, key=lambda item: item[0].count):
            some, refusal = await self._search(read, priority, fresh)
            if refusal is None:
                return answered  # the device stopped answering meanwhile: learn next time
            answered = answered or some
            alive = alive or some
            if not alive and not self.poller.refusals.explains(refusal.refused):
                self._refused_everything()
                return answered
            self._remember(refusal, exc)
        return answered

    async def _search(
        self, read: Read, priority: Priority, fresh: set[Address]
    ) -> tuple[bool, Refusal | None]:
        """Bisect a refused block with real reads: whether any part answered, and what the
        device refused (None when it stopped answering meanwhile)."""
        search = refusal_search(read, list(self.poller.points.values()))
        answered = False
        try:
            part = next(search)
            while True:
                ok = await self._probe(part, priority, fresh)
                answered = answered or ok
                part = search.send(ok)
        except StopIteration as done:
            return answered, done.value
        except ModbusError:
            return answered, None

    async def _probe(self, read: Read, priority: Priority, fresh: set[Address]) -> bool:
        """One read of a bisection: True answered (values kept), False refused."""
        try:
            values = await self.poller.submit(read, priority)
        except DeviceExceptionError as exc:
            if exc.action == "refused":
                return False
            raise
        self.poller.keep(read, values, fresh)
        return True

    def _remember(self, refusal: Refusal, exc: DeviceExceptionError) -> None:
        """Avoid what the device refused until the re-check (logged the first time, with the
        device's reason), and read no more registers at once than it showed it takes."""
        avoided = self.poller.refusals.refused
        first = self.poller.refusals.learn(refusal.refused, time.monotonic())
        if first:
            log.warning(
                "%s refused %s with %s; not read again for %.0f s",
                self.poller.device.id,
                self.shown(first),
                exc,
                self.poller.refusals.recheck,
            )
        elif refusal.refused:
            log.debug("%s refused %s again", self.poller.device.id, self.shown(refusal.refused))
        if refusal.refused - avoided:
            self.poller.forget_plans()
        if refusal.max_count is not None and refusal.max_count < (self.poller.max_read or 0x10000):
            self.poller.max_read = refusal.max_count
            log.warning(
                "%s: at most %d registers per read; plans adjusted",
                self.poller.device.id,
                self.poller.max_read,
            )
            self.poller.forget_plans()

    def shown(self, addresses: Iterable[Address]) -> str:
        """``holding 0x00A0 (wire 159)``: the address as the manual prints it, and as sent."""
        points, protocol = self.poller.points.values(), self.poller.protocol
        return ", ".join(
            f"{table.value} {printed_address(points, table, wire, protocol)} (wire {wire})"
            for table, wire in sorted(addresses)
        )

    def recheck(self) -> None:
        """Forget the refusals learnt ``refusal_recheck`` ago: the next plan reads them."""
        due = self.poller.refusals.expire(time.monotonic())
        if due:
            log.debug(
                "%s: reading %s again (refused before)", self.poller.device.id, self.shown(due)
            )
            self.poller.forget_plans()

    def _refused_everything(self) -> None:
        """A pass refused as a whole: a device fault (nothing learnt), a failure."""
        self.poller.announce(
            self.poller.health.refuses_every_read(time.monotonic()), first_contact=False
        )
