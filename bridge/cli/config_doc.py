"""docs/config.md, generated from the config file's JSON Schema so that it cannot drift.

``render_config_doc()`` walks ``config_schema()``: one Markdown table per section (field,
type, default, description), the two kinds of bus told apart by ``transport``, plus a
short hand-written introduction and a complete example (``EXAMPLE``, validated by
tests/test_docs.py). Durations are plain numbers in the schema; they are recognised from
the pydantic models, which carry the ``Duration`` parser. A field without a description
in the schema takes one from ``NOTES``; a note for a field the schema no longer has is an
error, so a renamed field cannot leave a stale line behind.

Regenerate with ``modbus-mqtt-bridge schema --markdown > docs/config.md`` (``make docs``).
"""

from __future__ import annotations

import json
import types
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel

from bridge.config import Config, config_schema
from bridge.core.duration import parse_duration

Schema = dict[str, Any]

REGENERATE = "modbus-mqtt-bridge schema --markdown > docs/config.md"

# Descriptions for fields whose model gives none, keyed "<model>.<field>".
NOTES: dict[str, str] = {
    "Config.mqtt": "the MQTT broker and topics",
    "Config.bridge": "the management side: health reports, raw writes, scans, metrics",
    "Config.buses": "the serial lines and TCP gateways the bridge owns",
    "Config.devices": "the Modbus devices, each on one bus with one mapping",
    "MqttConfig.url": "broker: `mqtt://[user[:password]@]host[:port]` or `mqtts://...` (TLS); "
    "a user and password in the URL log in and are never shown; a list of URLs: the nodes of a "
    "cluster, the next one tried after a failure (docs/brokers.md)",
    "MqttConfig.base_topic": "first level of every topic: `<base>/<device>/...`",
    "MqttConfig.discovery_prefix": "Home Assistant's discovery prefix",
    "MqttConfig.client_id": "MQTT client id (default: generated)",
    "MqttConfig.username": "user name for the broker",
    "MqttConfig.password": "password written in the file (prefer password_file or password_env)",
    "MqttConfig.password_file": "file holding the password (Docker/systemd secrets)",
    "MqttConfig.password_env": "environment variable holding the password",
    "MqttConfig.tls": "TLS settings for `mqtts://` URLs",
    "MqttConfig.keepalive": "MQTT keepalive",
    "MqttConfig.qos": "QoS of published messages (the bridge subscribes at QoS 0: docs/brokers.md)",
    "TlsConfig.ca": "CA bundle that signed the broker's certificate",
    "TlsConfig.cert": "client certificate (mutual TLS)",
    "TlsConfig.key": "private key of the client certificate",
    "ManagementConfig.metrics": "the optional Prometheus endpoint",
    "MetricsConfig.enabled": "serve Prometheus metrics over HTTP (`/metrics`)",
    "MetricsConfig.port": "TCP port of the metrics endpoint",
    "ManagementConfig.web": "the optional web page: devices, values, health, commissioning",
    "WebConfig.enabled": "serve the web page (README: The web page)",
    "WebConfig.port": "TCP port of the web page",
    "WebConfig.token": "token the page asks for (at least 16 characters; prefer token_file)",
    "WebConfig.token_file": "file holding the token (Docker/systemd secrets)",
    "WebConfig.token_env": "environment variable holding the token",
    "SerialBus.id": "name of the bus, used by devices[].bus",
    "SerialBus.transport": "Modbus RTU or Modbus ASCII on a serial line",
    "SerialBus.baudrate": "line speed in bit/s, as set on the devices",
    "SerialBus.parity": "N (none), E (even), O (odd)",
    "SerialBus.stopbits": "1 or 2",
    "SerialBus.bytesize": "data bits: 8 for RTU, often 7 for ASCII",
    "TcpBus.id": "name of the bus, used by devices[].bus",
    "TcpBus.transport": "Modbus TCP, or RTU frames through a serial gateway (`rtu-over-tcp`)",
    "TcpBus.host": "address of the device or gateway",
    "TcpBus.tcp_port": "TCP port of the device or gateway",
    "SerialLine.baudrate": "line speed in bit/s of the RS485 side, as set on the gateway",
    "SerialLine.parity": "N (none), E (even), O (odd)",
    "SerialLine.stopbits": "1 or 2",
    "SerialLine.bytesize": "data bits",
    "DeviceConfig.id": "stable id: the MQTT topic `<base>/<id>` and Home Assistant ids",
    "DeviceConfig.name": "name shown in Home Assistant (default: from the id)",
    "DeviceConfig.bus": "id of the bus the device is on",
    "DeviceConfig.poll": "poll intervals: the mapping's fast and slow values, and per entity",
    "DeviceConfig.options": "model options the mapping declares (`mappings show` lists them)",
    "DeviceConfig.protocol": "what this unit allows beyond the mapping's protocol rules",
    "DeviceConfig.enabled": "false: keep the device in the file but do not poll it",
    "PollConfig.fast": "interval of fast values (measurements, status)",
    "PollConfig.slow": "interval of slow values (settings); `once` values retry at this pace",
    "ProtocolOverride.max_read_registers": "registers per read (the mapping's when unset)",
    "ProtocolOverride.max_read_bits": "coils/inputs per read (the mapping's when unset)",
    "ProtocolOverride.coil_on_value": "FC05 ON word (the mapping's when unset)",
    "ProtocolOverride.min_request_interval": "silence between two requests to this unit",
    "ProtocolOverride.response_timeout": "answer timeout for this unit (else the bus timeout)",
}

