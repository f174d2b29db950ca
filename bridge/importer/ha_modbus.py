"""Home Assistant's ``modbus:`` YAML as a bridge config and one mapping per device.

``import_ha(data, source)`` takes what ``source.load_source`` read: a whole
``configuration.yaml`` (its ``modbus:`` key, and the ``modbus:`` of each package under
``homeassistant: packages:``), a package file, a bare list of hubs or one hub. Each hub
becomes a bus, each (hub, unit) a device with its own mapping; sensors, binary sensors and
switches are converted (``ha_entity``), fans and lights as switches (their entity ids
change platform), climates and covers are noted. Every ``scan_interval`` is kept: the
shortest is the device's ``fast`` poll, the longest its ``slow``, any other the entity's
own ``poll`` in seconds; ``0`` reads once.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from bridge.core.entity import MAX_INTERVAL
from bridge.importer import ha_entity
from bridge.importer.draft import Draft, entity_poll, mapping_document, validated, whole
from bridge.importer.naming import identifier, unique_key
from bridge.importer.result import MAX_ENTITIES, Import, ImportedDevice
from bridge.importer.source import Node, Unresolved, Where

_CONVERTERS: dict[str, Callable[[Node, Import], list[Draft]]] = {
    "sensors": ha_entity.sensor,
    "binary_sensors": ha_entity.binary_sensor,
    "switches": ha_entity.switch,
    "fans": lambda node, result: ha_entity.switch(node, result, "fan"),
    "lights": lambda node, result: ha_entity.switch(node, result, "light"),
}
_NOT_CONVERTED = {
    "climates": "a climate (target and current temperature, HVAC modes) has no mapping "
    "form; map its registers as a sensor and a number by hand",
    "covers": "a cover (open/close states and commands) has no mapping form; map its "
    "register as a select by hand",
}
_HUB_KEYS = frozenset(
    {"name", "type", "host", "port", "timeout", "delay", "message_wait_milliseconds"}
    | {"method", "baudrate", "bytesize", "parity", "stopbits"}
)
_TRANSPORTS = {"tcp": "tcp", "rtuovertcp": "rtu-over-tcp"}
MAX_CONNECT_DELAY = 60  # seconds: a bus's connect_delay, at most
MAX_OFFLINE_AFTER = 100  # a device's offline_after, at most
DEFAULT_HUB = "modbus_hub"


def import_ha(data: Any, source: str) -> Import:
    """Convert every hub found in ``data``; the answer's notes list what was left out."""
    result = Import(source)
    hubs = find_hubs(data, result)
    if not hubs:
        where = data.where if isinstance(data, Node) else Where(source, 1)
        result.note(where, "modbus", "no modbus hub found")
    names: set[str] = set()
    for hub in hubs:
        convert_hub(hub, result, names)
    return result


def find_hubs(data: Any, result: Import) -> list[Node]:
    """The hubs of a configuration, a package file, a list of hubs or one hub."""
    if isinstance(data, list):
        blocks: list[Any] = [data]
    elif isinstance(data, Node) and "type" in data:
        blocks = [data]
    elif isinstance(data, Node):
        blocks = [data["modbus"]] if "modbus" in data else []
        core = data.get("homeassistant")
        packages = core.get("packages") if isinstance(core, Node) else None
        if isinstance(packages, Node):
            blocks += [
                p["modbus"] for p in packages.values() if isinstance(p, Node) and "modbus" in p
            ]
        for value in (core, packages):
            if isinstance(value, Unresolved):
                result.note(value.where, value.tag, value.reason)
    else:
        blocks = []
    hubs: list[Node] = []
    for block in blocks:
        for hub in block if isinstance(block, list) else [block]:
            if isinstance(hub, Node):
                hubs.append(hub)
            elif isinstance(hub, Unresolved):
                result.note(hub.where, f"{hub.tag} {hub.value}", hub.reason)
    return hubs


