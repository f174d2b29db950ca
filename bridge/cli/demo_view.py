"""What the demo shows: a live table (rich) or plain lines, read from the running bridge.

The table fits an 80x24 terminal: a banner of short lines (the commands to try, without
``-h``/``-p`` when the broker is the local default), then one line per device: its id,
state, status label, active alarms and a few values with units, each cut short with an
ellipsis rather than wrapped.
"""

from __future__ import annotations

import shlex
from collections.abc import Iterator
from dataclasses import dataclass, field

from rich import box
from rich.console import Group, RenderableType
from rich.table import Table
from rich.text import Text

from bridge.app import Bridge
from bridge.config import MqttConfig
from bridge.core.codec import Value, unit_of
from bridge.core.entity import PollClass
from bridge.core.state import active_alarms, published
from bridge.modbus.poller import DevicePoller
from bridge.web import page_url

SAMPLES = 2  # values shown per device
DEFAULT_BROKER = ("127.0.0.1", "localhost", "::1")
DEFAULT_PORT = 1883


@dataclass(slots=True)
class DemoView:
    """The bridge being shown and what the plain view has already printed."""

    bridge: Bridge
    broker_url: str
    broker_how: str
    modbus: str = ""
    command: str = "modbus/borehole_pump/start_stop/set"  # the example command's topic
    command_payload: str = "OFF"
    extra: list[str] = field(default_factory=list)  # more banner lines (the demo's own)
    _said: dict[str, str] = field(default_factory=dict)

    def banner(self) -> list[str]:
        base = self.bridge.topics.base
        count = len(self.bridge.engine.devices)
        client = mosquitto_options(self.bridge.mqtt)
        return [
            f"modbus-mqtt-bridge demo: {count} simulated devices, {self.modbus}",
            f"MQTT broker: {self.broker_url} ({self.broker_how})",
            f"web page: {page_url(self.bridge.loaded.config.bridge.web)}",
            f"topics:  {base}/<device> (JSON), {base}/<device>/<key>/set",
            f"watch:   mosquitto_sub{client} -t '{base}/#' -v",
            f"command: mosquitto_pub{client} -t {self.command} -m {self.command_payload}",
            *self.extra,
            "Home Assistant: its MQTT integration on this broker shows the devices.",
        ]


def mosquitto_options(mqtt: MqttConfig) -> str:
    """`` -h HOST -p PORT -u USER -P ...`` for mosquitto_pub/sub; nothing for the local
    default broker without a login. The password is never printed: it is read from where
    the demo read it, or left as a placeholder."""
    parts: list[str] = []
    if mqtt.host not in DEFAULT_BROKER or mqtt.port != DEFAULT_PORT:
        parts += ["-h", mqtt.host, "-p", str(mqtt.port)]
    if mqtt.username is not None:
        parts += ["-u", shlex.quote(mqtt.username)]
    if mqtt.password_env is not None:
        parts += ["-P", f'"${mqtt.password_env}"']
    elif mqtt.password_file is not None:
        parts += ["-P", f'"$(cat {shlex.quote(str(mqtt.password_file))})"']
    elif mqtt.password is not None:
        parts += ["-P", "PASSWORD"]
    return "".join(f" {part}" for part in parts)


def render_table(view: DemoView) -> RenderableType:
    """The banner and one line per device."""
    table = Table(
        box=box.SIMPLE_HEAD, padding=(0, 1, 0, 0), pad_edge=False, show_edge=False, expand=True
    )
    for heading, width in (("device", 15), ("state", 8), ("status", 15)):
        table.add_column(heading, no_wrap=True, width=width)
    table.add_column("alarms", no_wrap=True, ratio=1)
    table.add_column("values", no_wrap=True, ratio=1)
    for poller in view.bridge.engine.devices.values():
        state = _state(poller)
        colour = {"online": "green", "offline": "red"}.get(state, "yellow")
        alarms = active_alarms(poller.points, poller.values)
        cells = (
            (poller.device.id, ""),
            (state, colour),
            (status_label(poller), ""),
            (", ".join(alarms) or "-", "red" if alarms else ""),
            (", ".join(_samples(poller)), ""),
        )
        table.add_row(
            *(Text(text, style, overflow="ellipsis", no_wrap=True) for text, style in cells)
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


def status_label(poller: DevicePoller) -> str:
    """The device's status as a word: the status entity's label, or for a yes/no status
    (the Vacon's "Running") its name, or "not" and its name."""
    key = poller.mapping.status
    value: Value = poller.values.get(key) if key is not None else None
    if key is None or value is None:
        return "-"
    if isinstance(value, bool):
        name = poller.points[key].entity.name.lower()
        return name if value else f"not {name}"
    return str(value)


def _state(poller: DevicePoller) -> str:
    online = poller.health.online
    return "starting" if online is None else "online" if online else "offline"


def _samples(poller: DevicePoller) -> list[str]:
    """A few fast-polled measurements with their units (not raw words, codes or flags)."""
    shown = []
    fast = poller.intervals[PollClass.FAST]
    for key in published(poller.points):
        point = poller.points[key]
        value = poller.values.get(key)
        entity = point.entity
        if poller.state.intervals[key] > fast or entity.ha.state_class != "measurement":
            continue
        if not isinstance(value, int | float) or isinstance(value, bool):
            continue
        shown.append(f"{entity.name} {value:g} {unit_of(point, poller.image) or ''}".rstrip())
        if len(shown) == SAMPLES:
            break
    return shown
