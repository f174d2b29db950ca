"""An ESPHome node's ``modbus_controller`` YAML as a bridge config and mappings.

The ``uart``/``modbus`` pair becomes one serial bus (its line settings; the ESP's pins say
nothing of the host's serial port, so the port is a placeholder, reported), each
``modbus_controller`` a device (``address`` its unit, ``update_interval`` its poll,
``command_throttle`` the gap between requests), and each ``sensor``, ``binary_sensor``,
``switch``, ``number``, ``select`` and ``text_sensor`` of ``platform: modbus_controller``
an entity (``esphome_entity``). ``substitutions`` are applied to text values first.
"""

from __future__ import annotations

import re
from typing import Any

from bridge.core.duration import parse_duration
from bridge.importer import esphome_entity
from bridge.importer.draft import Draft, entity_poll, mapping_document, validated, whole
from bridge.importer.naming import identifier, unique_key
from bridge.importer.result import MAX_ENTITIES, Import, ImportedDevice
from bridge.importer.source import Node, Where

PLATFORMS = ("sensor", "binary_sensor", "switch", "number", "select", "text_sensor")
_PARITY = {"NONE": "N", "EVEN": "E", "ODD": "O"}
_SUBSTITUTION = re.compile(r"\$\{(\w+)\}|\$(\w+)")

# Entities written inside a modbus_controller: ESPHome's own schema for it
# (esphome/components/modbus_controller/__init__.py, CONFIG_SCHEMA) has no such key and
# refuses the node; only the fork it came from (martgras' modbus_controller) nested them.
_INLINE = frozenset(f"{platform}{plural}" for platform in PLATFORMS for plural in ("", "s"))
_INLINE_REASON = (
    "entities inside a modbus_controller: ESPHome refuses them there (its schema has no such "
    "key); give each its own `- platform: modbus_controller` under sensor:, switch:, ... with "
    "modbus_controller_id, and import again"
)


def import_esphome(data: Any, source: str) -> Import:
    """Convert the node's modbus controllers; the notes list what was left out."""
    result = Import(source)
    if not isinstance(data, Node):
        result.note(Where(source, 1), "modbus_controller", "not an ESPHome node (key: value)")
        return result
    data = _substituted(data, data.get("substitutions"))
    controllers = _controllers(data, result)
    if not controllers:
        result.note(data.where, "modbus_controller", "no modbus_controller found")
        return result
    node_name = _node_name(data)
    bus = _bus(data, node_name, result)
    result.buses.append(bus)
    drafts: dict[str, list[Draft]] = {str(c.get("id", "")): [] for c in controllers}
    first = next(iter(drafts))
    for platform in PLATFORMS:
        for item in _list(data.get(platform)):
            if not isinstance(item, Node) or item.get("platform") != "modbus_controller":
                continue
            owner = str(item.get("modbus_controller_id", first))
            if owner not in drafts:
                result.note(item.at("modbus_controller_id"), owner, "no such modbus_controller")
            elif result.entities >= MAX_ENTITIES:
                result.note(item.where, platform, f"more than {MAX_ENTITIES} entities")
            else:
                made = esphome_entity.convert(platform, item, result, node_name)
                result.entities += len(made)
                drafts[owner].extend(made)
    for controller in controllers:
        _device(controller, bus, drafts[str(controller.get("id", ""))], result, node_name)
    return result


def _controllers(data: Node, result: Import) -> list[Node]:
    """The node's modbus controllers that are clients (a server role is noted)."""
    servers = {
        str(m.get("id"))
        for m in _list(data.get("modbus"))
        if isinstance(m, Node) and m.get("role") == "server"
    }
    controllers = []
    for controller in _list(data.get("modbus_controller")):
        if not isinstance(controller, Node):
            continue
        if str(controller.get("modbus_id")) in servers:
            reason = "a Modbus server on the ESP (the bridge is a client of devices)"
            result.note(controller.where, str(controller.get("id", "modbus_controller")), reason)
        else:
            controllers.append(controller)
    return controllers


def _list(value: Any) -> list[Any]:
    if value is None:
        return []
    return value if isinstance(value, list) else [value]


def _node_name(data: Node) -> str:
    esphome = data.get("esphome")
    if isinstance(esphome, Node):
        name = esphome.get("friendly_name") or esphome.get("name")
        if isinstance(name, str):
            return name
    return "esphome"


def _substituted(value: Any, substitutions: Any) -> Any:
    """``value`` with ``${name}``/``$name`` replaced in every text (one pass, no nesting)."""
    if not isinstance(substitutions, dict) or not substitutions:
        return value
    table = {str(k): str(v) for k, v in substitutions.items()}
    return _replace(value, table)


def _replace(value: Any, table: dict[str, str]) -> Any:
    if isinstance(value, str):
        return _SUBSTITUTION.sub(lambda m: table.get(m[1] or m[2], m[0]), value)
    if isinstance(value, list):
        return [_replace(v, table) for v in value]
    if isinstance(value, Node):
        copy = Node({k: _replace(v, table) for k, v in value.items()})
        copy.where, copy.places = value.where, value.places
        return copy
    return value