INTRO = """\
# Config file reference

<!-- Generated by `modbus-mqtt-bridge schema --markdown` from bridge/config/.
     Do not edit by hand: change the models (or bridge/cli/config_doc.py) and regenerate. -->

The config file is YAML with four sections: `mqtt` (the broker), `bridge` (the
management side), `buses` (serial lines and TCP gateways) and `devices` (what is on
them). Only `buses` is required. Check a file without starting anything:

    modbus-mqtt-bridge check -c config.yaml

A bad file is refused whole, with one `path: message` line per problem
(`devices.borehole_pump.unit: Input should be greater than or equal to 1`); nothing is
started. `modbus-mqtt-bridge schema config` prints the JSON Schema for editor completion.

Rules the tables below do not show:

- **Durations** accept `500ms`, `2s`, `1.5m`, `1h` or a number of seconds.
- **Ids** of buses and devices are lowercase letters, digits, `_` and `-`; `bridge` is
  reserved. A device id is its MQTT topic (`<base_topic>/<id>`): keep it stable.
- A **unit** id is 1..247 on a serial line (1..255 over TCP) and unique per bus among
  enabled devices.
- A device's `mapping` is a shipped mapping name (`modbus-mqtt-bridge mappings list`)
  or a path to a YAML file, relative to the config file's folder; its `options` must be
  options that mapping declares, with one of their choices.
- **Secrets**: give at most one of `password`, `password_file`, `password_env`; the
  password is never logged or published. `tls` needs an `mqtts://` URL. Likewise one of
  `token`, `token_file`, `token_env` for the web page, which needs one when its `host`
  is not a loopback address (unless only Home Assistant's ingress proxy may open it).
- Files the config names (`password_file`, `token_file`, `tls.ca`/`cert`/`key`) may be
  relative to the config file's folder, like mapping paths; `check` says when one is
  missing.
- A mapping that does not list `ascii` in its transports cannot be put on an `ascii` bus.
- **Raw reads and writes** keep the guards of every device that may answer the unit they
  name: on a serial line, the device configured at that unit; on a TCP bus (a gateway, or
  a device that ignores the unit id), the device configured at that unit, and for unit
  255 or a unit no device is configured at, every device on the bus. On a TCP bus a raw
  write to a unit no device is configured at is refused unless the bus's `raw_units`
  names it.
"""

