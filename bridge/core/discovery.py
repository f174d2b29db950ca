"""Home Assistant MQTT discovery payloads for the bridge and its devices. Pure.

Device-based discovery (the default): one retained JSON document per device on
``<prefix>/device/<device>/config`` holding ``device``, ``origin``, the shared
availability (the bridge's and the device's, both required: ``availability_mode: all``)
and one ``cmps`` entry per published entity, plus ``alarms`` (when the mapping has alarm
entities). The mapping's status entity is published once, as itself (the Smartgen's
"Genset status", the Vacon's "Running"): the state document's ``status`` copies its value
for MQTT clients, never as a second, identical component. Entity
mode (for Home Assistant versions without device-based discovery) publishes the same
components one by one on ``<prefix>/<component>/<device>/<key>/config`` with the shared
options inlined.

The state topic is set per component rather than shared at the root: Home Assistant
copies a shared ``state_topic`` into every component, and a write-only number (a
setpoint the device does not read back) would then parse the whole state document as its
value. A write-only select (a command
word) has a template of its own on the document (``discovery_entity.
command_state_template``).

The bridge is a device of its own: a connectivity binary_sensor on ``<base>/bridge/state``
and, per bus, diagnostic sensors whose value templates read the periodic
``<base>/bridge/health`` document (see ``health_report``): the request rate, utilisation
(%), timeouts and frame errors. Each device carries its own: its Modbus state, p95
latency (ms), errors and requests (unique ids and entity ids as when they were on the
bridge device).

``units`` are units read from registers (``unit_from``) and ``limits`` the current
limits read from registers (``min_from``/``max_from``, see ``codec.limits_of``);
``readings`` the values read that the payload must admit (``discovery_entity.
shown_readings``: an enum code the mapping has no label for, a number outside its range):
the app rebuilds and republishes discovery when any of them changes, so that Home
Assistant never drops a value the device holds.
"""

from __future__ import annotations

import json
from collections.abc import Mapping as AnyMapping
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Literal

from bridge import __version__
from bridge.core.codec import Value
from bridge.core.discovery_alarms import alarm_event_components, alarms_config
from bridge.core.discovery_entity import (
    QOS,
    ComponentContext,
    Config,
    Limits,
    component_config,
    slug,
)
from bridge.core.mapping import Mapping
from bridge.core.topics import Topics

SUPPORT_URL = "https://github.com/modbus-mqtt-bridge/modbus-mqtt-bridge"
ALARMS_KEY = "alarms"
BRIDGE_NAME = "Modbus MQTT bridge"
_NO_UNITS: AnyMapping[str, str | None] = MappingProxyType({})
_NO_LIMITS: AnyMapping[str, Limits] = MappingProxyType({})
_NO_READINGS: AnyMapping[str, Value] = MappingProxyType({})
_ROOT_ONLY = ("cmps",)

Mode = Literal["device", "entity"]


@dataclass(frozen=True, slots=True)
class Publish:
    """One MQTT message to send."""

    topic: str
    payload: str  # serialized JSON; "" deletes a retained config
    retain: bool = True


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """What discovery needs to know of one configured device."""

    id: str
    name: str
    mapping: Mapping
    options: dict[str, str]
    bus: str
    unit: int
    allow_dangerous_writes: bool
    fast_interval: float
    slow_interval: float
    intervals: AnyMapping[str, float] = field(default_factory=dict)  # each key's, resolved


@dataclass(frozen=True, slots=True)
class Origin:
    """The software that publishes the discovery messages: the bridge itself."""

    name: str = "modbus-mqtt-bridge"
    sw_version: str = __version__
    support_url: str = SUPPORT_URL

    def as_dict(self) -> dict[str, str]:
        return {"name": self.name, "sw_version": self.sw_version, "support_url": self.support_url}


def bridge_identifier(topics: Topics) -> str:
    """The bridge device's identifier, which every device's ``via_device`` names."""
    return f"{topics.base}_bridge"


def build_device_discovery(
    device: DeviceInfo,
    topics: Topics,
    origin: Origin,
    *,
    units: AnyMapping[str, str | None] = _NO_UNITS,
    limits: AnyMapping[str, Limits] = _NO_LIMITS,
    readings: AnyMapping[str, Value] = _NO_READINGS,
    state_refresh: float = 300.0,
    health: bool = False,
) -> dict[str, Any]:
    """The device-based discovery payload for ``<prefix>/device/<device>/config``; with
    ``health``, the device's own sensors of ``<base>/bridge/health`` too."""
    context = ComponentContext(
        topics=topics,
        device_id=device.id,
        allow_dangerous_writes=device.allow_dangerous_writes,
        fast_interval=device.fast_interval,
        slow_interval=device.slow_interval,
        intervals=device.intervals,
        state_refresh=state_refresh,
        units=units,
        limits=limits,
        readings=readings,
        device_name=device.name,
        keys=frozenset([*device.mapping.entities, ALARMS_KEY]),
    )
    return {
        "device": {
            "identifiers": [f"{topics.base}_{device.id}"],
            "manufacturer": device.mapping.manufacturer,
            "model": device.mapping.model,
            "name": device.name,
            "via_device": bridge_identifier(topics),
        },
        "origin": origin.as_dict(),
        "availability": [
            {"topic": topics.bridge_state},
            {"topic": topics.availability(device.id)},
        ],
        "availability_mode": "all",
        "cmps": device_components(device.mapping, device.options, context)
        | (device_health_components(topics, device.id) if health else {}),
    }


