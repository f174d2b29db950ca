"""What the bridge publishes about its devices while a session lasts: each device's JSON,
its plain values and its availability, the devices list, ``bridge/info``, and the
non-retained messages (``<device>/error``, management responses) kept while the broker is
away.

The path of a poll from here on: the engine reports a change (``changed``, called from
``Bridge._on_update``) -> the keys are marked dirty and ``run`` wakes -> ``flush`` sends,
for each dirty device, its discovery first when the change needs a new payload, then its
JSON, changed plain values and availability (on change only) in one burst, the devices
list when an availability changed, then the outbox. A command's read-back goes the same
way (``again``). Every (re)connect, ``refresh`` and Home Assistant's ``online``
(``home_assistant_online``) publish everything at once instead (``everything``).

A device no longer polled (removed or disabled by a config applied live: bridge/
reconfigure.py) has its retained topics emptied at the next flush, discovery configs first
(``removed``), as the demo empties everything at its stop; a device polled again before
that keeps them (``restored``).

Alarm events (bridge/core/alarm_events.py) are found where the change comes in, not when
it is sent: each raise and clear a poll sees is queued once on ``<base>/<device>/event``
(kept in the outbox while the broker is away), against the alarms last said active, which
``seed_alarms`` takes from the retained document at a start (bridge/carry_over.py). Until
the first session has read that (``carried_over``), polls only mark their changes.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections import deque
from collections.abc import Callable, Coroutine
from datetime import UTC, datetime
from typing import Any

from bridge.config import MqttConfig
from bridge.core.alarm_events import alarm_events, event_document, reported
from bridge.core.discovery import Publish
from bridge.core.discovery_alarms import alarm_names
from bridge.core.state import compact, plain_payload, state_document
from bridge.core.topics import Topics
from bridge.discovery_publisher import DiscoveryPublisher
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DevicePoller, DeviceUpdate
from bridge.mqtt import MqttClient, MqttPublishError

log = logging.getLogger(__name__)
Outgoing = tuple[str, str, bool]  # topic, payload, retain
OUTBOX = 200  # non-retained messages kept while the broker is away
HA_SETTLE = 0.5  # seconds after Home Assistant's "online" before republishing
HA_REPUBLISH_GAP = 30.0  # seconds at least between two republishes Home Assistant asks for
STATE_AFTER_DISCOVERY = 1.0  # seconds: a device's state again after its discovery changed
MAX_SEEDED_ALARMS = 200  # alarm names read from a retained document, at most


class StatePublisher:
    """The device state the bridge owes the broker, and the tasks that send it."""

    def __init__(
        self,
        engine: Engine,
        topics: Topics,
        mqtt: MqttConfig,
        discovery: DiscoveryPublisher,
        *,
        info: Callable[[], Any],
        spawn: Callable[[Coroutine[Any, Any, None]], None],
    ) -> None:
        self.engine = engine
        self.topics = topics
        self.mqtt = mqtt
        self.discovery = discovery
        self._info = info  # bridge/info's document
        self._spawn = spawn  # a task in the bridge's TaskGroup, beyond this session
        self._wake = asyncio.Event()
        self._dirty: dict[str, set[str]] = {}
        self._outbox: deque[Publish] = deque(maxlen=OUTBOX)
        self.dropped = 0  # messages the full outbox dropped (counted in bridge/health)
        self._availability: dict[str, str] = {}
        self._info_due = False  # bridge/info again: another bridge overwrote it
        self._republish = False  # after a mapping reload: info, discovery and state
        self._ha_online = asyncio.Event()  # Home Assistant said online: republish soon
        self._alarms: dict[str, frozenset[str]] = {}  # the alarms last said active
        self._carried = False  # the first session read what a run before left retained
        self._clearing: dict[str, list[str]] = {}  # device no longer polled -> its topics

    @property
    def queued(self) -> int:
        """Messages waiting in the outbox (bridge/health's ``process.outbox``)."""
        return len(self._outbox)

    # --- what the bridge asks for ---------------------------------------------------

    def changed(self, update: DeviceUpdate) -> None:
        """A poll (or a write's read-back) changed these values: publish them, and an
        event for each alarm they raise or clear."""
        self._dirty.setdefault(update.device_id, set()).update(update.changed)
        if update.changed and self._carried:
            self._alarm_events(update.device_id)
        self._wake.set()

    def seed_alarms(self, device_id: str, document: dict[str, object]) -> None:
        """The alarms a retained document said active, for a device this run has said
        nothing of yet: an alarm already active before a restart does not fire again."""
        alarms = document.get("alarms")
        poller = self.engine.devices.get(device_id)
        if device_id in self._alarms or not isinstance(alarms, list) or poller is None:
            return
        names = [a for a in alarms[:MAX_SEEDED_ALARMS] if isinstance(a, str) and len(a) <= 200]
        self._alarms[device_id] = reported(names, poller.points)

    def carried_over(self) -> None:
        """What a run before left retained is read (or there was none): from now on alarm
        events are found, first against it for what the polls before found."""
        if self._carried:
            return
        self._carried = True
        for device_id in self.engine.devices:
            self._alarm_events(device_id)

    def _alarm_events(self, device_id: str) -> None:
        poller = self.engine.devices.get(device_id)
        if poller is None:
            return
        before = self._alarms.get(device_id, frozenset())
        events, self._alarms[device_id] = alarm_events(poller.points, poller.values, before)
        if not events:
            return
        entities = {key: point.entity for key, point in poller.points.items()}
        names = alarm_names(entities, poller.device.display_name)
        when = datetime.now(UTC).isoformat(timespec="milliseconds")
        for event in events:
            log.info(
                "%s: %s %s",
                device_id,
                event.alarm,
                event.state,
                extra={"event": f"alarm_{event.state}", "alarm": event.alarm},
            )
            document = event_document(event, names.get(event.alarm, event.alarm), when)
            self.queue(Publish(self.topics.event(device_id), compact(document), retain=False))

    def again(self, device_id: str) -> None:
        """Send the device's state (changed or not): after a read on request, or after
        Home Assistant took a new discovery payload."""
        self._dirty.setdefault(device_id, set())
        self._wake.set()

    def queue(self, message: Publish) -> None:
        """Queue a non-retained message; when the outbox is full the oldest is dropped
        (and counted)."""
        if len(self._outbox) == self._outbox.maxlen:
            self.dropped += 1
        self._outbox.append(message)
        self._wake.set()

    def info_again(self) -> None:
        """``bridge/info`` once more: a bridge that came up beside this one overwrote it."""
        self._info_due = True
        self._wake.set()

    def reloaded(self, device_ids: list[str]) -> None:
        """Mappings reloaded: info, discovery and every state again."""
        for device_id in device_ids:
            self.discovery.forget(device_id)
            self._dirty.pop(device_id, None)
        self._republish = True
        self._wake.set()

    def removed(self, device_id: str, topics: list[str]) -> None:
        """A device is no longer polled: empty ``topics`` (its discovery configs first) and
        every other retained topic of the device the session published, at the next flush;
        forget what was said of it."""
        self._dirty.pop(device_id, None)
        self._availability.pop(device_id, None)
        self._alarms.pop(device_id, None)
        self._clearing[device_id] = topics
        self._wake.set()

    def restored(self, device_id: str) -> None:
        """A device is polled again before its topics were emptied: they stay."""
        self._clearing.pop(device_id, None)

    def home_assistant_online(self) -> None:
        """Home Assistant (re)started: discovery and state again, soon."""
        self._ha_online.set()

    # --- the session's tasks ------------------------------------------------------------

    async def run(self, client: MqttClient) -> None:
        """Publish what changed, whenever something did."""
        if self._clearing:  # left by a session that ended before it emptied them
            self._wake.set()
        while True:
            await self._wake.wait()
            self._wake.clear()
            await self.flush(client)

    async def refresh(self, client: MqttClient) -> None:
        """Everything again every ``mqtt.state_refresh`` seconds."""
        while True:
            await asyncio.sleep(self.mqtt.state_refresh)
            await self.everything(client)

    async def home_assistant_returns(self, client: MqttClient) -> None:
        """Discovery and state again after Home Assistant says ``online``: ``HA_SETTLE``
        seconds after it, however many come, and at most once per ``HA_REPUBLISH_GAP``
        (anyone may publish ``online``: a sustained flood must not keep the bridge
        republishing everything)."""
        last = -HA_REPUBLISH_GAP
        while True:
            await self._ha_online.wait()
            await asyncio.sleep(max(HA_SETTLE, last + HA_REPUBLISH_GAP - time.monotonic()))
            self._ha_online.clear()
            last = time.monotonic()
            log.info("Home Assistant is online: publishing discovery and state again")
            await self.discovery.publish(client)
            await self.everything(client)

    # --- publishing -----------------------------------------------------------------

    async def flush(self, client: MqttClient) -> None:
        """Everything due now: the topics of devices no longer polled, info, a reload's
        republish, dirty devices, the outbox."""
        if self._clearing:
            await self._clear_removed(client)
        if self._info_due:
            self._info_due = False
            await self._publish_info(client)
        if self._republish:  # after a mapping reload: new entities, new discovery
            self._republish = False
            self._ha_online.clear()
            await self._publish_info(client)
            await self.discovery.publish(client, clear_stale=True)
            await self.everything(client)
        dirty, self._dirty = self._dirty, {}
        burst: list[Outgoing] = []
        devices_changed = False
        for device_id, keys in dirty.items():
            poller = self.engine.devices.get(device_id)
            if poller is None:  # a read back after its delay, of a device removed since
                continue
            due = self.discovery.due(poller, keys)  # first: the payload admits the values
            if due and await self.discovery.publish(client, only=device_id):
                self._spawn(self._state_again(device_id))
            devices_changed |= self._device_messages(poller, keys, burst)
        await client.publish_many(burst)
        if devices_changed:
            await self._publish_devices_list(client)
        while self._outbox:
            message = self._outbox.popleft()
            try:
                await client.publish(message.topic, message.payload, retain=message.retain)
            except MqttPublishError as exc:
                log.warning("%s", exc)

    async def _clear_removed(self, client: MqttClient) -> None:
        """Empty the retained topics of the devices no longer polled: the ones listed, then
        the others this session published under the device's topic; acknowledged together."""
        clearing = dict(self._clearing)
        prefix = self.topics.discovery_prefix + "/"
        topics: list[str] = []
        for device_id, listed in clearing.items():
            own = self.topics.device(device_id)
            under = {t for t in client.retained_topics if t == own or t.startswith(own + "/")}
            topics += [t for t in listed if t not in under] + sorted(under)
        topics = sorted(dict.fromkeys(topics), key=lambda t: not t.startswith(prefix))
        await client.publish_many((topic, "", True) for topic in topics)
        for device_id, listed in clearing.items():
            if self._clearing.get(device_id) is listed:  # not restored meanwhile
                del self._clearing[device_id]
        log.info("emptied %d retained topics of %s", len(topics), ", ".join(clearing))

    async def everything(self, client: MqttClient, *, with_info: bool = False) -> None:
        """Every device's state and availability, the devices list (and ``bridge/info``),
        sent at once and acknowledged together."""
        self._availability.clear()
        burst: list[Outgoing] = []
        for poller in self.engine.devices.values():
            self._device_messages(poller, set(poller.state.published), burst)
        burst.append((self.topics.bridge_devices, self._devices_list(), True))
        if with_info:
            burst.append((self.topics.bridge_info, self.info(), True))
        await client.publish_many(burst)

    def info(self) -> str:
        """``bridge/info``'s payload."""
        return json.dumps(self._info(), default=str)

    def _device_messages(self, poller: DevicePoller, keys: set[str], burst: list[Outgoing]) -> bool:
        """Add a device's JSON, changed plain values and availability (when it changed) to
        ``burst``; True if the availability changed."""
        device_id = poller.device.id
        topics = self.topics
        output = self.mqtt.output
        if poller.values and output != "values":
            document = state_document(
                poller.mapping, poller.points, poller.values, poller.state.last_reset
            )
            burst.append((topics.device(device_id), compact(document), True))
        if output != "json":
            for key in sorted(keys & poller.state.published):
                payload = plain_payload(poller.values.get(key))
                burst.append((topics.value(device_id, key), payload, True))
        # online once it answered and its values are out, offline once it stopped
        # answering; before its first poll settled, nothing (a retained "offline" for a
        # device that is only being asked would be a false alarm)
        if poller.health.online is False:
            availability = "offline"
        elif poller.health.online and poller.values:
            availability = "online"
        else:
            return False
        if self._availability.get(device_id) != availability:
            self._availability[device_id] = availability
            burst.append((topics.availability(device_id), availability, True))
            return True
        return False

    async def _state_again(self, device_id: str) -> None:
        """Publish a device's state once more after Home Assistant took its new discovery:
        it applies a changed payload in the background, and a state that arrived first (a
        code now in the options, a number now in range) would have been dropped."""
        await asyncio.sleep(STATE_AFTER_DISCOVERY)
        self.again(device_id)

    async def _publish_devices_list(self, client: MqttClient) -> None:
        await client.publish(self.topics.bridge_devices, self._devices_list(), retain=True)

    async def _publish_info(self, client: MqttClient) -> None:
        await client.publish(self.topics.bridge_info, self.info(), retain=True)

    def _devices_list(self) -> str:
        listing = [
            {
                "id": p.device.id,
                "name": p.device.display_name,
                "mapping": p.device.mapping,
                "model": f"{p.mapping.manufacturer} {p.mapping.model}",
                "bus": p.device.bus,
                "unit": p.device.unit,
                "state": _availability_word(p.health.online),
            }
            for p in self.engine.devices.values()
        ]
        return compact(listing)


def _availability_word(online: bool | None) -> str:
    return "unknown" if online is None else "online" if online else "offline"
