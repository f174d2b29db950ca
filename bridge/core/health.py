"""Device health: what each transaction outcome means, counters, online/offline and backoff.

Pure: the caller passes the monotonic time in. A device goes offline after
``offline_after`` consecutive failures (timeouts, or exceptions the device means as
failures) and is then tried once per backoff interval, doubling up to a cap, so that a
dead unit costs its bus one timeout per interval instead of one per poll. The first
answer brings it back online. Busy answers and refused addresses prove the device is
alive and never count towards offline.
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
    return STANDARD_EXCEPTIONS.get(code, ExceptionMeaning(name=f"exception {code}"))


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


@dataclass(frozen=True, slots=True)
class HealthPolicy:
    offline_after: int = 3
    backoff_initial: float = 5.0
    backoff_max: float = 300.0
    backoff_factor: float = 2.0


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
    exceptions: Counter[int] = field(default_factory=Counter)
    last_latency: float | None = None
    last_success: float | None = None
    backoff: float = 0.0
    next_attempt: float = 0.0
    latencies: deque[float] = field(default_factory=lambda: deque(maxlen=256))

    def record(
        self, outcome: Outcome, now: float, *, latency: float | None = None, code: int | None = None
    ) -> Transition | None:
        """Count one transaction; return a transition when the device changed state."""
        self.requests += 1
        if code is not None:
            self.exceptions[code] += 1
        if outcome in (Outcome.TIMEOUT, Outcome.FAILED):
            return self._failure(outcome, now)
        if outcome is Outcome.BUSY:
            self.busy += 1
        if latency is not None:
            self.last_latency = latency
            self.latencies.append(latency)
        self.last_success = now
        self.consecutive_failures = 0
        self.backoff = 0.0
        if self.online is not True:
            self.online = True
            return Transition.ONLINE
        return None

    def _failure(self, outcome: Outcome, now: float) -> Transition | None:
        self.errors += 1
        if outcome is Outcome.TIMEOUT:
            self.timeouts += 1
        self.consecutive_failures += 1
        if self.consecutive_failures < self.policy.offline_after:
            return None
        policy = self.policy
        self.backoff = min(
            policy.backoff_max,
            policy.backoff_initial if not self.backoff else self.backoff * policy.backoff_factor,
        )
        self.next_attempt = now + self.backoff
        if self.online is not False:
            self.online = False
            return Transition.OFFLINE
        return None

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
