"""Device health: what each transaction outcome means, counters, online/offline and backoff.

Pure: the caller passes the monotonic time in. A device goes offline after
``offline_after`` consecutive failures and is then tried once per backoff interval,
doubling up to a cap, so that a dead unit costs its bus one timeout per interval instead
of one per poll. Only a real answer (values) brings it back online. The failures:

- a timeout, a bus or frame error, an exception the device means as a failure;
- a poll in which it refused every read (``refuses_every_read``: the poller's
  refusal_memory judged the pass a fault, not a map of holes);
- answering only "busy" (05/06, or the device's own busy codes): busy answers are alive and
  never failures on their own, but ``offline_after`` of them in a row spanning
  ``busy_offline_after`` seconds with no value in between take the device offline.

A refused address on its own neither counts nor clears anything: the pass decides.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field
from enum import StrEnum

from bridge.core.protocol import ExceptionMeaning, Protocol

# Standard meanings (Modbus Application Protocol 1.1b3, section 7) and what to do about them.
STANDARD_EXCEPTIONS: dict[int, ExceptionMeaning] = {
    1: ExceptionMeaning(name="illegal function", action="refused"),
    2: ExceptionMeaning(name="illegal data address", action="refused"),
    3: ExceptionMeaning(name="illegal data value", action="refused"),
    4: ExceptionMeaning(name="server device failure", action="fail"),
    5: ExceptionMeaning(name="acknowledge (processing a long command)", action="busy"),
    6: ExceptionMeaning(name="server device busy", action="busy"),
    7: ExceptionMeaning(name="negative acknowledge", action="fail"),
    8: ExceptionMeaning(name="memory parity error", action="fail"),
    10: ExceptionMeaning(name="gateway path unavailable", action="fail"),
    11: ExceptionMeaning(name="gateway target device failed to respond", action="fail"),
}


def exception_meaning(code: int, protocol: Protocol) -> ExceptionMeaning:
    """The device's own meaning of an exception code, else the standard one."""
    if code in protocol.exceptions:
        return protocol.exceptions[code]
    return STANDARD_EXCEPTIONS.get(code, ExceptionMeaning(name="not a standard code"))


class Outcome(StrEnum):
    """How one transaction ended."""

    OK = "ok"
    TIMEOUT = "timeout"
    FAILED = "failed"  # an exception response the device means as a failure
    BUSY = "busy"  # alive, try later
    REFUSED = "refused"  # alive, the address or value is not allowed


class Transition(StrEnum):
    OFFLINE = "offline"
    ONLINE = "online"


class Fault(StrEnum):
    """Why a device went offline."""

    NO_ANSWER = "no_answer"  # timeouts, failure exceptions
    REFUSES = "refuses"  # refused every read of its polls
    BUSY = "busy"  # answered only "busy"
    LOCKED = "locked"  # locked by a password the bridge cannot unlock (``lock_reason``)
    UNMAPPED = "unmapped"  # its mapping cannot be built yet (a SunSpec walk: ``lock_reason``)


@dataclass(frozen=True, slots=True)
class HealthPolicy:
    offline_after: int = 3
    backoff_initial: float = 5.0
    backoff_max: float = 300.0
    backoff_factor: float = 2.0
    busy_offline_after: float = 30.0  # seconds of answering only "busy" before offline
    refusal_recheck: float = 600.0  # seconds a learnt refusal is trusted before a re-read