EXAMPLE = """\
mqtt:
  url: mqtts://broker.example.net:8883
  base_topic: modbus
  discovery_prefix: homeassistant
  username: bridge
  password_env: MQTT_PASSWORD
  tls: {ca: /etc/ssl/certs/ca-certificates.crt}
  command_expiry: 5s
bridge:
  health_interval: 60s
  allow_raw_writes: false
  metrics: {enabled: true, host: 0.0.0.0, port: 9464}
  web: {enabled: true, host: 0.0.0.0, port: 8099, token_env: BRIDGE_WEB_TOKEN}
buses:
  - id: rs485
    transport: rtu
    port: /dev/ttyUSB0
    baudrate: 9600
    parity: N
    stopbits: 2
    timeout: 500ms
  - id: gateway
    transport: rtu-over-tcp
    host: 192.0.2.10
    tcp_port: 502
    timeout: 1s
    retries: 1
devices:
  - id: borehole_pump
    name: Borehole pump
    bus: rs485
    unit: 1
    mapping: nastec_vasco
    poll: {fast: 2s, slow: 60s}
    options: {register_9f: pcb_temperature}
  - id: genset
    name: Standby genset
    bus: gateway
    unit: 5
    mapping: smartgen_hgm6100
    options: {model: hgm6120}
    protocol: {min_request_interval: 1s}
    allow_dangerous_writes: false
  - id: oven
    name: Oven
    bus: rs485
    unit: 3
    mapping: examples/mappings/temperature_controller.yaml
    options: {model: tc4c}
    enabled: false
"""


@dataclass(frozen=True, slots=True)
class Section:
    """One table of the document: a heading, its anchor, the object schema it lists."""

    anchor: str
    heading: str
    model: str
    schema: Schema
    lead: str = ""


def render_config_doc() -> str:
    """The whole of docs/config.md."""
    schema = config_schema()
    durations = duration_fields(Config)
    used: set[str] = set()
    parts = [INTRO, "## Complete example\n", "```yaml\n" + EXAMPLE + "```\n"]
    for section in _sections(schema):
        parts.append(_render_section(section, schema, durations, used))
    stale = sorted(set(NOTES) - used)
    if stale:
        raise ValueError(f"NOTES name fields the config no longer has: {', '.join(stale)}")
    return "\n".join(parts)


def _sections(schema: Schema) -> Iterator[Section]:
    defs: dict[str, Schema] = schema["$defs"]
    yield Section("top-level", "Top level", "Config", schema)
    yield Section("mqtt", "`mqtt`", "MqttConfig", defs["MqttConfig"])
    yield Section("mqtt-tls", "`mqtt.tls`", "TlsConfig", defs["TlsConfig"])
    yield Section("bridge", "`bridge`", "ManagementConfig", defs["ManagementConfig"])
    yield Section("bridge-metrics", "`bridge.metrics`", "MetricsConfig", defs["MetricsConfig"])
    yield Section("bridge-web", "`bridge.web`", "WebConfig", defs["WebConfig"])
    yield Section("bridge-gateway", "`bridge.gateway`", "GatewayConfig", defs["GatewayConfig"])
    yield Section(
        "bridge-gateway-units",
        "`bridge.gateway.units` (a bus and unit)",
        "GatewayUnit",
        defs["GatewayUnit"],
    )
    for name, title, anchor in _bus_kinds(schema):
        transports = " or ".join(f"`{t}`" for t in defs[name]["properties"]["transport"]["enum"])
        lead = f"A bus whose `transport` is {transports}."
        yield Section(anchor, f"`buses[]`: {title}", name, defs[name], lead)
    yield Section(
        "buses-serial-behind",
        "`buses[].serial_behind`",
        "SerialLine",
        defs["SerialLine"],
        "The RS485 line behind a Modbus TCP gateway or serial server, for planning reads.",
    )
    yield Section("devices", "`devices[]`", "DeviceConfig", defs["DeviceConfig"])
    yield Section("devices-poll", "`devices[].poll`", "PollConfig", defs["PollConfig"])
    yield Section(
        "devices-protocol", "`devices[].protocol`", "ProtocolOverride", defs["ProtocolOverride"]
    )
    yield Section(
        "devices-sunspec",
        "`devices[].sunspec`",
        "SunSpecConfig",
        defs["SunSpecConfig"],
        "Only with `mapping: sunspec` (see the README, SunSpec devices).",
    )


