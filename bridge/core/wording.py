"""Values and alarms in the words Home Assistant shows them in, for the web page. Pure.

The state document speaks to machines: an enum value by its label (``running_forward``),
a boolean as ``true``, an alarm by its key. The page speaks as Home Assistant does: an
entity by the name Home Assistant shows (``discovery_entity.shown_name``), an enum value
in words (``Running forward``, as the ``alarms`` sensor shows a fault code:
``discovery_alarms.in_words``), a code the mapping has no label for as ``Unknown code
23``, a binary sensor by its device class (``Running`` / ``Not running``, ``Problem`` /
``OK``: ``hass.BINARY_SENSOR_STATES``), a switch ``On`` / ``Off``, a number with the
decimals it is published with, no value as ``Unknown``, and the active alarms by the
names the ``alarms`` sensor joins (``discovery_alarms.alarm_names``).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from collections.abc import Mapping as AnyMapping

from bridge.core.codec import UNKNOWN_CODE, Value, is_unknown_code
from bridge.core.discovery_alarms import alarm_names, in_words
from bridge.core.discovery_entity import platform_of
from bridge.core.entity import Component, Entity
from bridge.core.hass import BINARY_SENSOR_STATES, binary_sensor_class
from bridge.core.mapping import Point

UNKNOWN = "Unknown"  # Home Assistant's word for a state it has no value for
_SWITCH_STATES = ("Off", "On")
_IDENTIFIER = re.compile(r"^[a-z][a-z0-9_]*$")  # a label written as a key: running_forward


def value_text(
    entity: Entity,
    value: Value,
    decimals: int | None,
    allow_dangerous_writes: bool,
    units: bool = False,
) -> str:
    """``value`` of ``entity`` as Home Assistant shows it (without the unit): the platform
    the entity is published as (``allow_dangerous_writes`` decides for a guarded switch)
    picks the words of a boolean; ``units``: the enum's labels are units (``unit_sources``),
    shown as they are (``bar``, not ``Bar``)."""
    if value is None:
        return UNKNOWN
    if isinstance(value, bool):
        platform = platform_of(entity, allow_dangerous_writes)
        if platform is Component.BINARY_SENSOR:
            return BINARY_SENSOR_STATES[binary_sensor_class(entity)][value]
        return _SWITCH_STATES[value]
    if isinstance(value, str):
        return label_text(entity, value, units)
    return number_text(value, decimals)


def label_text(entity: Entity, value: str, units: bool = False) -> str:
    """An enum label in words (one already in words, ``2.5 kHz``, as it is); a code
    without one as ``Unknown code 23``; text, and units, as they are."""
    if entity.enum is None:
        return value
    if is_unknown_code(entity, value):
        return f"Unknown code {value.removeprefix(UNKNOWN_CODE)}"
    return value if units or not _IDENTIFIER.match(value) else in_words(value)


def unit_sources(points: AnyMapping[str, Point]) -> frozenset[str]:
    """Keys of the enums whose labels are another entity's unit (``unit_from``)."""
    return frozenset(p.unit_source.key for p in points.values() if p.unit_source is not None)


def number_text(value: float, decimals: int | None) -> str:
    """A number with ``decimals`` (as published), or as it is when they are not known;
    never ``-0.0``."""
    if decimals is None:
        return str(value)
    text = f"{value:.{decimals}f}"
    return text.removeprefix("-") if text.strip("-0.") == "" else text


def alarm_texts(points: AnyMapping[str, Point], keys: Iterable[str], device_name: str) -> list[str]:
    """The names Home Assistant's ``alarms`` sensor shows for the alarm ``keys`` the state
    document lists (``state.active_alarms``): an alarm bit's entity name, a fault code's
    label in words, a key it has no name for in words (``fault_code_23``)."""
    entities = {key: point.entity for key, point in points.items() if point.entity.alarm}
    names = alarm_names(entities, device_name)
    return [names.get(key, in_words(key)) for key in keys]
