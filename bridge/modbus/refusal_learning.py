"""Learning what a device refuses, with real reads through its link
(bridge/modbus/device_link.py) into what it knows (bridge/core/device_state.py).

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

from bridge.core.device_state import DeviceState
from bridge.core.planner import Address, addresses_of
from bridge.core.refusal import Refusal, refusal_search
from bridge.core.refusal_memory import Verdict
from bridge.core.request import Read
from bridge.errors import DeviceExceptionError, ModbusError
from bridge.modbus.device_link import DeviceLink, Refused
from bridge.modbus.scheduler import Priority

log = logging.getLogger(__name__)


class RefusalLearner:
    """Learns one device's refused addresses through its link."""

    def __init__(self, state: DeviceState, link: DeviceLink) -> None:
        self.state = state
        self.link = link

    async def judge(self, refused: list[Refused], priority: Priority, fresh: set[Address]) -> bool:
        """Search the blocks refused whole and learn their holes, unless the device refuses
        what it answered before or everything (bridge/core/refusal_memory.py): then it is a
        failure towards offline and nothing is learnt. True if any part answered."""
        if not refused:
            return False
        memory = self.state.refusals
        verdict = memory.judge(len(fresh), [addresses_of(r) for r, _ in refused])
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
            if not alive and not memory.explains(refusal.refused):
                self._refused_everything()
                return answered
            self._remember(refusal, exc)
        return answered

    async def _search(
        self, read: Read, priority: Priority, fresh: set[Address]
    ) -> tuple[bool, Refusal | None]:
        """Bisect a refused block with real reads: whether any part answered, and what the
        device refused (None when it stopped answering meanwhile)."""
        search = refusal_search(read, list(self.state.points.values()))
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
            values = await self.link.submit(read, priority)
        except DeviceExceptionError as exc:
            if exc.action == "refused":
                return False
            raise
        self.link.keep(read, values, fresh)
        return True

    def _remember(self, refusal: Refusal, exc: DeviceExceptionError) -> None:
        """Avoid what the device refused until the re-check (logged the first time, with the
        device's reason), and read no more registers at once than it showed it takes."""
        device_id = self.link.device.id
        first = self.state.avoid(refusal.refused, time.monotonic())
        if first:
            log.warning(
                "%s refused %s with %s; not read again for %.0f s",
                device_id,
                self.state.shown(first),
                exc,
                self.state.refusals.recheck,
            )
        elif refusal.refused:
            log.debug("%s refused %s again", device_id, self.state.shown(refusal.refused))
        if refusal.max_count is not None and self.state.limit_reads(refusal.max_count):
            log.warning(
                "%s: at most %d registers per read; plans adjusted",
                device_id,
                self.state.max_read,
            )

    def recheck(self) -> None:
        """Forget the refusals learnt ``refusal_recheck`` ago: the next plan reads them."""
        due = self.state.recheck(time.monotonic())
        if due:
            log.debug(
                "%s: reading %s again (refused before)", self.link.device.id, self.state.shown(due)
            )

    def _refused_everything(self) -> None:
        """A pass refused as a whole: a device fault (nothing learnt), a failure."""
        health = self.link.health
        self.link.announce(health.refuses_every_read(time.monotonic()), first_contact=False)
