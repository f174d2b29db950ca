"""Home Assistant discovery as the bridge publishes it: built from the live pollers (units
and limits read from registers), republished when those change, stale configs emptied.

A device whose discovery depends on registers (``unit_from``, ``min_from``, ``max_from``)
is published once its first poll has read them (or found the device silent), never
before with placeholder units and limits: Home Assistant would create its entities
without units. Devices without such entities are published at once.

``DiscoveryPublisher.publish(client)`` sends the bridge device and every ready device;
with ``only=device_id`` just that device, and only when its payload changed; with
``clear_stale`` the retained configs this bridge published before but no longer produces
(a removed device or entity) are emptied after (a device not ready yet keeps its config);
the bridge asks for that until one sweep was done (``swept``), again after a reload.
Those are found two ways: the retained configs under the discovery prefix that carry this
bridge's identifiers, and the list of topics the last full publish recorded, retained on
``<base>/bridge/discovery``, which is read by its exact name: RabbitMQ sends no retained
message to a subscription with a wildcard, so the first way finds nothing there. Any client
may publish in both places: a config of another shape is not ours, and of the record only
topics that can be published to count (``recorded_topics``), never an error.
``due(poller, changed)`` says whether a poll's changes call for ``publish(only=...)``: the
device just became ready, a unit or a limit read from a register changed, or a value Home
Assistant would drop (an enum code the mapping does not know, a number outside its range)
is not admitted by the payload sent (the payload admits what the device reads).
"""

from __future__ import annotations

import contextlib
import itertools
import json
import logging
import weakref

from bridge.config import LoadedConfig
from bridge.core.codec import Value, limits_of, unit_of
from bridge.core.device_state import DeviceState
from bridge.core.discovery import (
    DeviceInfo,
    Origin,
    Publish,
    build_bridge_discovery,
    build_discovery,
    removal,
)
from bridge.core.discovery_entity import admittable, admitted, shown_readings
from bridge.core.entity import PollClass
from bridge.core.mapping import Point
from bridge.core.topics import Topics
from bridge.errors import MissingDataError
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DevicePoller
from bridge.mqtt import MqttClient, MqttPublishError, MqttRefusedError

log = logging.getLogger(__name__)
MAX_RECORDED = 20_000  # topics taken from a bridge/discovery record, at most
MAX_RECORDED_BYTES = 4096  # a longer recorded topic is not one the bridge wrote
_NOT_IN_TOPICS = ("+", "#", "\x00")  # wildcards and NUL: no publish topic holds them


