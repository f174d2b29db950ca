"""The JSON documents of the page's API, built from what the health report and the state
topics use: ``engine.snapshot()`` through ``build_health_report``, each poller's values
through ``bridge.core.state``. Nothing here touches a bus or waits.

    overview   {version, time, uptime_s, mqtt, subscriptions, raw_writes, refused, gateway,
                devices: [summary],
                buses: [{id, transport, connected, utilisation, requests_per_s, requests,
                         timeouts, frame_errors, exceptions, reopenings}]}
    summary    {id, name, model, mapping, bus, unit, state, status, status_text, alarms,
                alarm_names, last_success, latency_p50_ms, latency_p95_ms, requests,
                errors, timeouts, backoff_s}
    device     summary + {topic, values: [value]}
    value      {key, name, value, text, unit, decimals, alarm, component, category, writable}
               (decimals null: not known yet, a scale_by value's exponent unread)
    values     {device, status, status_text, alarms, alarm_names, values: {key: value}}
               (the keys that changed)

The page speaks as Home Assistant does (``bridge.core.wording``): ``name`` is the entity's
name as Home Assistant shows it, ``text`` the value in its words (``Running forward``,
``Not running``, ``12.5``, ``Unknown``) beside ``value`` as the state document has it
(``running_forward``, ``false``); ``status_text`` and ``alarm_names`` likewise, beside
``status`` and ``alarms`` (the keys MQTT clients match).

Bus utilisation and request rates cover the last ``WINDOW`` seconds (``BusWindow``).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from typing import Any

from bridge.core.codec import Value, decimals_of, unit_of
from bridge.core.discovery_entity import shown_name
from bridge.core.health_report import Snapshot, build_health_report
from bridge.core.mapping import Point
from bridge.core.state import active_alarms, alarm_active, published
from bridge.core.wording import alarm_texts, unit_sources, value_text
from bridge.modbus.poller import DevicePoller

WINDOW = 10.0  # seconds of bus traffic the utilisation covers


class BusWindow:
    """Snapshots of the last ``WINDOW`` seconds, so that rates cover a recent stretch."""

    def __init__(self, window: float = WINDOW) -> None:
        self.window = window
        self._kept: deque[Snapshot] = deque()

    def report(self, snapshot: Snapshot) -> dict[str, Any]:
        """The health document of ``snapshot``, rates since the newest snapshot kept that is
        at least ``window`` seconds old (or the oldest kept, or the start)."""
        while len(self._kept) > 1 and snapshot.monotonic - self._kept[1].monotonic >= self.window:
            self._kept.popleft()
        previous = self._kept[0] if self._kept else None
        if not self._kept or snapshot.monotonic - self._kept[-1].monotonic >= 1.0:
            self._kept.append(snapshot)
        return build_health_report(snapshot, previous)


def overview(
    pollers: Iterable[DevicePoller], report: dict[str, Any], **bridge: Any
) -> dict[str, Any]:
    """The overview document: ``bridge`` fields (version, mqtt, subscriptions: group ->
    live|pending|refused, raw_writes, refused) first."""
    return {
        **bridge,
        "time": report["timestamp"],
        "uptime_s": report["uptime_s"],
        "devices": [summary(p, report["devices"].get(p.device.id, {})) for p in pollers],
        "buses": [{"id": bus_id, **bus} for bus_id, bus in report["buses"].items()],
    }


def summary(poller: DevicePoller, health: dict[str, Any]) -> dict[str, Any]:
    """One device's row: who it is, whether it answers, how fast, how often it failed."""
    device, mapping = poller.device, poller.mapping
    return {
        "id": device.id,
        "name": device.display_name,
        "model": f"{mapping.manufacturer} {mapping.model}",
        "mapping": device.mapping,
        "bus": device.bus,
        "unit": device.unit,
        "state": health.get("state", "unknown"),
        "error": health.get("error"),  # offline with a reason: a failed SunSpec walk
        **status_and_alarms(poller),
        "last_success": health.get("last_success"),
        "latency_p50_ms": health.get("latency_p50_ms"),
        "latency_p95_ms": health.get("latency_p95_ms"),
        "requests": health.get("requests", 0),
        "errors": health.get("errors", 0),
        "timeouts": health.get("timeouts", 0),
        "backoff_s": health.get("backoff_s", 0.0),
    }


def device_document(poller: DevicePoller, health: dict[str, Any], topic: str) -> dict[str, Any]:
    """A device's page: its summary, its MQTT topic and every published value."""
    units = unit_sources(poller.points)
    return {
        **summary(poller, health),
        "topic": topic,
        "values": [value_row(poller, key, units) for key in published(poller.points)],
    }


def status_and_alarms(poller: DevicePoller) -> dict[str, Any]:
    """The device's status and active alarms, as the state document has them and in the
    words Home Assistant shows."""
    device, mapping = poller.device, poller.mapping
    status = poller.values.get(mapping.status) if mapping.status else None
    point = poller.points.get(mapping.status) if mapping.status else None
    alarms = active_alarms(poller.points, poller.values)
    return {
        "status": status,
        "status_text": None if point is None else _text(poller, point, status),
        "alarms": alarms,
        "alarm_names": alarm_texts(poller.points, alarms, device.display_name),
    }


def value_row(poller: DevicePoller, key: str, units: frozenset[str]) -> dict[str, Any]:
    """One value, as published and as Home Assistant shows it (``units``: the keys whose
    labels are units, ``wording.unit_sources``)."""
    point = poller.points[key]
    entity = point.entity
    value = poller.values.get(key)
    return {
        "key": key,
        "name": shown_name(entity.name, poller.device.display_name),
        "value": value,
        "text": _text(poller, point, value, key in units),
        "unit": unit_of(point, poller.image),
        "decimals": decimals_of(point, poller.image),
        "alarm": alarm_active(point, value),
        "component": entity.component.value,
        "category": entity.ha.entity_category,
        "writable": entity.writable,
    }


def changed_values(poller: DevicePoller, keys: Iterable[str]) -> dict[str, Any]:
    """The values of ``keys`` (those published) with the device's status and alarms."""
    shown = set(published(poller.points))
    units = unit_sources(poller.points)
    return {
        "device": poller.device.id,
        **status_and_alarms(poller),
        "values": {key: value_row(poller, key, units) for key in sorted(set(keys) & shown)},
    }


def _text(poller: DevicePoller, point: Point, value: Value, units: bool = False) -> str:
    decimals = decimals_of(point, poller.image)
    allowed = poller.device.allow_dangerous_writes
    return value_text(point.entity, value, decimals, allowed, units)