def convert_hub(hub: Node, result: Import, names: set[str]) -> None:
    """One hub: its bus, and a device per unit its entities address. ``names``: the
    ``<platform>.<name>`` of the entities of the hubs before; Home Assistant loads only the
    first entity of a name on a platform, across hubs, and so does the import."""
    name = str(hub.get("name", DEFAULT_HUB))
    bus = _bus(hub, name, result)
    for key in hub:
        if key not in _HUB_KEYS | set(_CONVERTERS) | set(_NOT_CONVERTED):
            result.note(hub.at(key), f"{name}.{key}", "a key the import does not know")
    units: dict[int, list[Draft]] = {}
    for kind in (*_CONVERTERS, *_NOT_CONVERTED):
        for node in _items(hub, kind, name, result):
            if bus is None:
                entity = str(node.get("name", kind))
                result.note(node.where, entity, f"its hub {name!r} is not converted")
            elif kind in _NOT_CONVERTED:
                result.note(node.where, f"{node.get('name', kind)}", _NOT_CONVERTED[kind])
            elif f"{kind}.{node.get('name')}" in names:
                reason = f"a second {kind[:-1]} of this name: Home Assistant loads the first only"
                result.note(node.where, str(node.get("name")), reason)
            elif result.entities >= MAX_ENTITIES:
                result.note(node.where, kind, f"more than {MAX_ENTITIES} entities: not converted")
            else:
                if kind in ("fans", "lights"):
                    result.note(
                        node.where,
                        str(node.get("name", kind)),
                        f"a {kind[:-1]} becomes a switch (switch.<id>, not {kind[:-1]}.<id>)",
                        partly=True,
                    )
                names.add(f"{kind}.{node.get('name')}")
                drafts = _CONVERTERS[kind](node, result)
                result.entities += len(drafts)
                unit = node.get("slave", node.get("device_address", 0))
                units.setdefault(unit if isinstance(unit, int) else 0, []).extend(drafts)
    if bus is None:
        return
    result.buses.append(bus)
    for unit, drafts in sorted(units.items()):
        _device(hub, bus, unit, drafts, result, single=len(units) == 1)


def _items(hub: Node, kind: str, name: str, result: Import) -> list[Node]:
    value = hub.get(kind)
    if value is None:
        return []
    if isinstance(value, Unresolved):
        result.note(value.where, f"{name}.{kind}", f"{value.tag} {value.value}: {value.reason}")
        return []
    items = value if isinstance(value, list) else [value]
    nodes = []
    for item in items:
        if isinstance(item, Node):
            nodes.append(item)
        else:
            where = item.where if isinstance(item, Unresolved) else hub.at(kind)
            result.note(where, f"{name}.{kind}", "not an entity (key: value)")
    return nodes


def _bus(hub: Node, name: str, result: Import) -> dict[str, Any] | None:
    """The bus of a hub, or None (noted) when the bridge cannot speak it."""
    kind = hub.get("type")
    bus: dict[str, Any] = {"id": identifier(name)}
    timeout = hub.get("timeout", 3)
    if isinstance(timeout, int | float) and not isinstance(timeout, bool) and 0 < timeout <= 60:
        bus["timeout"] = timeout
    elif "timeout" in hub:
        result.note(hub.at("timeout"), f"{name}.timeout", "not 0..60 s: 1 s")
    if kind in _TRANSPORTS:
        host, port = hub.get("host"), hub.get("port", 502)
        if not isinstance(host, str) or not isinstance(port, int):
            result.note(hub.at("host"), f"{name}.host", "needs a host and a port")
            return None
        bus |= {"transport": _TRANSPORTS[kind], "host": host, "tcp_port": port}
    elif kind == "serial":
        serial = _serial(hub, name, result)
        if serial is None:
            return None
        bus |= serial
    else:
        reason = "the bridge has no UDP transport" if kind == "udp" else f"type {kind!r}"
        result.note(hub.at("type"), f"{name}.type", f"{reason}: the hub is not converted")
        return None
    _connect_delay(hub, name, bus, result)
    return bus


def _connect_delay(hub: Node, name: str, bus: dict[str, Any], result: Import) -> None:
    """The hub's ``delay``: seconds of silence after connecting, the bus's connect_delay."""
    delay = hub.get("delay")
    if not delay:
        return
    if isinstance(delay, bool) or not isinstance(delay, int | float) or delay < 0:
        result.note(hub.at("delay"), f"{name}.delay", f"{delay!r} is not seconds")
    elif delay > MAX_CONNECT_DELAY:
        reason = f"{delay} s: the bus waits {MAX_CONNECT_DELAY} s, its longest"
        result.note(hub.at("delay"), f"{name}.delay", reason, partly=True)
        bus["connect_delay"] = MAX_CONNECT_DELAY
    else:
        bus["connect_delay"] = delay