def device_components(
    mapping: Mapping, options: AnyMapping[str, str], context: ComponentContext
) -> dict[str, Config]:
    """Every component of one device, by key: entities (the status entity among them),
    then ``alarms``, the alarm events and their device triggers."""
    active = mapping.active(dict(options))
    components: dict[str, Config] = {}
    for key, entity in active.items():
        config = component_config(key, entity, context)
        if config is not None:
            components[key] = config
    if any(entity.alarm for entity in active.values()):
        components[ALARMS_KEY] = alarms_config(context, active)
        components |= alarm_event_components(context, active)
    return components


def build_discovery(
    device: DeviceInfo,
    topics: Topics,
    origin: Origin,
    *,
    mode: Mode,
    units: AnyMapping[str, str | None] = _NO_UNITS,
    limits: AnyMapping[str, Limits] = _NO_LIMITS,
    readings: AnyMapping[str, Value] = _NO_READINGS,
    state_refresh: float = 300.0,
    health: bool = False,
) -> list[Publish]:
    """The retained discovery messages of one device: one (device mode) or one per
    component (entity mode)."""
    payload = build_device_discovery(
        device,
        topics,
        origin,
        units=units,
        limits=limits,
        readings=readings,
        state_refresh=state_refresh,
        health=health,
    )
    if mode == "device":
        return [Publish(topics.device_config(device.id), dump(payload))]
    return _per_component(payload, topics, device.id)


def build_bridge_discovery(
    topics: Topics,
    origin: Origin,
    bridge_id: str,
    *,
    mode: Mode = "device",
    buses: Sequence[str] = (),
) -> list[Publish]:
    """The bridge as a device of its own, with a connectivity binary_sensor on
    ``<base>/bridge/state`` (no availability: offline shows as disconnected), and
    diagnostic sensors reading ``<base>/bridge/health`` for each of ``buses`` (ids; pass
    none when health reports are off), available while the bridge is online. Each
    device's health sensors are on the device (``build_device_discovery(health=True)``).

    ``bridge_id`` names the bridge in the discovery topic
    (``<prefix>/device/<bridge_id>/config``) and in its entity ids.
    """
    identifier = bridge_identifier(topics)
    connection = {
        "platform": "binary_sensor",
        "unique_id": f"{identifier}_connection_state",
        "default_entity_id": f"binary_sensor.{slug(bridge_id)}_connection_state",
        "name": "Connection state",
        "qos": QOS,
        "entity_category": "diagnostic",
        "enabled_by_default": True,  # whether the bridge runs: the first thing to look at
        "device_class": "connectivity",
        "state_topic": topics.bridge_state,
        "payload_on": "online",
        "payload_off": "offline",
    }
    payload = {
        "device": {
            "identifiers": [identifier],
            "manufacturer": origin.name,
            "model": BRIDGE_NAME,
            "name": BRIDGE_NAME,
            "sw_version": origin.sw_version,
        },
        "origin": origin.as_dict(),
        "cmps": {"connection_state": connection} | bus_health_components(topics, bridge_id, buses),
    }
    if mode == "device":
        return [Publish(topics.device_config(bridge_id), dump(payload))]
    return _per_component(payload, topics, bridge_id)


@dataclass(frozen=True, slots=True)
class HealthSensor:
    """One diagnostic sensor per bus or per device, reading a field of bridge/health;
    enabled by default when it is the first thing to look at (``enabled_reason``)."""

    suffix: str
    name: str
    field: str
    options: AnyMapping[str, Any]
    percent: bool = False  # a 0..1 fraction shown as %
    enabled_reason: str | None = None

    def template(self, section: str, item: str) -> str:
        """The field of ``item`` in the report's ``section`` (``buses``, ``devices``); a
        report without it (sent while the config changed: a device renamed or removed
        before Home Assistant had its new discovery) renders None, unknown to Home
        Assistant, instead of a template error in its log."""
        value = f"value_json.get('{section}', {{}}).get('{item}', {{}}).get('{self.field}')"
        if not self.percent:
            return f"{{{{ {value} }}}}"
        return f"{{% set v = {value} %}}{{{{ none if v is none else (v * 100) | round(1) }}}}"


