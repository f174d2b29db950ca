"""The state a device publishes: its JSON document, plain values, status and alarms. Pure.

``<base>/<device>`` carries every published value by key (numbers as numbers, enums as
labels, unknown as null), plus ``status`` (the value of the mapping's status entity) and
``alarms`` (the names of the active alarms: the key of each alarm bit that is on, the
label of each fault code that is not normal, ``<key>_<n>`` for a code the mapping has no
label for: an unknown code is still an active fault), and where the device has counters
it starts again by design (state class ``total``), ``last_reset``: when each count began,
as far as the bridge knows (``NEVER_RESET`` until it sees a reset). Secret and write-only
entities are never in it. ``<base>/<device>/<key>`` carries the plain value: JSON for
numbers, booleans and null (``23.5``, ``true``, ``null``), the bare text for labels and text.
"""

from __future__ import annotations

import json
from collections.abc import Mapping as AnyMapping
from typing import Any

from bridge.core.codec import UNKNOWN_CODE, Value, is_unknown_code, unknown_code
from bridge.core.mapping import Mapping, Point

# A total counter's last_reset before the bridge has seen it reset: a fixed moment, so a
# restart never tells Home Assistant that a new count began (it would add it again).
NEVER_RESET = "1970-01-01T00:00:00+00:00"


def published(points: AnyMapping[str, Point]) -> list[str]:
    """Keys whose values go to MQTT: readable and not secret."""
    return [k for k, p in points.items() if p.entity.readable and not p.entity.secret]


def active_alarms(points: AnyMapping[str, Point], values: AnyMapping[str, Value]) -> list[str]:
    """Names of the alarms active in ``values``, in mapping order."""
    names: list[str] = []
    for key, point in points.items():
        if point.entity.alarm and key in values and alarm_active(point, values[key]):
            value = values[key]
            if not isinstance(value, str):
                names.append(key)
            elif is_unknown_code(point.entity, value):
                names.append(f"{key}_{value.removeprefix(UNKNOWN_CODE)}")
            else:
                names.append(value)
    return names


def alarm_active(point: Point, value: Value) -> bool:
    """True when ``value`` of an alarm entity means the alarm is on: a bit that is on, a
    fault code that is not normal."""
    entity = point.entity
    if not entity.alarm:
        return False
    if entity.kind == "bool":
        return value is True
    if entity.enum is not None and isinstance(value, str):
        return value not in {entity.enum.get(raw, unknown_code(raw)) for raw in entity.normal}
    return False


def state_document(
    mapping: Mapping,
    points: AnyMapping[str, Point],
    values: AnyMapping[str, Value],
    last_reset: AnyMapping[str, str] | None = None,
) -> dict[str, Any]:
    """The JSON object published on ``<base>/<device>``."""
    keys = published(points)
    document: dict[str, Any] = {key: values.get(key) for key in keys}
    if mapping.status is not None and mapping.status in points:
        document["status"] = values.get(mapping.status)
    document["alarms"] = active_alarms(points, values)
    resetting = [k for k in keys if points[k].entity.ha.state_class == "total"]
    if resetting:
        last_reset = last_reset or {}
        document["last_reset"] = {k: last_reset.get(k, NEVER_RESET) for k in resetting}
    return document


def compact(document: object) -> str:
    """JSON without the spaces ``json.dumps`` puts after separators (fewer bytes)."""
    return json.dumps(document, separators=(",", ":"))


def plain_payload(value: Value) -> str:
    """The payload of ``<base>/<device>/<key>``."""
    if isinstance(value, str):
        return value
    return json.dumps(value)
