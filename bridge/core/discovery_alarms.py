"""The ``alarms`` component of a device: the active alarms by name. Pure.

The state document's ``alarms`` lists keys (an alarm bit's key, a fault code's label,
``<key>_<n>`` for a code without a label; see ``state``): what MQTT clients and
automations match. Home Assistant shows the names a person reads instead ("Dry running,
Motor overcurrent"), from a table of names in the template, and keeps the keys in the
attribute ``keys``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping as AnyMapping

from bridge.core.discovery_entity import (
    TEXT_MAX,
    ComponentContext,
    Config,
    base_config,
    shown_name,
)
from bridge.core.entity import Component, Entity, PollClass

ALARM_KEYS_TEMPLATE = "{{ {'keys': value_json.alarms} | tojson }}"


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