def _bus(data: Node, node_name: str, result: Import) -> dict[str, Any]:
    """The serial bus of the node's uart (the first), with a placeholder port."""
    uarts = [u for u in _list(data.get("uart")) if isinstance(u, Node)]
    uart = uarts[0] if uarts else None
    bus: dict[str, Any] = {"id": identifier(node_name), "transport": "rtu"}
    bus["port"] = "/dev/ttyUSB0"
    where = uart.where if uart is not None else data.where
    result.note(
        where,
        "uart",
        "the ESP's pins are not a serial port here: the bus's port is "
        "/dev/ttyUSB0, set the RS485 adapter you use",
        partly=True,
    )
    _modbus_timing(data, bus, result)
    if uart is None:
        return bus
    for key in uart:
        if key not in ("id", "tx_pin", "rx_pin", "baud_rate", "parity", "stop_bits", "data_bits"):
            result.note(uart.at(key), f"uart.{key}", "an ESP option the bridge has not")
    baud, parity = uart.get("baud_rate"), _PARITY.get(str(uart.get("parity", "NONE")))
    stop, size = uart.get("stop_bits", 1), uart.get("data_bits", 8)
    if isinstance(baud, int) and 300 <= baud <= 921600:
        bus["baudrate"] = baud
    if parity is not None:
        bus["parity"] = parity
    if stop in (1, 2):
        bus["stopbits"] = stop
    if size in (7, 8):
        bus["bytesize"] = size
    else:
        result.note(uart.at("data_bits"), "uart.data_bits", "the bridge speaks 7 or 8 data bits")
    return bus


def _modbus_timing(data: Node, bus: dict[str, Any], result: Import) -> None:
    """The ``modbus`` hub's ``send_wait_time`` (the wait for an answer) as the timeout."""
    hubs = [
        m for m in _list(data.get("modbus")) if isinstance(m, Node) and m.get("role") != "server"
    ]
    for hub in hubs[:1]:
        wait = _seconds(hub.get("send_wait_time", "250ms"))
        if wait is not None and 0 < wait <= 60:
            bus["timeout"] = wait
        for key in hub:
            if key not in ("id", "uart_id", "send_wait_time", "role"):
                reason = "the host's RS485 adapter turns the line itself"
                result.note(
                    hub.at(key),
                    f"modbus.{key}",
                    reason if key == "flow_control_pin" else "an ESP option the bridge has not",
                )
    for hub in hubs[1:]:
        result.note(
            hub.where,
            f"modbus {hub.get('id')}",
            "one bus per node is imported: its devices join the first",
        )


def _device(
    controller: Node, bus: dict[str, Any], drafts: list[Draft], result: Import, node_name: str
) -> None:
    """One controller: a device of the bus and its mapping."""
    name = str(controller.get("id", node_name))
    unit = controller.get("address", 1)
    if not isinstance(unit, int) or not 1 <= unit <= 247:
        result.note(controller.at("address"), f"{name}.address", "not a unit 1..247")
        return
    interval = _seconds(controller.get("update_interval", "60s")) or 60.0
    skips = [d.scan_interval for d in drafts if d.scan_interval]
    named = {max(skips, default=0) + 1: "slow", 1: "fast"}  # updates from one read to the next
    entities: dict[str, Any] = {}
    for draft in drafts:
        draft.fields.pop("skip_updates", None)
        updates = draft.scan_interval + 1  # skip_updates + 1: every n-th update exactly
        poll = named.get(updates) or entity_poll(interval * updates, {})
        checked = validated(draft, draft.fields | {"poll": poll, "ha": draft.ha}, result)
        if checked is not None:
            entities[unique_key(draft.name, entities)] = checked
    config: dict[str, Any] = {
        "id": identifier(name),
        "name": name.replace("_", " ").capitalize(),
        "bus": bus["id"],
        "unit": unit,
        "poll": {"fast": interval, "slow": interval * (max(skips, default=0) + 1)},
    }
    throttle = _seconds(controller.get("command_throttle", 0))
    if throttle:
        config["protocol"] = {"min_request_interval": throttle}
    for key in controller:
        if key in _INLINE:
            result.note(controller.at(key), f"{name}.{key}", _INLINE_REASON)
        elif key not in ("id", "address", "modbus_id", "update_interval", "command_throttle"):
            result.note(controller.at(key), f"{name}.{key}", "not kept by the bridge")
    entities = whole(entities, drafts, result)
    if not entities:
        result.note(controller.where, name, "no entity converted: the device is not written")
        return
    description = f"ESPHome modbus_controller {name!r} of {node_name!r}, imported"
    mapping = mapping_document(config["name"], description, "rtu", entities, result)
    result.devices.append(ImportedDevice(config, mapping))


def _seconds(value: Any) -> float | None:
    try:
        return parse_duration(value)
    except (ValueError, TypeError):
        return None
