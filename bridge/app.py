"""The bridge: the Modbus engine and the MQTT session wired together.

``Bridge(loaded).run()`` runs one TaskGroup: the engine (every bus and device) and the
MQTT session, which reconnects by itself. Every (re)connect subscribes to the command
topics, clears retained discovery configs the bridge no longer produces, publishes
discovery and the whole state. Pollers report changes; a publisher sends the device's
JSON, the changed plain values and its availability. Commands run per device in arrival
order, each with an expiry: one that could not run in time is dropped with an error,
never executed late; anything refused or failing goes to ``<base>/<device>/error``.
Each session publishes ``<base>/bridge/health`` every ``bridge.health_interval``; the
optional metrics endpoint serves the same counters for the whole run.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections import deque
from typing import Any

from bridge import __version__
from bridge.config import LoadedConfig
from bridge.core.commands import Command, RecentMessages, parse_get, parse_set
from bridge.core.discovery import (
    Origin,
    Publish,
)
from bridge.core.health_report import HealthReporter
from bridge.core.management_request import response
from bridge.core.state import plain_payload, published, state_document
from bridge.core.topics import Action, Topics
from bridge.discovery_publisher import DiscoveryPublisher
from bridge.errors import BridgeError, ValueRejectedError
from bridge.management import Management
from bridge.metrics import serve_metrics
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DevicePoller, DeviceUpdate
from bridge.mqtt import Message, MqttClient, MqttError, run_with_reconnect

log = logging.getLogger(__name__)
OUTBOX = 200  # non-retained messages kept while the broker is away


class Bridge:
    """One config's buses and devices, published over one MQTT connection."""

    def __init__(self, loaded: LoadedConfig) -> None:
        config = loaded.config
        self.loaded = loaded
        self.mqtt = config.mqtt
        self.topics = Topics(config.mqtt.base_topic, config.mqtt.discovery_prefix)
        self.origin = Origin(sw_version=__version__)
        self.engine = Engine(loaded, self._on_update)
        self.discovery = DiscoveryPublisher(loaded, self.engine, self.topics, self.origin)
        self._wake = asyncio.Event()
        self._dirty: dict[str, set[str]] = {}
        self._outbox: deque[Publish] = deque(maxlen=OUTBOX)
        self._availability: dict[str, str] = {}
        self._recent = RecentMessages(window=max(60.0, 10 * self.mqtt.command_expiry))
        self._locks: dict[str, asyncio.Lock] = {}
        self._group: asyncio.TaskGroup | None = None
        self._health = HealthReporter()  # rates since the previous report
        self.mqtt_state = "connecting"  # "online" while connected, "offline" between
        self.management = Management(
            loaded, self.engine, on_reload=self._reloaded, mqtt_state=lambda: self.mqtt_state
        )
        self._republish = False

    # --- running ----------------------------------------------------------------------

    async def run(self) -> None:
        """Run until cancelled."""
        metrics = serve_metrics(self.loaded.config.bridge.metrics, self.engine.snapshot)
        async with metrics, asyncio.TaskGroup() as group:
            self._group = group
            group.create_task(self.engine.run(), name="engine")
            group.create_task(
                run_with_reconnect(
                    self.mqtt, self.topics.bridge_state, self._session, on_state=self._mqtt_is
                ),
                name="mqtt",
            )

    def _mqtt_is(self, state: str) -> None:
        self.mqtt_state = state

    async def _session(self, client: MqttClient) -> None:
        """One connection: subscribe, clean up, publish everything, then serve."""
        filters = (*self.topics.command_filters(), self.topics.bridge_requests)
        await client.subscribe(*filters, qos=max(1, self.mqtt.qos))
        await self._publish_info(client)
        await self.discovery.publish(client, clear_stale=True)
        await self._publish_everything(client)
        try:
            async with asyncio.TaskGroup() as group:
                group.create_task(self._publisher(client))
                group.create_task(self._refresher(client))
                group.create_task(self._health_reports(client))
                async for message in client.messages():
                    await self._handle(client, message)
        except ExceptionGroup as failed:
            raise _first(failed) from None

    async def _publisher(self, client: MqttClient) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            await self._flush(client)

    async def _refresher(self, client: MqttClient) -> None:
        while True:
            await asyncio.sleep(self.mqtt.state_refresh)
            await self._publish_everything(client)

    async def _health_reports(self, client: MqttClient) -> None:
        """``<base>/bridge/health`` now and every ``health_interval`` (never when 0)."""
        interval = self.loaded.config.bridge.health_interval
        while interval > 0:
            report = self._health.report(self.engine.snapshot())
            await client.publish(self.topics.bridge_health, json.dumps(report), retain=False)
            await asyncio.sleep(interval)

    # --- state ------------------------------------------------------------------------

    def _on_update(self, update: DeviceUpdate) -> None:
        self._dirty.setdefault(update.device_id, set()).update(update.changed)
        self._wake.set()

    async def _flush(self, client: MqttClient) -> None:
        if self._republish:  # after a mapping reload: new entities, new discovery
            self._republish = False
            await self._publish_info(client)
            await self.discovery.publish(client, clear_stale=True)
            await self._publish_everything(client)
        dirty, self._dirty = self._dirty, {}
        devices_changed = False
        for device_id, keys in dirty.items():
            poller = self.engine.devices[device_id]
            devices_changed |= await self._publish_device(client, poller, keys)
            if keys & self.discovery.sources(poller):
                await self.discovery.publish(client, only=device_id)
        if devices_changed:
            await self._publish_devices_list(client)
        while self._outbox:
            message = self._outbox.popleft()
            await client.publish(message.topic, message.payload, retain=message.retain)

    async def _publish_device(
        self, client: MqttClient, poller: DevicePoller, keys: set[str]
    ) -> bool:
        """Publish a device's JSON, changed plain values and availability; True if the
        availability changed."""
        device_id = poller.device.id
        topics = self.topics
        mapping = poller.mapping
        document = state_document(mapping, poller.points, poller.values)
        if poller.values:
            await client.publish(topics.device(device_id), json.dumps(document), retain=True)
        for key in sorted(keys & set(published(poller.points))):
            payload = plain_payload(poller.values.get(key))
            await client.publish(topics.value(device_id, key), payload, retain=True)
        availability = "online" if poller.health.online else "offline"
        if self._availability.get(device_id) != availability:
            self._availability[device_id] = availability
            await client.publish(topics.availability(device_id), availability, retain=True)
            return True
        return False

    async def _publish_everything(self, client: MqttClient) -> None:
        self._availability.clear()
        for poller in self.engine.devices.values():
            await self._publish_device(client, poller, set(published(poller.points)))
        await self._publish_devices_list(client)

    async def _publish_devices_list(self, client: MqttClient) -> None:
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
        await client.publish(self.topics.bridge_devices, json.dumps(listing), retain=True)

    # --- commands ---------------------------------------------------------------------

    async def _handle(self, client: MqttClient, message: Message) -> None:
        request = self.topics.parse_request(message.topic)
        if request is not None:
            self._spawn(self._answer(request, message.payload))
            return
        if message.topic == self.topics.ha_status:
            if message.payload.strip() == b"online":
                log.info("Home Assistant is online: publishing discovery and state again")
                await self.discovery.publish(client)
                await self._publish_everything(client)
            return
        target = self.topics.parse_command(message.topic)
        if target is None:
            return
        now = time.monotonic()
        if self._recent.is_duplicate(
            message.topic, message.payload, message.mid, message.duplicate, now
        ):
            log.info("ignoring a redelivered duplicate on %s", message.topic)
            return
        try:
            if target.action is Action.GET:
                keys = parse_get(message.payload)
                self._spawn(self._read_now(target.device_id, keys))
                return
            items = parse_set(message.payload, target.key)
        except ValueRejectedError as exc:
            self._error(
                target.device_id, target.key, message.payload.decode(errors="replace"), str(exc)
            )
            return
        expiry = self.mqtt.command_expiry
        for key, value in items.items():
            command = Command(target.device_id, key, value, now, now + expiry)
            self._spawn(self._execute(command))

    def _spawn(self, work: Any) -> None:
        if self._group is None:
            raise RuntimeError("the bridge is not running")
        self._group.create_task(work)

    async def _execute(self, command: Command) -> None:
        """Run one command in arrival order for its device, or drop it with an error."""
        poller = self.engine.devices.get(command.device_id)
        if poller is None:
            self._error(command.device_id, command.key, command.value, "no such device")
            return
        lock = self._locks.setdefault(command.device_id, asyncio.Lock())
        async with lock:
            left = command.expires - time.monotonic()
            if left <= 0:
                poller.writes.expired += 1
                self._error(
                    command.device_id,
                    command.key,
                    command.value,
                    "expired: not executed within the command expiry",
                )
                return
            if poller.health.online is False:
                poller.writes.rejected += 1
                self._error(
                    command.device_id,
                    command.key,
                    command.value,
                    f"{command.device_id} is offline: nothing written",
                )
                return
            try:
                await poller.write(command.key, command.value, deadline=command.expires)
            except BridgeError as exc:
                self._error(command.device_id, command.key, command.value, str(exc))

    async def _read_now(self, device_id: str, keys: list[str] | None) -> None:
        poller = self.engine.devices.get(device_id)
        if poller is None:
            self._error(device_id, None, keys, "no such device")
            return
        unknown = [k for k in keys or [] if k not in poller.points]
        if unknown:
            self._error(device_id, None, keys, f"no such entities: {', '.join(unknown)}")
            return
        await poller.read_now(keys)
        self._dirty.setdefault(device_id, set())
        self._wake.set()

    # --- management -------------------------------------------------------------------

    async def _answer(self, command: str, payload: bytes) -> None:
        """Run one management request and queue its response."""
        try:
            answer = await self.management.handle(command, payload)
        except Exception as exc:  # a request must never stop the bridge
            log.exception("management request %s failed", command)
            answer = response(error=f"internal error: {exc}")
        topic = self.topics.bridge_response(command)
        self._outbox.append(Publish(topic, answer, retain=False))
        self._wake.set()

    async def _reloaded(self, device_ids: list[str]) -> None:
        log.info("mappings reloaded for %s", ", ".join(device_ids))
        for device_id in device_ids:
            self.discovery.forget(device_id)
            self._dirty.pop(device_id, None)
        self._republish = True
        self._wake.set()

    async def _publish_info(self, client: MqttClient) -> None:
        info = json.dumps(self.management.info(), default=str)
        await client.publish(self.topics.bridge_info, info, retain=True)

    def _error(self, device_id: str, key: str | None, value: object, error: str) -> None:
        log.info("%s %s=%r refused: %s", device_id, key, value, error)
        payload = json.dumps({"key": key, "value": value, "error": error}, default=str)
        self._outbox.append(Publish(self.topics.error(device_id), payload, retain=False))
        self._wake.set()


def _availability_word(online: bool | None) -> str:
    return "unknown" if online is None else "online" if online else "offline"


def _first(failed: ExceptionGroup[Exception]) -> Exception:
    """The MQTT error that ended a session (so the reconnect loop sees it), else the group."""
    for exc in failed.exceptions:
        if isinstance(exc, ExceptionGroup):
            return _first(exc)
        if isinstance(exc, MqttError):
            return exc
    return failed