_COUNTER = MappingProxyType({"state_class": "total_increasing"})
BUS_HEALTH_SENSORS = (
    HealthSensor(
        "request_rate",
        "request rate",
        "requests_per_s",
        {
            "unit_of_measurement": "req/s",
            "state_class": "measurement",
            "icon": "mdi:swap-horizontal",
        },
    ),
    HealthSensor(
        "utilisation",
        "utilisation",
        "utilisation",
        {"unit_of_measurement": "%", "state_class": "measurement", "icon": "mdi:gauge"},
        percent=True,
        enabled_reason="a full bus delays every device on it",
    ),
    HealthSensor(
        "timeouts",
        "timeouts",
        "timeouts",
        _COUNTER | {"icon": "mdi:timer-alert"},
        enabled_reason="a silent device or a broken line shows here first",
    ),
    HealthSensor(
        "frame_errors",
        "frame errors",
        "frame_errors",
        _COUNTER | {"icon": "mdi:alert-circle"},
        enabled_reason="wiring, termination and baud rate problems show here first",
    ),
)
DEVICE_HEALTH_SENSORS = (
    HealthSensor(
        "state",
        "Modbus state",
        "state",
        {"device_class": "enum", "options": ["online", "offline", "unknown"]},
        enabled_reason="whether the device answers: the first thing to look at",
    ),
    HealthSensor(
        "latency_p95",
        "Modbus latency p95",
        "latency_p95_ms",
        {"unit_of_measurement": "ms", "device_class": "duration", "state_class": "measurement"},
    ),
    HealthSensor(
        "errors",
        "Modbus errors",
        "errors",
        _COUNTER | {"icon": "mdi:alert"},
        enabled_reason="refused and failed requests: the second thing to look at",
    ),
    HealthSensor("requests", "Modbus requests", "requests", _COUNTER | {"icon": "mdi:counter"}),
)


def bus_health_components(
    topics: Topics, bridge_id: str, buses: Sequence[str]
) -> dict[str, Config]:
    """The bridge's diagnostic sensors of each bus on ``<base>/bridge/health``, by
    component key ``bus_<bus>_<suffix>``. The health document is retained, so a sensor has
    a value as soon as Home Assistant subscribes; it is unavailable while the bridge is
    offline."""
    components: dict[str, Config] = {}
    for bus in buses:
        for sensor in BUS_HEALTH_SENSORS:
            key = f"bus_{bus}_{sensor.suffix}"
            name = f"Bus {bus} {sensor.name}"
            components[key] = _health_sensor(topics, bridge_id, key, name, sensor) | {
                "availability_topic": topics.bridge_state,
                "value_template": sensor.template("buses", bus),
            }
    return components


def device_health_components(topics: Topics, device_id: str) -> dict[str, Config]:
    """The device's diagnostic sensors on ``<base>/bridge/health``, by component key
    ``device_<device>_<suffix>``: on the device, with the unique ids and entity ids they
    had on the bridge device, available while the bridge is online (also while the device
    is offline: their own availability replaces the device's)."""
    components: dict[str, Config] = {}
    for sensor in DEVICE_HEALTH_SENSORS:
        key = f"device_{device_id}_{sensor.suffix}"
        components[key] = _health_sensor(topics, topics.base, key, sensor.name, sensor) | {
            "availability": [{"topic": topics.bridge_state}],
            "value_template": sensor.template("devices", device_id),
        }
    return components


def _health_sensor(
    topics: Topics, bridge_id: str, key: str, name: str, sensor: HealthSensor
) -> Config:
    return {
        "platform": "sensor",
        "unique_id": f"{bridge_identifier(topics)}_{key}",
        "default_entity_id": f"sensor.{slug(bridge_id)}_{slug(key)}",
        "name": name,
        "qos": QOS,
        "entity_category": "diagnostic",
        "enabled_by_default": sensor.enabled_reason is not None,
        "state_topic": topics.bridge_health,
        **sensor.options,
    }


def _per_component(payload: dict[str, Any], topics: Topics, node_id: str) -> list[Publish]:
    """Entity-mode messages: each component with the shared root options inlined."""
    shared = {name: value for name, value in payload.items() if name not in _ROOT_ONLY}
    messages = []
    for key, component in payload["cmps"].items():
        body = {name: value for name, value in component.items() if name != "platform"}
        topic = topics.entity_config(component["platform"], node_id, key)
        messages.append(Publish(topic, dump(body | shared)))
    return messages


def removal(topic: str) -> Publish:
    """The empty retained message that deletes a discovery config."""
    return Publish(topic, "")


def dump(payload: AnyMapping[str, Any]) -> str:
    """Compact JSON, UTF-8 as is (units such as °C and m³)."""
    return json.dumps(payload, ensure_ascii=False, separators=(",", ":"))
