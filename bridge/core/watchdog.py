"""A device's communication watchdog as the bridge keeps it fed. Pure: times are passed in.

A device with ``protocol.keepalive`` (the soft starter's 60 s watchdog, the Vacon board's
fieldbus time-out) stops the motor when no request reaches it for a while. The poller's
fast polls come at least every ``interval``; when a pass is slow or the bus is busy with
other work (commissioning, a slow neighbour), a keepalive read goes ahead of the polls
once the device has been silent for ``LEAD`` of the interval. A silence longer than the
interval is reported once (``lapse``), and its end once (``answered``).
"""

from __future__ import annotations

from dataclasses import dataclass

LEAD = 0.5  # a keepalive read once the device was silent for this fraction of the interval


@dataclass(slots=True)
class Watchdog:
    """When the device last answered, and whether a lapse was reported."""

    interval: float
    last_answer: float | None = None  # None: not answered yet (nothing to keep alive)
    lapsed: bool = False

    def answered(self, now: float) -> bool:
        """Record an answer; True when it ends a lapse that was reported."""
        self.last_answer = now
        ended, self.lapsed = self.lapsed, False
        return ended

    def due(self) -> float | None:
        """When a keepalive read is due (None before the first answer)."""
        if self.last_answer is None:
            return None
        return self.last_answer + LEAD * self.interval

    def lapse(self, now: float) -> float | None:
        """The silence so far when it exceeds the interval and was not reported yet (it is
        now), else None."""
        if self.last_answer is None or self.lapsed:
            return None
        silence = now - self.last_answer
        if silence <= self.interval:
            return None
        self.lapsed = True
        return silence
