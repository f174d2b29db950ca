"""One trial poll of a device not configured yet: what the page's "Try it" shows.

``trial_poll(device, mapping, scheduler, bus)`` builds the device's poller as the engine
would (the same plan of reads, read limits, refusal search, tear and scale-factor checks)
on ``scheduler``, without adding it to the engine, and polls every interval of it once,
queued as a poll (the bus's polls, commands and other masters are not overtaken). The
poller is returned for its values, refused addresses and counters; nothing is published
and nothing written: a poll only reads, the trial device has no password (nothing is
unlocked), and the poller's scheduler is the bus's behind ``ReadsOnly``, which refuses
anything but a read before it is queued. The poller is dropped with the answer.
"""

from __future__ import annotations

import asyncio
from typing import Any, cast

from bridge.config import DeviceConfig, SerialBus, TcpBus
from bridge.core.entity import PollClass
from bridge.core.mapping import Mapping
from bridge.core.request import Read, Write, WriteSequence
from bridge.errors import ValueRejectedError
from bridge.modbus.engine import link_timing
from bridge.modbus.poller import DevicePoller
from bridge.modbus.scheduler import BusScheduler

TRIAL_LIMIT = 60.0  # seconds one trial poll may take at most (its reads, their retries)


class ReadsOnly:
    """A bus's scheduler as a trial poller sees it (its ``DeviceLink`` uses ``submit`` and
    ``bus_id`` only): reads are queued on the bus, anything else is refused unsent."""

    def __init__(self, scheduler: BusScheduler) -> None:
        self._scheduler = scheduler

    @property
    def bus_id(self) -> str:
        return self._scheduler.bus_id

    async def submit(
        self, unit: int, request: Read | Write | WriteSequence, **options: Any
    ) -> tuple[int, ...]:
        if not isinstance(request, Read):
            raise ValueRejectedError("a trial poll only reads")
        return await self._scheduler.submit(unit, request, **options)


async def trial_poll(
    device: DeviceConfig, mapping: Mapping, scheduler: BusScheduler, bus: SerialBus | TcpBus
) -> DevicePoller:
    """The poller of ``device`` after one poll of every interval (TimeoutError past
    ``TRIAL_LIMIT``: the reads still queued are dropped with it)."""
    poller = DevicePoller(
        device.model_copy(update={"password": None, "password_file": None, "password_env": None}),
        mapping,
        cast("BusScheduler", ReadsOnly(scheduler)),
        timing=link_timing(bus),
        timeout=bus.timeout,
        retries=0,
    )
    named = (PollClass.FAST, PollClass.SLOW, PollClass.ONCE)
    async with asyncio.timeout(TRIAL_LIMIT):
        await poller.poll([*named, *poller.state.intervals.values()])
    return poller