class DiscoveryPublisher:
    """The discovery side of one bridge."""

    def __init__(
        self, loaded: LoadedConfig, engine: Engine, topics: Topics, origin: Origin
    ) -> None:
        self.engine = engine
        self.topics = topics
        self.origin = origin
        self._mqtt = loaded.config.mqtt
        self._health_interval = loaded.config.bridge.health_interval
        self._sent: dict[str, int] = {}  # device -> digest of its configs as sent
        self._readings: dict[str, dict[str, Value]] = {}  # the readings each payload admits
        self._sweep_refused = False  # the broker refused the sweep's subscriptions (said once)
        # the stale configs were swept this run: only a start (or a reload) leaves any, and
        # the sweep is a retained read, seconds on a cluster after a node failure
        self.swept = False
        # per device state (so per set of points): its sources and its admittable points
        self._facts: weakref.WeakKeyDictionary[
            DeviceState, tuple[frozenset[str], dict[str, Point]]
        ] = weakref.WeakKeyDictionary()

    def forget(self, device_id: str) -> None:
        """Build the device's discovery afresh next time (its mapping changed), and sweep
        stale configs again at the next session."""
        self.swept = False
        self._sent.pop(device_id, None)
        self._readings.pop(device_id, None)

    def stale(self, poller: DevicePoller, keys: set[str]) -> bool:
        """True when the device's payload changes with these keys: a unit or limit source,
        or a reading Home Assistant would drop that the payload sent does not admit (a
        reading back inside its range keeps the wider payload until the next full one)."""
        if keys & self.sources(poller):
            return True
        sent = self._readings.get(poller.device.id, {})
        return not admitted(poller.points, sent, self._shown(poller), poller.image)

    def _shown(self, poller: DevicePoller) -> dict[str, Value]:
        return shown_readings(self._known(poller)[1], poller.values, poller.image)

    def _known(self, poller: DevicePoller) -> tuple[frozenset[str], dict[str, Point]]:
        """The device's sources and admittable points, worked out once per set of points
        (every flush asks: issue 27)."""
        facts = self._facts.get(poller.state)
        if facts is None:
            sources = frozenset(
                source.key
                for point in poller.points.values()
                for source in (point.unit_source, point.min_source, point.max_source)
                if source is not None
            )
            facts = self._facts[poller.state] = (sources, admittable(poller.points))
        return facts

    def ready(self, poller: DevicePoller) -> bool:
        """True when the device's discovery has what it depends on (or depends on nothing)."""
        return poller.first_poll_done or not self.sources(poller)

    def due(self, poller: DevicePoller, changed: set[str]) -> bool:
        """True when a poll's changes may change what this device's discovery says: it just
        became ready, or its payload is stale (see ``stale``)."""
        if poller.device.id not in self._sent:
            return self.ready(poller)
        return self.stale(poller, changed)

    @property
    def pending(self) -> list[str]:
        """Devices whose discovery waits for their first poll."""
        if self._mqtt.discovery == "off":
            return []
        return [d for d, p in self.engine.devices.items() if d not in self._sent and p.points]

    def _device_info(self, poller: DevicePoller) -> DeviceInfo:
        device = poller.device
        return DeviceInfo(
            id=device.id,
            name=device.display_name,
            mapping=poller.mapping,
            options=dict(device.options),
            bus=device.bus,
            unit=device.unit,
            allow_dangerous_writes=device.allow_dangerous_writes,
            fast_interval=poller.intervals[PollClass.FAST],
            slow_interval=poller.intervals[PollClass.SLOW],
            intervals=poller.state.intervals,
        )

    def sources(self, poller: DevicePoller) -> frozenset[str]:
        """Keys whose value changes a discovery payload (units and limits from registers)."""
        return self._known(poller)[0]

    def discovery_for(self, poller: DevicePoller) -> list[Publish]:
        units, limits = {}, {}
        for key, point in poller.points.items():
            if point.unit_source is not None:
                units[key] = unit_of(point, poller.image)
            if point.min_source is not None or point.max_source is not None:
                with contextlib.suppress(MissingDataError):
                    limits[key] = limits_of(point, poller.image)
        readings = self._shown(poller)
        self._readings[poller.device.id] = readings
        return build_discovery(
            self._device_info(poller),
            self.topics,
            self.origin,
            mode=self._mqtt.discovery if self._mqtt.discovery != "off" else "device",
            units=units,
            limits=limits,
            readings=readings,
            state_refresh=self._mqtt.state_refresh,
            health=self._health_interval > 0,  # the device's health sensors read it
        )

    async def publish(
        self, client: MqttClient, *, clear_stale: bool = False, only: str | None = None
    ) -> bool:
        """Publish the bridge's and every device's configs (``only``: that device's, and
        only if they changed); True if a device's configs went out. Device by device,
        remembering a digest of what went out, not the payloads (about 26 kB per device)."""
        if self._mqtt.discovery == "off":
            return False
        sent = False
        current: set[str] = set()
        if only is None:
            health = self._health_interval > 0  # the sensors read it
            bridge_messages = build_bridge_discovery(
                self.topics,
                self.origin,
                self.topics.base,
                buses=list(self.engine.schedulers) if health else [],
            )
            await self._send(client, bridge_messages, current)
        for device_id, poller in self.engine.devices.items():
            if (only is not None and device_id != only) or not poller.points:
                continue  # (no points: a SunSpec device not walked yet)
            messages = self.discovery_for(poller)
            current.update(m.topic for m in messages)  # not ready yet: its config stays
            if not self.ready(poller):
                continue  # published after its first poll (Bridge._flush)
            digest = hash(tuple(messages))
            if only is not None and digest == self._sent.get(device_id):
                return False  # nothing changed
            self._sent[device_id] = digest
            await self._send(client, messages, current)
            sent = True
        if clear_stale:
            await self._clear_stale(client, current)
            record = json.dumps(sorted(current)).encode()
            await client.publish(self.topics.bridge_discovery, record, retain=True)
            self.swept = True
        return sent

    @staticmethod
    async def _send(client: MqttClient, messages: list[Publish], sent: set[str]) -> None:
        await client.publish_many((m.topic, m.payload, True) for m in messages)
        sent.update(m.topic for m in messages)

    async def _clear_stale(self, client: MqttClient, current: set[str]) -> None:
        """Empty the retained configs this bridge published before but no longer produces;
        skipped, with a warning the first time, when the broker refuses the subscriptions
        that find them (an ACL)."""
        try:
            stale = await self._stale(client, current)
        except MqttRefusedError as exc:
            level = logging.DEBUG if self._sweep_refused else logging.WARNING
            self._sweep_refused = True
            log.log(level, "%s: stale discovery configs are not removed", exc)
            return
        failed: list[MqttPublishError] = []
        for topic in sorted(stale):
            log.info("removing stale discovery config %s", topic)
            message = removal(topic)
            try:
                await client.publish(message.topic, message.payload, retain=True)
            except MqttPublishError as exc:  # one topic: the others are still removed
                failed.append(exc)
        if failed:
            log.warning("%d stale discovery config(s) not removed: %s", len(failed), failed[0])

    async def _stale(self, client: MqttClient, current: set[str]) -> set[str]:
        """The configs to empty, not in ``current``: retained ones of ours, and recorded
        ones, except those the broker shows holding another's config (any client may
        overwrite the record: it must not empty another integration's configs). A broker
        that sends no retained message to wildcards (RabbitMQ) shows none: there the
        record is all there is to go by."""
        prefix = self.topics.discovery_prefix
        found: dict[str, bytes] = {}
        for pattern in (f"{prefix}/+/+/config", f"{prefix}/+/+/+/config"):
            found |= await client.retained(pattern, keep=lambda topic: topic not in current)
        ours = {t for t, payload in found.items() if payload and self._ours(payload)}
        others = found.keys() - ours
        recorded = await client.retained(self.topics.bridge_discovery)
        listed = recorded_topics(recorded.get(self.topics.bridge_discovery, b""), prefix)
        return (ours | (listed - others)) - current

    def _ours(self, payload: bytes) -> bool:
        """True when a retained config names a device of this bridge. Any client may
        publish there, so a config of another shape (a device that is not an object,
        identifiers that are not a list or a string, JSON nested too deeply) is not ours,
        never an error."""
        try:
            data = json.loads(payload)
        except (ValueError, RecursionError):  # RecursionError: nested deeper than it follows
            return False
        if not isinstance(data, dict):
            return False
        device = data.get("device") or data.get("dev") or {}
        if not isinstance(device, dict):
            return False
        identifiers = device.get("identifiers") or device.get("ids") or []
        if isinstance(identifiers, str):
            identifiers = [identifiers]
        if not isinstance(identifiers, list):
            return False
        mark = f"{self.topics.base}_"
        return any(isinstance(i, str) and i.startswith(mark) for i in identifiers)


def recorded_topics(payload: bytes, prefix: str) -> set[str]:
    """The discovery config topics of a ``bridge/discovery`` record. Any client may
    overwrite the record, so only what the bridge can publish an empty message to counts:
    strings under ``prefix`` ending in ``/config``, without wildcards or NUL, UTF-8, at
    most MAX_RECORDED_BYTES long; the first MAX_RECORDED of them."""
    try:
        topics = json.loads(payload) if payload else []
    except (ValueError, RecursionError):
        return set()
    if not isinstance(topics, list):
        return set()
    return set(itertools.islice((t for t in topics if _removable(t, prefix)), MAX_RECORDED))


def _removable(topic: object, prefix: str) -> bool:
    if not isinstance(topic, str) or not topic.startswith(f"{prefix}/"):
        return False
    if not topic.endswith("/config") or any(c in topic for c in _NOT_IN_TOPICS):
        return False
    try:
        return len(topic.encode()) <= MAX_RECORDED_BYTES
    except UnicodeEncodeError:  # a lone surrogate
        return False