def _bus_kinds(schema: Schema) -> list[tuple[str, str, str]]:
    """(model, title, anchor) per kind of bus, from the discriminated union of ``buses``."""
    items = schema["properties"]["buses"]["items"]
    kinds = []
    for choice in items["oneOf"]:
        name = _ref_name(choice["$ref"])
        serial = name == "SerialBus"
        kinds.append((name, "serial line" if serial else "TCP", _bus_anchor(name)))
    return kinds


def _bus_anchor(model: str) -> str:
    return "buses-serial" if model == "SerialBus" else "buses-tcp"


def _render_section(
    section: Section, root: Schema, durations: dict[str, set[str]], used: set[str]
) -> str:
    lines = [f'<a id="{section.anchor}"></a>', "", f"## {section.heading}", ""]
    intro = section.lead or _markdown(section.schema.get("description", ""))
    if intro and section.model != "Config":
        lines += [intro, ""]
    lines += ["| field | type | default | description |", "|---|---|---|---|"]
    required = set(section.schema.get("required", ()))
    for field, prop in section.schema["properties"].items():
        is_duration = field in durations.get(section.model, set())
        kind = _type_of(prop, root, is_duration)
        default = _default_of(prop, field in required, is_duration)
        note_key = f"{section.model}.{field}"
        description = prop.get("description") or NOTES.get(note_key, "")
        if note_key in NOTES:
            used.add(note_key)
        cells = (f"`{field}`", kind, default, _markdown(description))
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return "\n".join(lines) + "\n"


def _type_of(prop: Schema, root: Schema, is_duration: bool) -> str:
    """A short, readable type: ``integer (1..255)``, `` `rtu` | `ascii` ``, a link."""
    choices = [p for p in prop.get("anyOf", [prop]) if p.get("type") != "null"]
    if len(choices) > 1:  # a value or a list of them (mqtt.url)
        return " or ".join(_type_of(c, root, is_duration=False) for c in choices)
    if len(choices) == 1:
        prop = {**prop, **choices[0]}
    if is_duration:
        return "duration"
    if "$ref" in prop:
        return f"object, see [{_ref_title(prop['$ref'])}](#{_ref_anchor(prop['$ref'])})"
    if "enum" in prop:
        return " \\| ".join(f"`{_yaml_scalar(v)}`" for v in prop["enum"])
    kind = prop.get("type", "any")
    if kind == "array":
        return _array_type(prop["items"], root)
    if kind == "object":
        values = prop.get("additionalProperties", {}).get("type", "any")
        return f"map of name to {values}"
    if prop.get("format") == "password":
        return "string (secret)"
    if prop.get("format") == "path":
        return "path"
    if "minimum" in prop or "maximum" in prop:
        return f"{kind} ({prop.get('minimum', '')}..{prop.get('maximum', '')})"
    return str(kind)


def _array_type(items: Schema, root: Schema) -> str:
    if "oneOf" in items:
        kinds = _bus_kinds(root)
        links = " or ".join(f"[{title}](#{anchor})" for _, title, anchor in kinds)
        return f"list of buses: {links}"
    if "$ref" in items:
        return f"list, see [{_ref_title(items['$ref'])}](#{_ref_anchor(items['$ref'])})"
    kind = items.get("type", "any")
    if "minimum" in items or "maximum" in items:
        return f"list of {kind} ({items.get('minimum', '')}..{items.get('maximum', '')})"
    return f"list of {kind}"


