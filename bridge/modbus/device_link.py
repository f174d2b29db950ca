"""How one device talks to its bus: requests through the bus scheduler, their outcomes
counted, its state of health announced.

``submit`` sends one request (a device locked by a password is unlocked once and the
request sent again, bridge/modbus/unlock.py) and records how it ended in the device's
health (bridge/core/health.py) and its watchdog (bridge/core/watchdog.py); a change of
health (online, offline with the reason, locked) is logged once and announced through
``on_change``. ``read_block`` reads one block into what the device knows
(bridge/core/device_state.py); a block the device refuses is judged with the rest of its
pass, or on its own through ``judge`` (the device's refusal learning,
bridge/modbus/refusal_learning.py, which sits above this module and is handed in).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Awaitable, Callable
from typing import Protocol

from bridge.config import DeviceConfig
from bridge.core.device_state import DeviceState
from bridge.core.health import DeviceHealth, Fault, HealthPolicy, Outcome, Transition
from bridge.core.planner import Address
from bridge.core.request import Read, Write, WriteSequence
from bridge.core.watchdog import Watchdog
from bridge.errors import (
    BusError,
    DeviceExceptionError,
    DeviceTimeoutError,
    FrameError,
    ModbusError,
)
from bridge.modbus.scheduler import BusScheduler, Priority
from bridge.modbus.unlock import Unlocker

log = logging.getLogger(__name__)

Refused = tuple[Read, DeviceExceptionError]  # a block refused whole, with the refusal
Changes = Callable[[frozenset[str]], None]  # the keys whose value changed (empty: health)
Judge = Callable[[list[Refused], Priority, set[Address]], Awaitable[bool]]


class Link(Protocol):
    """What the write path needs of a device's link: a ``DeviceLink``, or in a unit test a
    fake that stands in for the bus (tests/unit/test_writer.py)."""

    device: DeviceConfig
    retries: int  # resends of an idempotent write

    async def submit(
        self,
        request: Read | Write | WriteSequence,
        priority: Priority,
        retries: int | None = None,
        deadline: float | None = None,
    ) -> tuple[int, ...]: ...

    async def read_block(
        self,
        read: Read,
        priority: Priority,
        fresh: set[Address],
        refused: list[Refused] | None = None,
    ) -> bool: ...


class DeviceLink:
    """One device's requests through its bus scheduler, and its health."""

    def __init__(
        self,
        device: DeviceConfig,
        state: DeviceState,
        scheduler: BusScheduler,
        *,
        timeout: float,
        retries: int,
        policy: HealthPolicy,
        on_change: Changes,
        judge: Judge,
    ) -> None:
        self.device = device
        self.state = state
        self.scheduler = scheduler
        self.timeout = timeout
        self.retries = retries
        self.health = DeviceHealth(policy)
        self.unlocker = Unlocker(device, state.protocol)
        keepalive = state.protocol.keepalive
        self.watchdog = Watchdog(keepalive.interval) if keepalive is not None else None
        self.on_change = on_change
        self.judge = judge

    async def read_block(
        self,
        read: Read,
        priority: Priority,
        fresh: set[Address],
        refused: list[Refused] | None = None,
    ) -> bool:
        """One read into the device's image. A refusal is judged with the rest of the pass
        (added to ``refused``) or, without a pass, on its own; True if the read (or a part
        of it) answered."""
        try:
            values = await self.submit(read, priority)
        except DeviceExceptionError as exc:
            if exc.action != "refused":
                return False
            if refused is not None:
                refused.append((read, exc))
                return False
            return await self.judge([(read, exc)], priority, fresh)
        except ModbusError:
            return False
        self.keep(read, values, fresh)
        return True

    def keep(self, read: Read, values: tuple[int, ...], fresh: set[Address]) -> None:
        """A read's answer into the image; addresses refused before and answered now are
        read again (the plans are made again)."""
        back = self.state.keep(read, values, fresh)
        self.state.stamp(((read.table, a) for a in read.span), time.monotonic())
        if back:
            log.info("%s answers %s again; read again", self.device.id, self.state.shown(back))

    async def submit(
        self,
        request: Read | Write | WriteSequence,
        priority: Priority,
        retries: int | None = None,
        deadline: float | None = None,
    ) -> tuple[int, ...]:
        """One request through the bus scheduler, its outcome counted. A device locked by
        a password is unlocked once and the request sent again (bridge/modbus/unlock.py)."""
        return await self.unlocker.submit(
            lambda: self._submit(request, priority, retries, deadline),
            lambda write: self._submit(write, Priority.WRITE, self.retries, None),
            self._locked_out,
        )

    async def proxy(
        self, request: Read, deadline: float, yielded: Callable[[], None] | None = None
    ) -> tuple[int, ...]:
        """Another master's read through the gateway: after commands, its slot contested
        with the bridge's polls (the fair share: ``yielded`` is told each slot it gave
        up), ended unsent with CommandExpiredError if still waiting at ``deadline``."""
        return await self.unlocker.submit(
            lambda: self._submit(request, Priority.PROXY, None, deadline, yielded),
            lambda write: self._submit(write, Priority.WRITE, self.retries, None),
            self._locked_out,
        )

    def _locked_out(self, reason: str) -> None:
        """The device stays locked: in error with the reason (logged once), offline."""
        if self.health.fault is not Fault.LOCKED:
            log.error("%s: %s", self.device.id, reason)
            self.announce(self.health.locked(time.monotonic(), reason), first_contact=False)

    async def _submit(
        self,
        request: Read | Write | WriteSequence,
        priority: Priority,
        retries: int | None,
        deadline: float | None,
        yielded: Callable[[], None] | None = None,
    ) -> tuple[int, ...]:
        if retries is None:  # reads are not resent: the next cycle reads again
            retries = 0
        answer: list[float] = []  # the device's time per frame, not the wait before it
        try:
            values = await self.scheduler.submit(
                self.device.unit,
                request,
                timeout=self.timeout,
                priority=priority,
                retries=retries,
                protocol=self.state.protocol,
                deadline=deadline,
                answered=answer.append,
                yielded=yielded,
            )
        except DeviceTimeoutError:
            self._record(Outcome.TIMEOUT)
            raise
        except (BusError, FrameError):
            self._record(Outcome.TIMEOUT)
            raise
        except DeviceExceptionError as exc:
            outcome = {
                "busy": Outcome.BUSY,
                "fail": Outcome.FAILED,
                "locked": Outcome.FAILED,
            }.get(exc.action, Outcome.REFUSED)
            self._record(outcome, code=exc.code)
            raise
        self._record(Outcome.OK, latency=sum(answer))
        return values

    def _record(
        self, outcome: Outcome, *, latency: float | None = None, code: int | None = None
    ) -> None:
        now = time.monotonic()
        dog = self.watchdog
        if dog is not None and outcome is not Outcome.TIMEOUT and dog.answered(now):
            log.info("%s answers again: its watchdog is fed", self.device.id)
        first_contact = self.health.online is None
        transition = self.health.record(outcome, now, latency=latency, code=code)
        self.announce(transition, first_contact=first_contact)

    def announce(self, transition: Transition | None, *, first_contact: bool) -> None:
        """Log a change of state once (offline with the reason) and announce it."""
        if transition is None:
            return
        fields = {"device": self.device.id, "unit": self.device.unit, "bus": self.scheduler.bus_id}
        if transition is Transition.OFFLINE:
            health = self.health
            failures, backoff = health.consecutive_failures, health.backoff
            reason = health.offline_reason(time.monotonic())
            log.warning(
                "%s (unit %d on %s) offline %s; retrying every %.1f s or later",
                *fields.values(),
                reason,
                backoff,
                extra=fields
                | {
                    "event": "device_offline",
                    "failures": failures,
                    "backoff_s": backoff,
                    "reason": str(health.fault),
                },
            )
        else:
            word = "online" if first_contact else "back online"
            event = "device_online" if first_contact else "device_recovered"
            log.info("%s %s", self.device.id, word, extra=fields | {"event": event})
        self.on_change(frozenset())
