"""Checks of a config beyond its model, as ``path: message`` rows: topics MQTT would
refuse, a password or token file or variable that is not there (or holds no usable
value), TLS files, mapping folders that do not exist; and the error rows themselves (list
indexes replaced by ids, each row once).

They work on whatever validated: ``bridge.config.loading.load_config_data`` runs them on
the whole config, and on the parts that validate on their own when others do not, so that
a file's problems are all reported in one run (``check``) rather than in rounds. The
invariants between sections (references, units) are the model's (``bridge.config.model``).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bridge.config.field import is_register_number
from bridge.config.model import MIN_TOKEN
from bridge.core.checks import wide_keys

if TYPE_CHECKING:
    from bridge.config.model import DeviceConfig, ManagementConfig, WebConfig
    from bridge.config.mqtt import MqttConfig
    from bridge.core.mapping import Mapping

MAX_TOPIC_BYTES = 65535  # MQTT's limit on a topic name
_LONGEST_COMPONENT = "binary_sensor"


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


def web_token_errors(web: WebConfig) -> list[str]:
    if not web.enabled or (web.token_file is None and web.token_env is None):
        return []
    where = "bridge.web.token_file" if web.token_file is not None else "bridge.web.token_env"
    try:
        token = web.token_value() or ""
    except OSError as exc:
        return [f"{where}: cannot read {str(web.token_file)!r}: {exc.strerror}"]
    if len(token) < MIN_TOKEN:
        return [f"{where}: the token is missing or shorter than {MIN_TOKEN} characters"]
    return []


def whole_read_errors(devices: Iterable[DeviceConfig], mappings: dict[str, Mapping]) -> list[str]:
    """A device's ``max_read_registers`` below 4 where its mapping has a 64-bit number
    (read whole, in one request of 4 registers)."""
    errors: list[str] = []
    for device in devices:
        limit, mapping = device.protocol.max_read_registers, mappings.get(device.id)
        wide = wide_keys(mapping.entities) if mapping is not None and limit is not None else []
        if wide and limit is not None and limit < 4:
            errors.append(
                f"devices.{device.id}.protocol.max_read_registers: {limit} would read the "
                f"64-bit {wide[0]} in parts; it is read whole, in one request of 4 registers"
            )
    return errors


def device_password_errors(
    devices: Iterable[DeviceConfig], mappings: dict[str, Mapping]
) -> list[str]:
    """A device password needs a mapping that unlocks with one, a source that holds it,
    and a number the device register takes (0..65535); the value is never shown."""
    errors: list[str] = []
    for device in devices:
        if not device.has_password:
            continue
        where = f"devices.{device.id}"
        field = next(
            name
            for name in ("password", "password_file", "password_env")
            if getattr(device, name) is not None
        )
        mapping = mappings.get(device.id)
        if mapping is not None and mapping.protocol.unlock is None:
            errors.append(f"{where}.{field}: the mapping {device.mapping} has no password unlock")
            continue
        if device.password_file is not None and not device.password_file.is_file():
            errors.append(f"{where}.password_file: no such file {str(device.password_file)!r}")
        elif device.password_env is not None and device.password_env not in os.environ:
            errors.append(
                f"{where}.password_env: environment variable {device.password_env} is not set"
            )
        elif not is_register_number(device.password_value()):
            errors.append(f"{where}.{field}: the password must be a number 0..65535")
    return errors