@dataclass(slots=True)
class DeviceHealth:
    """Counters and the online/offline state of one device."""

    policy: HealthPolicy = HealthPolicy()
    online: bool | None = None  # None until the first answer or the first offline verdict
    consecutive_failures: int = 0
    requests: int = 0
    errors: int = 0
    timeouts: int = 0
    busy: int = 0
    refusal_faults: int = 0  # polls refused as a whole (a device fault, nothing learnt)
    exceptions: Counter[int] = field(default_factory=Counter)
    last_latency: float | None = None
    last_success: float | None = None
    backoff: float = 0.0
    next_attempt: float = 0.0
    fault: Fault | None = None  # why it is offline
    lock_reason: str = ""  # Fault.LOCKED: why the device stays locked
    busy_streak: int = 0  # busy answers since the last value
    busy_since: float = 0.0  # the first of them
    latencies: deque[float] = field(default_factory=lambda: deque(maxlen=256))

    def record(
        self, outcome: Outcome, now: float, *, latency: float | None = None, code: int | None = None
    ) -> Transition | None:
        """Count one transaction; return a transition when the device changed state."""
        self.requests += 1
        if code is not None:
            self.exceptions[code] += 1
        if outcome in (Outcome.TIMEOUT, Outcome.FAILED):
            self.errors += 1
            if outcome is Outcome.TIMEOUT:
                self.timeouts += 1
            return self._failure(Fault.NO_ANSWER, now)
        if outcome is Outcome.BUSY:
            return self._busy(now)
        if outcome is Outcome.REFUSED:
            return None  # a hole or a device fault: the poller judges the whole pass
        if latency is not None:
            self.last_latency = latency
            self.latencies.append(latency)
        self.last_success = now
        self.consecutive_failures = 0
        self.backoff = 0.0
        self.busy_streak = 0
        if self.online is not True:
            self.online, self.fault = True, None
            return Transition.ONLINE
        return None

    def refuses_every_read(self, now: float) -> Transition | None:
        """Count a pass the device refused as a whole (not a map of holes) as a failure."""
        self.refusal_faults += 1
        return self._failure(Fault.REFUSES, now)

    def locked(self, now: float, reason: str) -> Transition | None:
        """The device is locked by a password the bridge cannot unlock: offline at once,
        with the reason (its probes answer 'locked' until someone fixes the password)."""
        self.lock_reason = reason
        self.consecutive_failures = max(self.consecutive_failures, self.policy.offline_after)
        self.fault = Fault.LOCKED
        return self._offline(Fault.LOCKED, now)

    def unmapped(self, now: float, reason: str) -> Transition | None:
        """The device's mapping could not be built (a SunSpec device whose walk failed):
        offline at once, with the reason, until a build succeeds."""
        self.lock_reason = reason
        self.consecutive_failures = max(self.consecutive_failures, self.policy.offline_after)
        return self._offline(Fault.UNMAPPED, now)

    def offline_reason(self, now: float) -> str:
        """Why the device is offline, for the log: 'after 3 failed requests'."""
        if self.fault in (Fault.LOCKED, Fault.UNMAPPED):
            return f"({self.lock_reason})"
        if self.fault is Fault.BUSY:
            return f"after {now - self.busy_since:.0f} s: answers only 'busy'"
        if self.fault is Fault.REFUSES:
            return f"after {self.consecutive_failures} failed polls: refuses every read"
        return f"after {self.consecutive_failures} failed requests"

    def _busy(self, now: float) -> Transition | None:
        self.busy += 1
        self.busy_streak += 1
        if self.busy_streak == 1:
            self.busy_since = now
        if self.online is False:
            self._back_off(now)  # a probe answered busy: not back yet
            return None
        policy = self.policy
        if (
            self.busy_streak >= policy.offline_after
            and now - self.busy_since >= policy.busy_offline_after
        ):
            return self._offline(Fault.BUSY, now)
        if self.online is None:
            self.online = True  # first contact: the unit is there
            return Transition.ONLINE
        return None

    def _failure(self, fault: Fault, now: float) -> Transition | None:
        self.consecutive_failures += 1
        if self.consecutive_failures < self.policy.offline_after:
            return None
        return self._offline(fault, now)

    def _offline(self, fault: Fault, now: float) -> Transition | None:
        self._back_off(now)
        if self.online is not False:
            self.online, self.fault = False, fault
            return Transition.OFFLINE
        return None

    def _back_off(self, now: float) -> None:
        policy = self.policy
        self.backoff = min(
            policy.backoff_max,
            policy.backoff_initial if not self.backoff else self.backoff * policy.backoff_factor,
        )
        self.next_attempt = now + self.backoff

    def may_poll(self, now: float) -> bool:
        """Online devices poll on schedule; offline ones only when their backoff ran out."""
        return self.online is not False or now >= self.next_attempt

    def percentile(self, fraction: float) -> float | None:
        """Latency percentile over the recent transactions (nearest rank)."""
        if not self.latencies:
            return None
        ordered = sorted(self.latencies)
        rank = max(0, min(len(ordered) - 1, round(fraction * len(ordered)) - 1))
        return ordered[rank]