_ANCHORS = {
    "MqttConfig": ("mqtt", "mqtt"),
    "TlsConfig": ("mqtt.tls", "mqtt-tls"),
    "ManagementConfig": ("bridge", "bridge"),
    "MetricsConfig": ("bridge.metrics", "bridge-metrics"),
    "WebConfig": ("bridge.web", "bridge-web"),
    "GatewayConfig": ("bridge.gateway", "bridge-gateway"),
    "GatewayUnit": ("bridge.gateway.units", "bridge-gateway-units"),
    "SerialLine": ("buses[].serial_behind", "buses-serial-behind"),
    "DeviceConfig": ("devices[]", "devices"),
    "PollConfig": ("devices[].poll", "devices-poll"),
    "ProtocolOverride": ("devices[].protocol", "devices-protocol"),
    "SunSpecConfig": ("devices[].sunspec", "devices-sunspec"),
}


def _ref_name(ref: str) -> str:
    return ref.rsplit("/", 1)[-1]


def _ref_title(ref: str) -> str:
    return _ANCHORS[_ref_name(ref)][0]


def _ref_anchor(ref: str) -> str:
    return _ANCHORS[_ref_name(ref)][1]


def _default_of(prop: Schema, required: bool, is_duration: bool) -> str:
    if required:
        return "**required**"
    if "default" not in prop:
        return "`[]`" if prop.get("type") == "array" else "`{}`"
    value = prop["default"]
    if value is None:
        return "none"
    if isinstance(value, dict):
        return "see its section"
    if is_duration and isinstance(value, int | float):
        return f"`{value:g}s`"
    return f"`{_yaml_scalar(value)}`"


def _yaml_scalar(value: object) -> str:
    """How a value is written in YAML: strings that would read as numbers are quoted."""
    if isinstance(value, bool | int | float) or value is None:
        return json.dumps(value)
    text = str(value)
    try:
        float(text)
    except ValueError:
        return text
    return f'"{text}"'


def _markdown(text: str) -> str:
    """Docstring markup (``code``) to Markdown (`code`) on one line; ``<`` and ``>``
    outside code spans escaped so that ``<base>`` is not read as an HTML tag."""
    parts = " ".join(text.replace("``", "`").split()).split("`")
    for index in range(0, len(parts), 2):
        parts[index] = parts[index].replace("<", "&lt;").replace(">", "&gt;")
    return "`".join(parts)


def _cell(text: str) -> str:
    """A table cell: pipes escaped unless already escaped."""
    return text.replace(" | ", " \\| ") if "\\|" not in text else text


# --- durations: recognised from the models, since the schema says only "number" -------


def duration_fields(model: type[BaseModel]) -> dict[str, set[str]]:
    """Fields parsed as durations, by model name, for ``model`` and every nested model."""
    found: dict[str, set[str]] = {}
    pending: list[type[BaseModel]] = [model]
    while pending:
        current = pending.pop()
        if current.__name__ in found:
            continue
        found[current.__name__] = set()
        for name, info in current.model_fields.items():
            if _is_duration(info.metadata) or _mentions_duration(info.annotation):
                found[current.__name__].add(name)
            pending.extend(_nested_models(info.annotation))
    return found


def _is_duration(metadata: list[Any]) -> bool:
    return any(getattr(item, "func", None) is parse_duration for item in metadata)


def _mentions_duration(annotation: object) -> bool:
    if typing.get_origin(annotation) is typing.Annotated:
        return _is_duration(list(getattr(annotation, "__metadata__", ())))
    return any(_mentions_duration(arg) for arg in typing.get_args(annotation))


def _nested_models(annotation: object) -> list[type[BaseModel]]:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    if isinstance(annotation, types.GenericAlias | types.UnionType) or typing.get_args(annotation):
        return [m for arg in typing.get_args(annotation) for m in _nested_models(arg)]
    return []
