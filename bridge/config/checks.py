"""Checks of a config beyond its fields, as ``path: message`` rows: references between
sections (a device's bus, units shared on a bus, ids used twice, a gateway line given
twice), topics MQTT would refuse,
a password file or variable that is not there, mapping folders that do not exist.

They work on whatever validated: ``bridge.config.model.load_config_data`` runs them on the whole
config, and on the parts that validate on their own when others do not, so that a file's
problems are all reported in one run (``check``) rather than in rounds.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Collection, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from bridge.config.model import DeviceConfig, ManagementConfig, MqttConfig, SerialBus, TcpBus
    from bridge.core.mapping import Mapping

MAX_TOPIC_BYTES = 65535  # MQTT's limit on a topic name
MAX_SERIAL_UNIT = 247
_LONGEST_COMPONENT = "binary_sensor"


def reference_errors(
    buses: Sequence[SerialBus | TcpBus],
    devices: Sequence[DeviceConfig],
    invalid_buses: Collection[str] = (),
) -> list[str]:
    """Ids used twice, a device on a bus that does not exist, a unit a serial line cannot
    address, two enabled devices at one unit of a bus. ``invalid_buses``: ids of buses that
    exist in the file but did not validate (their devices are not checked against them)."""
    errors = duplicates("buses", [bus.id for bus in buses])
    errors += duplicates("devices", [device.id for device in devices])
    known = {bus.id: bus for bus in buses}
    units: dict[tuple[str, int], str] = {}
    for device in devices:
        where = f"devices.{device.id}"
        bus = known.get(device.bus)
        if bus is None:
            if device.bus not in invalid_buses:
                errors.append(f"{where}.bus: no bus {device.bus!r} (have {sorted(known)})")
            continue
        if bus.transport in ("rtu", "ascii") and device.unit > MAX_SERIAL_UNIT:
            errors.append(f"{where}.unit: serial lines address units 1..{MAX_SERIAL_UNIT}")
        if not device.enabled:
            continue
        other = units.setdefault((device.bus, device.unit), device.id)
        if other != device.id:
            errors.append(f"{where}.unit: unit {device.unit} is also {other!r} on {bus.id}")
    return errors + shared_gateway_errors(buses)


def shared_gateway_errors(buses: Iterable[SerialBus | TcpBus]) -> list[str]:
    """A gateway's serial line carries one frame at a time: one bus per gateway port."""
    seen: dict[tuple[str, int], str] = {}
    errors = []
    for bus in buses:
        if getattr(bus, "serial_behind", None) is None:
            continue
        host, port = getattr(bus, "host", ""), getattr(bus, "tcp_port", 0)
        other = seen.setdefault((host, port), bus.id)
        if other != bus.id:
            errors.append(
                f"buses.{bus.id}.host: {host}:{port} is bus {other!r} too; "
                "one serial line carries one frame at a time, so give its devices one bus"
            )
    return errors


def duplicates(section: str, ids: list[str]) -> list[str]:
    counts = Counter(ids)
    return [f"{section}.{i}: id used {n} times" for i, n in counts.items() if n > 1]


def topic_errors(
    mqtt: MqttConfig, devices: Iterable[DeviceConfig], mappings: dict[str, Mapping]
) -> list[str]:
    """Devices whose longest topic (a discovery config or a command) would exceed MQTT's
    limit, so that the broker would refuse it at run time."""
    errors = []
    for device in devices:
        mapping = mappings.get(device.id)
        if mapping is None:
            continue
        key = max(mapping.entities, key=len, default="")
        longest = max(
            f"{mqtt.base_topic}/{device.id}/{key}/set",
            f"{mqtt.discovery_prefix}/{_LONGEST_COMPONENT}/{device.id}/{key}/config",
            key=lambda topic: len(topic.encode("utf-8")),
        )
        size = len(longest.encode("utf-8"))
        if size > MAX_TOPIC_BYTES:
            errors.append(
                f"devices.{device.id}.id: its topics would be {size} bytes, over MQTT's "
                f"{MAX_TOPIC_BYTES}; shorten the id or the mapping's keys"
            )
    return errors


def folder_errors(bridge: ManagementConfig, base: Path) -> list[str]:
    return [
        f"bridge.mapping_dirs: no such folder {str(folder)!r}"
        for folder in bridge.mapping_dirs
        if not (base / folder).is_dir()
    ]


def secret_errors(mqtt: MqttConfig) -> list[str]:
    """The broker password's file or variable, and the TLS files, are there."""
    errors = []
    if mqtt.password_file is not None and not mqtt.password_file.is_file():
        errors.append(f"mqtt.password_file: no such file {str(mqtt.password_file)!r}")
    if mqtt.password_env is not None and mqtt.password_env not in os.environ:
        errors.append(f"mqtt.password_env: environment variable {mqtt.password_env} is not set")
    tls = mqtt.tls
    if tls is None:
        return errors
    files = (("ca", tls.ca), ("cert", tls.cert), ("key", tls.key))
    errors += [
        f"mqtt.tls.{name}: no such file {str(path)!r}"
        for name, path in files
        if path is not None and not path.is_file()
    ]
    if tls.key is not None and tls.cert is None:
        errors.append("mqtt.tls.key: a key goes with its certificate (mqtt.tls.cert)")
    return errors


def with_ids(rows: Iterable[str], data: dict[str, Any]) -> list[str]:
    """Replace list indexes by ids: ``devices.0.unit`` -> ``devices.borehole_pump.unit``."""
    result = []
    for row in rows:
        location, sep, message = row.partition(": ")
        parts = location.split(".")
        items = data.get(parts[0])
        if len(parts) > 1 and parts[1].isdigit() and isinstance(items, list):
            index = int(parts[1])
            item = items[index] if index < len(items) else None
            if isinstance(item, dict) and isinstance(item.get("id"), str) and item["id"]:
                parts[1] = item["id"]
        result.append(".".join(parts) + sep + message)
    return result


def unique(rows: Iterable[str]) -> list[str]:
    """Rows in their order, each once."""
    return list(dict.fromkeys(rows))
