"""The ``mapping: sunspec`` devices: walked, built, cached and kept up to date at run time.

For each such device ``SunSpecDevices.run`` (an engine companion: it runs while the engine
runs) does one of two things:

- the config loaded a cached mapping (bridge/sunspec/cache.py): the device polls with it
  at once; after its first poll the chain is walked once (the device's bus scheduler,
  at poll priority; after a backoff again until a walk succeeds) and, if it changed (a
  firmware update), its registers are read and the mapping is rebuilt,
  swapped in the way ``mapping/reload`` swaps one (``swap``: bridge/management.py) and
  cached again;
- no cache: the device is offline (the reason in its health and the log) until a walk
  and a build succeed; a silent or failing unit is tried again after a backoff like an
  unreachable device's (5 s doubling to 5 min), a unit that answers but has no ``SunS``
  marker after ``NOT_SUNSPEC_RETRY``. Every request goes through the bus scheduler, so
  the walk of a dead unit delays no other device more than one poll of it would.

Then it watches the device: one that was offline and answers again (a firmware update
reboots it) has its chain walked again, as after a start, and rebuilt if it changed; at
most once every ``REWALK_GAP`` (a device that keeps dropping off a noisy line is checked
once the gap has passed, not at every return).

``start(device_id)`` and ``stop(device_id)`` begin and end that for one device while the
engine runs (a config applied live: bridge/reconfigure.py). ``rewalk(device_id)`` walks
and builds now (``mapping/reload`` with ``rewalk``) and
swaps the mapping in when it differs. A cache that cannot be written is logged; the
device runs with the mapping built.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Awaitable, Callable, Sequence
from pathlib import Path
from typing import Any

from bridge.config import LoadedConfig
from bridge.config.loading import MAX_READ_REGISTERS
from bridge.core.entity import Table
from bridge.core.management_request import RequestError
from bridge.core.mapping import Mapping
from bridge.core.request import Read
from bridge.errors import BridgeError, NotSunSpecError
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DevicePoller
from bridge.modbus.scheduler import Priority
from bridge.sunspec import cache
from bridge.sunspec.mapping import BuiltMapping, build_from_device, build_mapping
from bridge.sunspec.walk import BASES, Chain, WalkLimits, read_chain, walk

log = logging.getLogger(__name__)
Swap = Callable[[str, Mapping], Awaitable[None]]
NOT_SUNSPEC_RETRY = 600.0  # seconds before a unit without the marker is asked again
FIRST_POLL_WAIT = 30.0  # seconds a cached device's chain check waits for its first poll
WATCH = 1.0  # seconds between two looks at a device's availability (rebooted: walk again)
REWALK_GAP = 600.0  # seconds at least between two checks of a chain after the device's returns
BACKOFF_INITIAL, BACKOFF_MAX = 5.0, 300.0  # a failed walk, as an unreachable device


class SunSpecDevices:
    """The walks, builds and caches of one config's ``mapping: sunspec`` devices."""

    def __init__(self, loaded: LoadedConfig, engine: Engine, swap: Swap) -> None:
        self.loaded = loaded
        self.engine = engine
        self.state_dir = state_dir_of(loaded)
        self._swap = swap
        self._locks = {device_id: asyncio.Lock() for device_id in self.ids}
        self.walks = 0  # chain walks done, a check's and a build's (the tests count them)
        self._group: asyncio.TaskGroup | None = None
        self._tasks: dict[str, asyncio.Task[None]] = {}

    @property
    def ids(self) -> list[str]:
        """The devices polled as ``mapping: sunspec`` now (a mapping switch takes one out)."""
        return [d for d, p in self.engine.devices.items() if p.device.is_sunspec]

    async def run(self) -> None:
        """Keep every SunSpec device's mapping built and current (until cancelled)."""
        try:
            async with asyncio.TaskGroup() as group:
                self._group = group
                for device_id in self.ids:
                    self.start(device_id)
                await asyncio.get_running_loop().create_future()  # open for ``start``
        finally:
            self._group = None
            self._tasks.clear()

    def start(self, device_id: str) -> None:
        """Keep a device's mapping built and current from now on (a SunSpec device added,
        enabled or restarted by a config applied live: bridge/reconfigure.py)."""
        if self._group is not None:
            task = self._group.create_task(self._keep(device_id), name=f"sunspec:{device_id}")
            self._tasks[device_id] = task

    async def stop(self, device_id: str) -> None:
        """No more walks of a device (before it is stopped or restarted); a walk in flight
        is cut short (it only reads)."""
        task = self._tasks.pop(device_id, None)
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def rewalk(self, device_id: str) -> bool:
        """Walk and build now; True if the mapping changed (and was swapped in)."""
        poller = self.engine.device(device_id)
        chain, built = await build_from_device(self._reader(poller), *self._bounds(poller))
        return await self._install(device_id, chain, built)

    async def rewalk_many(self, wanted: list[str] | None) -> dict[str, Any]:
        """``mapping/reload`` with ``rewalk``: the SunSpec devices named (None: all) walked
        and built again, one at a time; a device that is not one is refused."""
        ids = self.ids
        wanted = list(ids) if wanted is None else wanted
        other = [d for d in wanted if d not in ids]
        if other:
            raise RequestError(f"devices: not mapping: sunspec devices {other}")
        changed, failed = [], {}
        for device_id in wanted:
            try:
                if await self.rewalk(device_id):
                    changed.append(device_id)
            except (BridgeError, ValueError) as exc:
                failed[device_id] = str(exc)
        return {"reloaded": wanted, "changed": changed, "failed": failed}

    # --- one device ---------------------------------------------------------------------

    async def _keep(self, device_id: str) -> None:
        poller = self.engine.device(device_id)
        cached = cache.load(self.state_dir, device_id, *self._setting(poller))
        if poller.points and cached is not None:
            await self._check(device_id, cached.signature)
        else:
            await self._build(device_id)
        await self._after_reboots(device_id)

    async def _after_reboots(self, device_id: str) -> None:
        """Walk the chain again whenever the device answers after being offline (a firmware
        update reboots it); rebuilt if it changed. Ends when it is switched to a file."""
        was_offline = due = False
        checked = -math.inf
        while self.engine.device(device_id).device.is_sunspec:
            poller = self.engine.device(device_id)
            if poller.health.online is False:
                was_offline = True
            elif poller.health.online and was_offline:
                was_offline, due = False, True
            if due and poller.health.online and time.monotonic() >= checked + REWALK_GAP:
                due, checked = False, time.monotonic()
                log.info(
                    "%s: answers again; checking its SunSpec model chain (a firmware update "
                    "changes it)",
                    device_id,
                )
                cached = cache.load(self.state_dir, device_id, *self._setting(poller))
                if cached is None:
                    await self._build(device_id)
                else:
                    await self._check(device_id, cached.signature)
            await asyncio.sleep(WATCH)

    async def _build(self, device_id: str) -> None:
        """Walk and build until it succeeds (the device offline with the reason meanwhile)."""
        delay = BACKOFF_INITIAL
        while self.engine.device(device_id).device.is_sunspec:  # not switched to a file
            try:
                await self.rewalk(device_id)
                return
            except NotSunSpecError as exc:
                reason = f"not a SunSpec device: {exc}"
                log.error("%s: %s; asking again in %.0f s", device_id, reason, NOT_SUNSPEC_RETRY)
                self._offline(device_id, reason)
                await asyncio.sleep(NOT_SUNSPEC_RETRY)
            except (BridgeError, ValueError) as exc:  # silent, refused, a bad chain
                reason = f"SunSpec walk failed: {exc}"
                log.warning("%s: %s; trying again in %.0f s", device_id, reason, delay)
                self._offline(device_id, reason)
                await asyncio.sleep(delay)
                delay = min(BACKOFF_MAX, delay * 2)

    async def _check(self, device_id: str, known: cache.Signature) -> None:
        """After the cached mapping's first poll, walk once (again after a backoff until a
        walk succeeds; the polls go on with the cached mapping meanwhile); a changed chain
        is read and built."""
        poller = self.engine.device(device_id)
        deadline = time.monotonic() + FIRST_POLL_WAIT
        while not poller.first_poll_done and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
        delay = BACKOFF_INITIAL
        while self.engine.device(device_id).device.is_sunspec:  # not switched to a file
            poller = self.engine.device(device_id)
            read = self._reader(poller)
            bases, limits = self._bounds(poller)
            try:
                chain = await walk(read, bases, limits)
                self.walks += 1
                if cache.signature(chain) == known:
                    log.info("%s: SunSpec model chain unchanged (cached mapping)", device_id)
                    return
                log.warning("%s: the SunSpec model chain changed; building its mapping", device_id)
                registers = await read_chain(read, chain, limits.read_limit)
                built = build_mapping(chain, registers, read_limit=limits.read_limit)
                await self._install(device_id, chain, built)
                return
            except (BridgeError, ValueError) as exc:
                log.warning(
                    "%s: the SunSpec chain could not be checked (%s); polling with the cached "
                    "mapping, checking again in %.0f s",
                    device_id,
                    exc,
                    delay,
                )
                await asyncio.sleep(delay)
                delay = min(BACKOFF_MAX, delay * 2)

    async def _install(self, device_id: str, chain: Chain, built: BuiltMapping) -> bool:
        """Cache the built mapping and swap it in if it differs from the one polled."""
        self.walks += 1
        mapping = built.mapping()
        poller = self.engine.device(device_id)
        try:
            bases, limit = self._setting(poller)
            cache.store(self.state_dir, device_id, chain, built, bases=bases, read_limit=limit)
        except OSError as exc:
            log.error("%s: the SunSpec mapping could not be cached: %s", device_id, exc)
        async with self._locks.setdefault(device_id, asyncio.Lock()):
            if not self.engine.device(device_id).device.is_sunspec:
                return False  # switched to a mapping file meanwhile (mapping/reload)
            if mapping == self.loaded.mappings.get(device_id):
                return False
            await self._swap(device_id, mapping)
        log.info(
            "%s: SunSpec mapping built: models %s, %d entities",
            device_id,
            ", ".join(map(str, chain.model_ids)),
            len(mapping.entities),
        )
        for pattern in poller.device.poll.rule().unmatched(mapping.entities):
            log.warning(
                "%s: poll.entities.%s names no entity of the built mapping", device_id, pattern
            )
        return True

    def _offline(self, device_id: str, reason: str) -> None:
        poller = self.engine.device(device_id)
        if not poller.points:  # a device polling a cached mapping says what its polls say
            poller.health.unmapped(time.monotonic(), reason)
            poller.values_changed(frozenset())  # its availability: offline

    # --- the bus --------------------------------------------------------------------------

    @staticmethod
    def _reader(poller: DevicePoller) -> Callable[[int, int], Awaitable[Sequence[int]]]:
        """Holding-register reads of the device through its bus scheduler at poll priority."""
        timeout = poller.link.timeout

        async def read(address: int, count: int) -> Sequence[int]:
            request = Read(Table.HOLDING, address, count)
            return await poller.scheduler.submit(
                poller.device.unit, request, timeout=timeout, priority=Priority.POLL
            )

        return read

    def _setting(self, poller: DevicePoller) -> tuple[Sequence[int] | None, int]:
        device = poller.device
        return device.sunspec_bases, device.protocol.max_read_registers or MAX_READ_REGISTERS

    def _bounds(self, poller: DevicePoller) -> tuple[Sequence[int], WalkLimits]:
        bases, limit = self._setting(poller)
        return bases or BASES, WalkLimits(read_limit=limit)


def state_dir_of(loaded: LoadedConfig) -> Path:
    """The bridge's state folder (``bridge.state_dir`` from the config file's folder)."""
    return loaded.path.parent / loaded.config.bridge.state_dir