def _offline_after(drafts: list[Draft], result: Import) -> int | None:
    """The device's ``offline_after`` from its entities' ``lazy_error_count`` (failed reads
    Home Assistant lets pass before an entity is unavailable; it is at the next failure):
    the largest count + 1, noted once where the device's entities differ (a missing count
    is Home Assistant's 0)."""
    counts: dict[str, int] = {}
    for draft in drafts:
        count = draft.node.get("lazy_error_count")
        if "lazy_error_count" not in draft.node:
            continue
        if isinstance(count, bool) or not isinstance(count, int) or count < 0:
            where = draft.node.at("lazy_error_count")
            result.note(where, f"{draft.name}.lazy_error_count", f"{count!r} is not a count")
        else:
            counts[draft.name] = min(count, MAX_OFFLINE_AFTER - 1)
            if count >= MAX_OFFLINE_AFTER:
                reason = f"{count}: offline after {MAX_OFFLINE_AFTER} failures, the most"
                where = draft.node.at("lazy_error_count")
                result.note(where, f"{draft.name}.lazy_error_count", reason, partly=True)
    if not counts:
        return None
    most = max(counts.values())
    values = {counts.get(d.name, 0) for d in drafts}
    if len(values) > 1:
        first = next(d for d in drafts if counts.get(d.name) == most)
        reason = (
            f"the device goes offline after {most + 1} failed requests in a row (the largest "
            f"count + 1): its entities' counts differ ({', '.join(map(str, sorted(values)))})"
        )
        where = first.node.at("lazy_error_count")
        result.note(where, f"{first.name}.lazy_error_count", reason, partly=True)
    return most + 1


def _serial(hub: Node, name: str, result: Import) -> dict[str, Any] | None:
    port, method = hub.get("port"), hub.get("method", "rtu")
    size = hub.get("bytesize", 8)
    line = {k: hub.get(k) for k in ("baudrate", "parity", "stopbits")}
    if not isinstance(port, str) or method not in ("rtu", "ascii") or size not in (7, 8):
        result.note(
            hub.at("bytesize" if size not in (7, 8) else "port"),
            f"{name}.type",
            "a serial line needs a port, method rtu/ascii and 7 or 8 data bits: not converted",
        )
        return None
    serial: dict[str, Any] = {"transport": method, "port": port, "bytesize": size}
    return serial | {k: v for k, v in line.items() if v is not None}


def _device(
    hub: Node, bus: dict[str, Any], unit: int, drafts: list[Draft], result: Import, *, single: bool
) -> None:
    """One device and its mapping from the drafts of one unit (``single``: the hub's only
    unit, the device takes the hub's id and name)."""
    name = str(hub.get("name", DEFAULT_HUB))
    device_id = bus["id"] if single else f"{bus['id']}_unit_{unit}"
    fast, slow = _poll(drafts)
    entities: dict[str, Any] = {}
    for draft in drafts:
        fields = _entity(draft, fast, slow, result)
        if fields is not None:
            entities[unique_key(draft.name, entities)] = fields
    entities = whole(entities, drafts, result)
    if not entities:
        reason = "no entity converted: the device is not written"
        result.note(hub.where, f"{name} unit {unit}", reason)
        return
    config: dict[str, Any] = {
        "id": device_id,
        "name": name if single else f"{name} unit {unit}",
        "bus": bus["id"],
        "unit": unit or 1,
        "poll": {"fast": fast or 15, "slow": max(slow, fast or 15)},
    }
    if unit == 0:
        config["enabled"] = False
        result.note(
            hub.where,
            f"{name} unit 0",
            "Home Assistant's default unit 0 (broadcast on a serial line) cannot be "
            "addressed: written as unit 1 and disabled; set the device's unit and enable it",
            partly=True,
        )
    offline_after = _offline_after(drafts, result)
    if offline_after is not None:
        config["offline_after"] = offline_after
    wait = hub.get("message_wait_milliseconds")
    if isinstance(wait, int) and not isinstance(wait, bool) and wait > 0:
        config["protocol"] = {"min_request_interval": wait / 1000}
    description = f"Home Assistant modbus hub {name!r}, unit {unit}, imported"
    mapping = mapping_document(config["name"], description, bus["transport"], entities, result)
    result.devices.append(ImportedDevice(config, mapping))


def _poll(drafts: list[Draft]) -> tuple[int, int]:
    """The device's fast and slow poll: the shortest and the longest scan interval."""
    intervals = sorted({d.scan_interval for d in drafts if d.scan_interval > 0})
    if not intervals:
        return 0, 0
    return intervals[0], intervals[-1]


def _entity(draft: Draft, fast: int, slow: int, result: Import) -> dict[str, Any] | None:
    """The entity's fields with its poll (its scan interval exactly), validated
    (``draft.validated``)."""
    poll = entity_poll(draft.scan_interval, {0: "once", fast: "fast", slow: "slow"})
    if not isinstance(poll, str) and draft.scan_interval > MAX_INTERVAL:
        reason = f"{draft.scan_interval} s: read every 31 days, the longest poll interval"
        where = draft.node.at("scan_interval")
        result.note(where, f"{draft.name}.scan_interval", reason, partly=True)
    return validated(draft, draft.fields | {"poll": poll, "ha": draft.ha}, result)
