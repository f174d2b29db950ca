"""What the demo shows: a live table (rich) or plain lines, read from the running bridge."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from urllib.parse import urlsplit

from rich.console import Group, RenderableType
from rich.table import Table
from rich.text import Text

from bridge.app import Bridge
from bridge.core.codec import unit_of
from bridge.core.entity import PollClass
from bridge.core.state import active_alarms, published
from bridge.modbus.poller import DevicePoller
from bridge.web import page_url

SAMPLES = 3  # values shown per device


@dataclass(slots=True)
class DemoView:
    """The bridge being shown and what the plain view has already printed."""

    bridge: Bridge
    broker_url: str
    broker_how: str
    modbus: str = ""
    _said: dict[str, str] = field(default_factory=dict)

    def banner(self) -> list[str]:
        parts = urlsplit(self.broker_url)
        host, port = parts.hostname or "127.0.0.1", parts.port or 1883
        base = self.bridge.topics.base
        first = next(iter(self.bridge.engine.devices), "borehole_pump")
        count = len(self.bridge.engine.devices)
        return [
            f"modbus-mqtt-bridge demo: {count} simulated devices on {self.modbus} "
            "(Modbus TCP, units 1-5)",
            f"MQTT broker: {self.broker_url} ({self.broker_how})",
            f"web page: {page_url(self.bridge.loaded.config.bridge.web)}",
            f"watch:    mosquitto_sub -h {host} -p {port} -t '{base}/#' -v",
            f"command:  mosquitto_pub -h {host} -p {port} -t {base}/{first}/start_stop/set -m ON",
            "Home Assistant: add the MQTT integration on this broker; the devices appear "
            f"through discovery ({self.bridge.topics.discovery_prefix}/device/<id>/config)",
            "Ctrl-C stops.",
        ]


def render_table(view: DemoView) -> RenderableType:
    """The banner and one row per device."""
    table = Table(expand=True)
    for heading in ("device", "model", "unit", "state", "status", "alarms", "values", "topic"):
        table.add_column(heading, overflow="fold")
    for poller in view.bridge.engine.devices.values():
        state = _state(poller)
        colour = {"online": "green", "offline": "red"}.get(state, "yellow")
        alarms = active_alarms(poller.points, poller.values)
        table.add_row(
            poller.device.id,
            f"{poller.mapping.manufacturer} {poller.mapping.model}",
            str(poller.device.unit),
            Text(state, style=colour),
            _text(poller.values.get(poller.mapping.status or "")),
            Text(", ".join(alarms) or "-", style="red" if alarms else ""),
            "\n".join(_samples(poller)),
            view.bridge.topics.device(poller.device.id),
        )
    mqtt = Text(f"MQTT {view.bridge.mqtt_state}", style="bold")
    return Group(*(Text(line) for line in view.banner()), mqtt, table)


def render_plain(view: DemoView) -> Iterator[str]:
    """Lines for what changed since the last call (MQTT link, device states)."""
    bridge = view.bridge
    if view._said.get("mqtt") != bridge.mqtt_state:
        view._said["mqtt"] = bridge.mqtt_state
        yield f"MQTT {bridge.mqtt_state} ({view.broker_url})"
    for device_id, poller in bridge.engine.devices.items():
        state = _state(poller)
        if view._said.get(device_id) != state:
            view._said[device_id] = state
            yield (
                f"{device_id}: {state} ({poller.mapping.model}, unit {poller.device.unit}, "
                f"{len(published(poller.points))} values on {bridge.topics.device(device_id)})"
            )
    states = {_state(p) for p in bridge.engine.devices.values()}
    announced = bridge.mqtt_state == "online" and not bridge.discovery.pending
    if "ready" not in view._said and states == {"online"} and announced:
        view._said["ready"] = "yes"
        yield f"ready: {len(bridge.engine.devices)} devices online, publishing to MQTT"


def _state(poller: DevicePoller) -> str:
    online = poller.health.online
    return "starting" if online is None else "online" if online else "offline"


def _samples(poller: DevicePoller) -> list[str]:
    """A few fast-polled numbers with their units."""
    shown = []
    for key in published(poller.points):
        point = poller.points[key]
        value = poller.values.get(key)
        if point.entity.poll_class is not PollClass.FAST or isinstance(value, bool):
            continue
        if isinstance(value, int | float):
            unit = unit_of(point, poller.image) or ""
            shown.append(f"{point.entity.name}: {value:g} {unit}".rstrip())
        if len(shown) == SAMPLES:
            break
    return shown


def _text(value: object) -> str:
    return "-" if value is None else str(value)
