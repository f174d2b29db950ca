"""The ``alarms`` component of a device, its alarm events and device triggers. Pure.

The state document's ``alarms`` lists keys (an alarm bit's key, a fault code's label,
``<key>_<n>`` for a code without a label; see ``state``): what MQTT clients and
automations match. Home Assistant shows the names a person reads instead ("Dry running,
Motor overcurrent"), from a table of names in the template, and keeps the keys in the
attribute ``keys``.

Each raise and clear also goes to ``<base>/<device>/event`` (bridge/core/alarm_events.py):
the ``alarm_events`` event entity lists every ``<alarm>_raised`` / ``<alarm>_cleared`` it
can carry, and each of them is a device trigger too (``type`` raised or cleared,
``subtype`` the alarm's name), so an automation picks "Dry running raised" from a list.
"""

from __future__ import annotations

import json
from collections.abc import Mapping as AnyMapping

from bridge.core.alarm_events import CLEARED, RAISED, event_type, other
from bridge.core.discovery_entity import (
    QOS,
    TEXT_MAX,
    ComponentContext,
    Config,
    base_config,
    object_id,
    shown_name,
)
from bridge.core.entity import Component, Entity, PollClass

ALARM_KEYS_TEMPLATE = "{{ {'keys': value_json.alarms} | tojson }}"
EVENTS_KEY = "alarm_events"
EVENT_TYPE_TEMPLATE = "{{ value_json.event_type }}"


def alarms_config(context: ComponentContext, active: AnyMapping[str, Entity]) -> Config:
    """The ``alarms`` component: the names of the active alarms joined, or ``none``; the
    keys the state document lists are its attribute ``keys`` (for automations)."""
    config = base_config("alarms", "Active alarms", Component.SENSOR, context)
    return config | {
        "enabled_by_default": True,
        "icon": "mdi:alert",
        "state_topic": context.topics.device(context.device_id),
        "value_template": alarms_template(alarm_names(active, context.device_name)),
        "json_attributes_topic": context.topics.device(context.device_id),
        "json_attributes_template": ALARM_KEYS_TEMPLATE,
        "expire_after": context.expire_after(PollClass.FAST),
    }


def alarm_names(active: AnyMapping[str, Entity], device_name: str) -> dict[str, str]:
    """What the state document's ``alarms`` may list, with the name a person reads: an
    alarm bit's key -> the entity's name, a fault code's label -> the label in words."""
    names: dict[str, str] = {}
    for key, entity in active.items():
        if not entity.alarm:
            continue
        if entity.enum is None:
            names[key] = shown_name(entity.name, device_name)
            continue
        for raw, label in entity.enum.items():
            if raw not in entity.normal:
                names[label] = in_words(label)
    return names


def in_words(label: str) -> str:
    """``dc_bus_undervoltage`` -> ``Dc bus undervoltage``."""
    text = label.replace("_", " ")
    return text[:1].upper() + text[1:]


def alarms_template(names: AnyMapping[str, str]) -> str:
    """A template joining the names of the alarms the state document lists (a key it has
    no name for, such as ``fault_code_23`` for a code without a label, in words), at most
    ``TEXT_MAX`` characters, or ``none``."""
    table = json.dumps(dict(names), ensure_ascii=False, separators=(",", ":"))
    each = "{{ n.get(k, k | replace('_', ' ') | capitalize) }}{{ ', ' if not loop.last else '' }}"
    return (
        f"{{% set n = {table} %}}{{% set text %}}{{% for k in value_json.alarms %}}{each}"
        f"{{% endfor %}}{{% endset %}}{{{{ (text or 'none')[:{TEXT_MAX}] }}}}"
    )


def alarm_event_components(context: ComponentContext, active: AnyMapping[str, Entity]) -> Config:
    """The ``alarm_events`` event entity and two device triggers per alarm (raised,
    cleared), all reading ``<base>/<device>/event``; none for a device without alarms."""
    names = alarm_names(active, context.device_name)
    if not names:
        return {}
    for key, entity in active.items():  # codes the mapping has no label for
        if entity.alarm and entity.enum is not None:
            names[other(key)] = f"{shown_name(entity.name, context.device_name)}: other code"
    topic = context.topics.event(context.device_id)
    components: Config = {
        EVENTS_KEY: {
            "platform": "event",
            "unique_id": f"{context.unique_prefix}_{EVENTS_KEY}",
            "default_entity_id": f"event.{object_id(EVENTS_KEY, context)}",
            "name": "Alarm events",
            "qos": QOS,
            "enabled_by_default": True,
            "icon": "mdi:alert-circle-outline",
            "state_topic": topic,
            "event_types": [event_type(a, s) for a in names for s in (RAISED, CLEARED)],
        }
    }
    for alarm, name in names.items():
        for state in (RAISED, CLEARED):
            components[f"{event_type(alarm, state)}_trigger"] = {
                "platform": "device_automation",
                "automation_type": "trigger",
                "topic": topic,
                "value_template": EVENT_TYPE_TEMPLATE,
                "payload": event_type(alarm, state),
                "type": state,
                "subtype": name,
                "qos": QOS,
            }
    return components
