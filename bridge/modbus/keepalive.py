"""Keeping a device's communication watchdog fed (bridge/core/watchdog.py): a task beside
the poll loop of a device whose mapping declares ``protocol.keepalive``.

While the device is online, a read at ``Priority.KEEPALIVE`` (after writes, before reads on
request, commissioning and polls) goes out once it has been silent for half its keepalive
interval: the first block of its shortest poll interval, whose values are published like a
poll's. The log says once when the device went longer than the interval without an answer
(its watchdog may stop the motor) and once when it answers again.
"""

from __future__ import annotations

import asyncio
import logging
import time

from bridge.core.device_state import DeviceState
from bridge.core.planner import Address
from bridge.core.schedule import ONCE
from bridge.modbus.device_link import Changes, DeviceLink
from bridge.modbus.scheduler import Priority

log = logging.getLogger(__name__)
LAPSE_MARGIN = 0.01  # seconds: wake just after a silence became longer than the interval


async def keep_alive(state: DeviceState, link: DeviceLink, on_change: Changes) -> None:
    """Feed the device's watchdog until cancelled; say so when it could not. The values a
    keepalive read changed go to ``on_change``."""
    dog = link.watchdog
    if dog is None:
        return
    while True:
        now = time.monotonic()
        _report_lapse(link, now)
        due = dog.due()
        if due is not None and link.health.online is True and now >= due:
            if await _read_once(state, link, on_change):
                continue
            await asyncio.sleep(dog.interval / 2)  # nothing to read: never spin the loop
            continue
        await asyncio.sleep(_next_wake(link, now) - now)


def _next_wake(link: DeviceLink, now: float) -> float:
    """The next keepalive read (while online), or the moment a silence becomes a lapse."""
    dog = link.watchdog
    if dog is None or dog.last_answer is None:
        return now + 1.0
    wakes = [now + dog.interval / 2]
    if link.health.online is True and (due := dog.due()) is not None:
        wakes.append(due)
    if not dog.lapsed:
        wakes.append(dog.last_answer + dog.interval + LAPSE_MARGIN)
    return max(now + LAPSE_MARGIN, min(wakes))


def _report_lapse(link: DeviceLink, now: float) -> None:
    dog = link.watchdog
    silence = dog.lapse(now) if dog is not None else None
    if dog is None or silence is None:
        return
    log.warning(
        "%s: no answer for %.1f s, longer than its communication watchdog allows "
        "(keepalive %g s): the device may stop the motor",
        link.device.id,
        silence,
        dog.interval,
        extra={"event": "watchdog_lapse", "device": link.device.id},
    )


async def _read_once(state: DeviceState, link: DeviceLink, on_change: Changes) -> bool:
    """One keepalive read: the first block of the shortest interval that has one (its
    values decoded and their changes passed on); False when there is no block to read
    (every entity polled once, or refused)."""
    shortest = sorted({*state.intervals.values(), state.rule.fast, state.rule.slow} - {ONCE})
    plan = next((p for p in map(state.plan, ([i] for i in shortest)) if p), ())
    if not plan:
        return False
    read = plan[0]
    fresh: set[Address] = set()
    await link.read_block(read, Priority.KEEPALIVE, fresh)
    keys = [k for k, p in state.points.items() if {(p.table, a) for a in p.span} & fresh]
    changed = state.decode_fresh(keys, fresh)
    if changed:
        on_change(changed)
    return True
