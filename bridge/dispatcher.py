"""Command messages (``/set``, ``/get``) turned into engine work: bounded, coalesced, on time.

``Dispatcher.handle(target, message)`` never waits: it checks the message and hands the
work to a task, so the MQTT message loop is never held up by a device or a flood.

* A message delivered with the retain flag is refused and never executed (a stale
  retained ``start`` would start a motor at every reconnect); so is a payload beyond
  ``MAX_PAYLOAD`` bytes, before it is parsed.
* ``/set``: every key of one message is one command, validated whole and written all or
  nothing (``DevicePoller.write_many``). Its expiry is the earlier of
  ``mqtt.command_expiry`` and the publisher's MQTT 5 message expiry, counted from the
  message's arrival (it may wait unread while a session starts); the scheduler checks it
  right before the first frame is sent. Commands run per device in arrival order; at
  most ``MAX_WAITING`` wait per device, more are refused as busy.
* ``/get``: at most one read waits per device; a ``/get`` arriving meanwhile joins it.
  A device is read on request at most once per ``GET_INTERVAL`` seconds, so a flood of
  ``/get`` cannot keep the bus from polling the other devices.

Every refusal and failure goes to ``error(device, key, value, reason)``; after a read on
request, ``read(device)`` has the device's state published.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import AsyncIterator, Callable, Coroutine
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

from bridge.core.codec import Value
from bridge.core.commands import (
    Command,
    RecentMessages,
    check_size,
    parse_get,
    parse_set,
    past_deadline,
)
from bridge.core.topics import Action, CommandTopic
from bridge.errors import (
    BridgeError,
    CommandExpiredError,
    CommandRejectedError,
    DeviceTimeoutError,
    ValueRejectedError,
)
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DevicePoller
from bridge.modbus.writer import Later
from bridge.mqtt import Message

log = logging.getLogger(__name__)
MAX_WAITING = 16  # commands waiting per device
GET_INTERVAL = 1.0  # seconds between two reads on request of one device
RETAINED = (
    "retained message refused: commands act only on live messages; clear it with "
    "an empty retained message on the same topic"
)

Error = Callable[[str, str | None, object, str], None]
Spawn = Callable[[Coroutine[Any, Any, None], Callable[[str], None]], None]
Read = Callable[[str], None]


@dataclass(slots=True)
class DispatchCounters:
    """What happened to command messages (for ``bridge/health``)."""

    commands: int = 0  # /set messages accepted for execution
    refused: int = 0  # refused before execution: retained, too large, malformed, busy
    coalesced: int = 0  # /get messages that joined a read already waiting


class Dispatcher:
    """Runs the commands of one bridge."""

    def __init__(
        self, engine: Engine, expiry: float, *, spawn: Spawn, error: Error, read: Read
    ) -> None:
        self.engine = engine
        self.expiry = expiry
        self.counters = DispatchCounters()
        self._spawn = spawn
        self._error = error
        self._after_read = read
        self._recent = RecentMessages(window=max(60.0, 10 * expiry))
        self._locks: dict[str, asyncio.Lock] = {}
        self._waiting: dict[str, int] = {}
        self._reads: dict[str, set[str] | None] = {}  # reads waiting: keys, None for all
        self._last_read: dict[str, float] = {}

    def handle(self, target: CommandTopic, message: Message) -> None:
        """Check one command message and start its work; never waits."""
        device_id, key = target.device_id, target.key
        try:
            if message.retain:
                raise ValueRejectedError(RETAINED)
            check_size(message.payload)
        except ValueRejectedError as exc:
            self._refuse(device_id, key, message.payload, str(exc))
            return
        now = time.monotonic()
        if self._recent.is_duplicate(
            message.topic, message.payload, message.mid, message.duplicate, now
        ):
            log.info("ignoring a redelivered duplicate on %s", message.topic)
            return
        try:
            if target.action is Action.GET:
                self._get(device_id, parse_get(message.payload))
                return
            items = parse_set(message.payload, key)
        except ValueRejectedError as exc:
            self._refuse(device_id, key, message.payload, str(exc))
            return
        arrived = now if message.received is None else min(now, message.received)
        self._set(Command.arrived(device_id, items, arrived, self.expiry, message.expiry))

    def _refuse(self, device_id: str, key: str | None, value: object, reason: str) -> None:
        self.counters.refused += 1
        self._error(device_id, key, value, reason)

    # --- /set -------------------------------------------------------------------------

    def _set(self, command: Command) -> None:
        waiting = self._waiting.get(command.device_id, 0)
        if waiting >= MAX_WAITING:
            for key, value in command.items.items():
                self._refuse(
                    command.device_id,
                    key,
                    value,
                    f"busy: {waiting} commands already wait for {command.device_id}; "
                    "nothing written",
                )
            return
        self.counters.commands += 1
        self._waiting[command.device_id] = waiting + 1
        self._spawn(self._execute(command), lambda reason: self._fail(command, reason))

    async def _execute(self, command: Command) -> None:
        """Run one command in arrival order for its device, or drop it with an error; the
        read back after a ``verify_delay`` comes after, the device's next command going on
        meanwhile."""
        later: Later = []
        try:
            poller = await self._run(command, later)
        finally:
            self._waiting[command.device_id] -= 1
        if later and poller is not None:
            try:
                await poller.writer.read_back_later(later)
            except BridgeError as exc:
                self._fail(command, f"written; the read back after its delay failed: {exc}")

    async def _run(self, command: Command, later: Later) -> DevicePoller | None:
        """The command run under its device's lock; the poller that ran it."""
        device_id = command.device_id
        if device_id not in self.engine.devices:
            self._fail(command, "no such device")
            return None
        async with self._locks.setdefault(device_id, asyncio.Lock()):
            poller = self.engine.devices.get(device_id)  # now: a reload may have replaced it
            if poller is None:  # or removed it (a config applied live: bridge/reconfigure.py)
                self._fail(command, "no such device: it was removed from the config")
                return None
            if command.expired(time.monotonic()):
                poller.writes.expired += 1
                self._fail(command, "expired: not executed within the command expiry")
                return None
            if poller.health.online is False:
                poller.writes.rejected += 1
                self._fail(command, f"{device_id} is offline: nothing written")
                return None
            try:
                await poller.write_many(command.items, deadline=command.expires, later=later)
            except CommandRejectedError as exc:
                for key, value in command.items.items():
                    self._error(device_id, key, value, exc.reason(key))
            except BridgeError as exc:
                self._fail(command, str(exc))
            return poller

    @asynccontextmanager
    async def between_commands(self, device_id: str) -> AsyncIterator[None]:
        """Hold the device's commands: the one running (a write of several registers)
        ends first, the ones after wait (a config applied live stops or restarts the
        device meanwhile: bridge/reconfigure.py)."""
        async with self._locks.setdefault(device_id, asyncio.Lock()):
            yield

    async def write_for(
        self, device_id: str, items: dict[str, object], deadline: float
    ) -> dict[str, Value]:
        """A command from another way in (the Modbus TCP gateway, bridge/gateway.py): run
        in order with the device's /set commands, under the same bound, expiry and offline
        check, and written all or nothing by the same writer; failures are raised, not
        published (the caller answers its client)."""
        waiting = self._waiting.get(device_id, 0)
        if waiting >= MAX_WAITING:
            raise CommandExpiredError(f"busy: {waiting} commands already wait for {device_id}")
        self._waiting[device_id] = waiting + 1
        try:
            async with self._locks.setdefault(device_id, asyncio.Lock()):
                poller = self.engine.device(device_id)
                if past_deadline(deadline, time.monotonic()):
                    poller.writes.expired += 1
                    raise CommandExpiredError("expired: not executed within the command expiry")
                if poller.health.online is False:
                    poller.writes.rejected += 1
                    raise DeviceTimeoutError(f"{device_id} is offline: nothing written")
                self.counters.commands += 1
                return await poller.write_many(items, deadline=deadline)
        finally:
            self._waiting[device_id] -= 1

    def _fail(self, command: Command, reason: str) -> None:
        for key, value in command.items.items():
            self._error(command.device_id, key, value, reason)

    # --- /get -------------------------------------------------------------------------

    def _get(self, device_id: str, keys: list[str] | None) -> None:
        poller = self.engine.devices.get(device_id)
        if poller is None:
            self._refuse(device_id, None, keys, "no such device")
            return
        unknown = [k for k in keys or [] if k not in poller.points]
        if unknown:
            self._refuse(device_id, None, keys, f"no such entities: {', '.join(unknown[:10])}")
            return
        if device_id in self._reads:  # a read waits already: this one joins it
            self.counters.coalesced += 1
            waiting = self._reads[device_id]
            self._reads[device_id] = (
                None if waiting is None or keys is None else waiting | set(keys)
            )
            return
        self._reads[device_id] = None if keys is None else set(keys)
        self._spawn(
            self._read(device_id), lambda reason: self._error(device_id, None, keys, reason)
        )

    async def _read(self, device_id: str) -> None:
        """One read on request, no sooner than ``GET_INTERVAL`` after the previous one."""
        try:
            wait = self._last_read.get(device_id, -GET_INTERVAL) + GET_INTERVAL - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
        finally:
            keys = self._reads.pop(device_id, None)
        self._last_read[device_id] = time.monotonic()
        poller = self.engine.devices.get(device_id)
        if poller is None:
            return
        known = None if keys is None else sorted(k for k in keys if k in poller.points)
        await poller.read_now(known)
        self._after_read(device_id)
