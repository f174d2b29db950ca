"""One entity as a Home Assistant MQTT discovery component. Pure.

``component_config(key, entity, context)`` returns the component mapping that goes under
``cmps`` of a device-based discovery payload (with its ``platform``), or None when the
entity is not published: secret, write-only and guarded by the dangerous-write switch,
or write-only with nothing Home Assistant could show. A dangerous writable entity whose
writes are not allowed is published read-only (sensor or binary_sensor, same key and
unique_id) when it can be read.

Values come from the device's JSON state document (``<base>/<device>``) through
``{{ value_json.<key> }}``; a read-only component gets ``expire_after`` so that a value
the bridge stopped refreshing goes unavailable. A write-only select (a command word) reads
the device's document too, for the option its ``state_from`` link shows (the drive's status
``standby`` as ``stop``), else for nothing: its state is unknown, never the last option
chosen, which Home Assistant would show without a state topic (optimistic). Other
write-only components (buttons; numbers and texts, none shipped) have no state topic.
"""

from __future__ import annotations

import json
import math
import re
import sys
from collections.abc import Callable
from collections.abc import Mapping as AnyMapping
from dataclasses import dataclass, field
from typing import Any, TypeGuard

from bridge.core.codec import (
    COMMAND_OFF,
    COMMAND_ON,
    COMMAND_PRESS,
    Image,
    Value,
    float_limit,
    is_unknown_code,
    limits_of,
    raw_bounds,
    scale_value,
)
from bridge.core.entity import MAX_EXPONENT, Component, Entity, PollClass, StateLink
from bridge.core.hass import BUTTON_CLASSES, SWITCH_CLASSES, binary_sensor_class
from bridge.core.mapping import Point
from bridge.core.topics import Topics
from bridge.errors import MissingDataError

Config = dict[str, Any]
Limits = tuple[float | None, float | None]

# Payloads the bridge uses on the wire: the state document renders Python booleans
# through the template, commands take ON/OFF and PRESS (see DESIGN.md, MQTT contract).
STATE_TRUE = "True"
STATE_FALSE = "False"
QOS = 1
TEXT_MAX = 255  # Home Assistant's longest state
_READ_ONLY = (Component.SENSOR, Component.BINARY_SENSOR)
_SLUG = re.compile(r"[^a-z0-9_]+")


@dataclass(frozen=True, slots=True)
class ComponentContext:
    """What every component of one device shares."""

    topics: Topics
    device_id: str
    allow_dangerous_writes: bool
    fast_interval: float
    slow_interval: float
    state_refresh: float
    units: AnyMapping[str, str | None]
    limits: AnyMapping[str, Limits]
    intervals: AnyMapping[str, float] = field(default_factory=dict)  # key -> its poll interval
    readings: AnyMapping[str, Value] = field(default_factory=dict)
    device_name: str = ""
    keys: frozenset[str] = frozenset()  # every key of the mapping (entity ids kept apart)

    @property
    def unique_prefix(self) -> str:
        return f"{self.topics.base}_{self.device_id}"

    def expire_after(self, poll: PollClass | float, key: str = "") -> int:
        """Seconds after which an unrefreshed value is stale: two state refreshes plus
        one poll (every value is republished at least every ``state_refresh``), so always
        longer than the interval, as Home Assistant needs. The poll is the key's interval
        as its poller resolved it, else ``poll``'s: an interval of its own, ``fast``, or
        ``slow`` (``once`` too)."""
        if key in self.intervals:
            interval = self.intervals[key]
        elif poll is PollClass.FAST:
            interval = self.fast_interval
        else:
            interval = self.slow_interval if isinstance(poll, PollClass) else poll
        interval = interval if math.isfinite(interval) else self.slow_interval
        return int(2 * self.state_refresh + interval)


def slug(text: str) -> str:
    """An entity-id-safe form: lowercase letters, digits and ``_``."""
    return _SLUG.sub("_", text.lower()).strip("_")


def shown_name(name: str, device_name: str) -> str:
    """The entity's name without a leading device name: Home Assistant shows the device's
    name before it ("Genset status" on the device "Genset" would read "Genset Genset
    status")."""
    prefix = f"{device_name} "
    if device_name and name.casefold().startswith(prefix.casefold()) and len(name) > len(prefix):
        rest = name[len(prefix) :]
        return rest[:1].upper() + rest[1:]
    return name


def object_id(key: str, context: ComponentContext) -> str:
    """The entity id Home Assistant is asked for, after the platform: ``<device>_<key>``,
    without a leading repeat of the device id in the key (key ``genset_status`` on the
    device ``genset`` is ``sensor.genset_status``, not ``sensor.genset_genset_status``).
    The repeat stays where the shorter id is another key's (``status`` beside it). Home
    Assistant takes the id only when it first creates the entity: one already there keeps
    its id and history, and the unique id is the key's in any case."""
    device = slug(context.device_id)
    rest = key.removeprefix(f"{device}_")
    if not rest or rest == key or rest in context.keys:
        return f"{device}_{key}"
    return f"{device}_{rest}"


def value_template(key: str) -> str:
    return f"{{{{ value_json.{key} }}}}"


def platform_of(entity: Entity, allow_dangerous_writes: bool) -> Component | None:
    """The platform the entity is published as, or None when it is not published."""
    if entity.secret:
        return None
    component = entity.component
    guarded = entity.dangerous and not allow_dangerous_writes
    if component in _READ_ONLY or guarded or not entity.writable:
        if not entity.readable:
            return None
        return component if component in _READ_ONLY else read_only_platform(entity)
    return component


def read_only_platform(entity: Entity) -> Component:
    return Component.BINARY_SENSOR if entity.kind == "bool" else Component.SENSOR


def base_config(
    key: str,
    name: str,
    platform: Component,
    context: ComponentContext,
    entity_id: str | None = None,
) -> Config:
    """The options every component has: platform, ids, name and QoS. ``entity_id``: the
    object id the entity asks for instead of ``object_id``'s (an imported entity's).

    QoS is set per component: Home Assistant up to 2026.2 at least accepts a shared
    ``qos`` at the root of a device payload but does not pass it on to the components.
    """
    return {
        "platform": platform.value,
        "unique_id": f"{context.unique_prefix}_{key}",
        "default_entity_id": f"{platform.value}.{entity_id or object_id(key, context)}",
        "name": shown_name(name, context.device_name),
        "qos": QOS,
    }


def component_config(key: str, entity: Entity, context: ComponentContext) -> Config | None:
    """The ``cmps`` entry of one entity, or None when the entity is not published."""
    platform = platform_of(entity, context.allow_dangerous_writes)
    if platform is None:
        return None
    config = base_config(key, entity.name, platform, context, entity.ha.entity_id)
    category = entity.ha.entity_category
    if category == "config" and platform in _READ_ONLY:
        category = "diagnostic"  # Home Assistant refuses config on sensors
    if category is not None:
        config["entity_category"] = category
    config["enabled_by_default"] = entity.enabled_by_default
    if entity.ha.icon is not None:
        config["icon"] = entity.ha.icon
    config |= _BUILDERS[platform](key, entity, context)
    if platform in _READ_ONLY:
        config["expire_after"] = context.expire_after(entity.poll_spec, key)
    return config


def admittable(points: AnyMapping[str, Point]) -> dict[str, Point]:
    """The points whose readings a discovery payload may have to admit: enums (a code
    without a label) and writable numbers (a reading beyond the range offered)."""
    return {
        key: point
        for key, point in points.items()
        if point.entity.enum is not None
        or (point.entity.writable and point.entity.kind == "number")
    }


def shown_readings(
    points: AnyMapping[str, Point], values: AnyMapping[str, Value], image: Image
) -> dict[str, Value]:
    """The values read that a discovery payload must admit, by key: an enum code the
    mapping has no label for (an option), a writable number outside its limits or below
    its ``dangerous_below`` (the number's range). ``points`` may be ``admittable``'s."""
    shown: dict[str, Value] = {}
    for key, point in points.items():
        entity = point.entity
        if entity.enum is None and not (entity.writable and entity.kind == "number"):
            continue  # neither an unknown code nor a number beyond its range can come
        value = values.get(key)
        if is_unknown_code(entity, value) or _beyond(point, value, image):
            shown[key] = value
    return shown


def admitted(
    points: AnyMapping[str, Point],
    sent: AnyMapping[str, Value],
    shown: AnyMapping[str, Value],
    image: Image,
) -> bool:
    """True when a payload built with the readings ``sent`` shows every reading of
    ``shown`` too: the same unknown code, or a number inside the range the reading sent
    widened (a setting that wanders below its limits needs no new payload per poll)."""
    for key, value in shown.items():
        if key not in sent:
            return False
        if value == sent[key]:
            continue
        point, before = points.get(key), sent[key]
        if point is None or not _widened_to(point, before, value, image):
            return False
    return True


def _widened_to(point: Point, before: Value, value: Value, image: Image) -> bool:
    """``value`` lies in the range the reading ``before`` widened (both numbers)."""
    if not (_is_number(before) and _is_number(value)):
        return False
    low, high = _bounds(point, image)
    low = before if low is None else min(low, before)
    high = before if high is None else max(high, before)
    return low <= value <= high


def _is_number(value: Value) -> TypeGuard[int | float]:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _bounds(point: Point, image: Image) -> tuple[float | None, float | None]:
    """The range a writable number is offered in: its limits (read, else the mapping's),
    none below ``dangerous_below``."""
    entity = point.entity
    try:
        low, high = limits_of(point, image)
    except MissingDataError:
        low, high = entity.min, entity.max
    floor = entity.dangerous_below
    if floor is not None:
        low = floor if low is None else max(low, floor)
    return low, high


def _beyond(point: Point, value: Value, image: Image) -> bool:
    entity = point.entity
    if not entity.writable or entity.kind != "number" or not _is_number(value):
        return False
    low, high = _bounds(point, image)
    return (low is not None and value < low) or (high is not None and value > high)


# --- read-only platforms ---------------------------------------------------------------


def _state(key: str, context: ComponentContext) -> Config:
    return {
        "state_topic": context.topics.device(context.device_id),
        "value_template": value_template(key),
    }


def _sensor(key: str, entity: Entity, context: ComponentContext) -> Config:
    config = _state(key, context)
    if entity.enum is not None:
        config |= {"device_class": "enum", "options": options_of(key, entity, context)}
    elif entity.kind == "number":
        config |= numeric_sensor_options(key, entity, context)
    return config


def numeric_sensor_options(key: str, entity: Entity, context: ComponentContext) -> Config:
    """device_class, state_class, unit and display precision of a numeric sensor."""
    config: Config = {}
    if entity.ha.device_class is not None:
        config["device_class"] = entity.ha.device_class
    if entity.ha.state_class is not None:
        config["state_class"] = entity.ha.state_class
    if entity.ha.state_class == "total":  # a count the device starts again by design
        config["last_reset_value_template"] = f"{{{{ value_json.last_reset.{key} }}}}"
    unit = unit_of(key, entity, context)
    if unit is not None:
        config["unit_of_measurement"] = unit
    if entity.ha.display_precision is not None:
        config["suggested_display_precision"] = entity.ha.display_precision
    elif not entity.data_type.is_float and (
        entity.scale_by is None or entity.precision is not None
    ):
        # a float has no fixed decimals, nor a value scaled by a register (scale_by)
        config["suggested_display_precision"] = entity.decimals
    return config


def unit_of(key: str, entity: Entity, context: ComponentContext) -> str | None:
    """The fixed unit, or the one last read from the entity's unit register."""
    if entity.unit_from is not None:
        return context.units.get(key)
    return entity.unit


def _binary_sensor(key: str, entity: Entity, context: ComponentContext) -> Config:
    config = _state(key, context) | {"payload_on": STATE_TRUE, "payload_off": STATE_FALSE}
    device_class = binary_sensor_class(entity)
    if device_class is not None:
        config["device_class"] = device_class
    return config


# --- commanding platforms --------------------------------------------------------------


def _command(key: str, entity: Entity, context: ComponentContext) -> Config:
    """command_topic, plus the state when the entity can be read (else: optimistic)."""
    config: Config = {"command_topic": context.topics.set(context.device_id, key)}
    if entity.readable:
        config |= _state(key, context)
    elif entity.toggle_of is not None:  # a toggle shows the state it flips
        config |= _state(entity.toggle_of, context)
    return config


def _number(key: str, entity: Entity, context: ComponentContext) -> Config:
    low, high = number_range(key, entity, context)
    config = _command(key, entity, context) | {
        "min": low,
        "max": high,
        "step": _step(entity),
        "mode": entity.ha.mode or "box",
    }
    unit = unit_of(key, entity, context)
    if unit is not None:
        config["unit_of_measurement"] = unit
    if entity.ha.device_class is not None:
        config["device_class"] = entity.ha.device_class
    return config


def number_range(key: str, entity: Entity, context: ComponentContext) -> tuple[float, float]:
    """Limits read from the device, else the mapping's, else what the register holds;
    without ``allow_dangerous_writes``, none below ``dangerous_below``. Widened to the value
    the device reads now (``context.readings``), which Home Assistant would drop as out of
    range otherwise; writes stay checked against the limits."""
    if entity.data_type.is_float:  # the float's own range, scaled (never infinite)
        top = min(float_limit(entity.data_type) * abs(entity.scale), sys.float_info.max)
        ends = [entity.offset - top, entity.offset + top]
    else:
        raw_low, raw_high = raw_bounds(entity)
        power = MAX_EXPONENT if entity.scale_by is not None else 0  # any exponent it may read
        ends = sorted(
            (
                scale_value(entity, raw_low, exponent=power),
                scale_value(entity, raw_high, exponent=power),
            )
        )
    if entity.sign_from is not None:
        ends = [-ends[1], ends[1]]
    static = (
        entity.min if entity.min is not None else ends[0],
        entity.max if entity.max is not None else ends[1],
    )
    dynamic = context.limits.get(key, (None, None))
    low = dynamic[0] if dynamic[0] is not None else static[0]
    high = dynamic[1] if dynamic[1] is not None else static[1]
    if low > high:  # limit registers that contradict each other: keep the mapping's
        low, high = static
    guarded = entity.dangerous_below
    if guarded is not None and not context.allow_dangerous_writes and guarded <= high:
        low = max(low, guarded)  # values below are refused: not offered
    reading = context.readings.get(key)
    if isinstance(reading, int | float) and not isinstance(reading, bool):
        low, high = min(low, reading), max(high, reading)  # what the device holds is shown
    return low, high


def options_of(key: str, entity: Entity, context: ComponentContext) -> list[str]:
    """The enum's labels, and the code the device reads now when the mapping has no label
    for it (``code_23``): Home Assistant drops a state that is not one of the options."""
    labels = list((entity.enum or {}).values())
    reading = context.readings.get(key)
    if isinstance(reading, str) and is_unknown_code(entity, reading):
        labels.append(reading)
    return labels


def _select(key: str, entity: Entity, context: ComponentContext) -> Config:
    config = _command(key, entity, context) | {"options": options_of(key, entity, context)}
    if not entity.readable:  # a command word: not optimistic (it would show the last choice)
        config |= {
            "state_topic": context.topics.device(context.device_id),
            "value_template": command_state_template(entity.state_from),
        }
    return config


def command_state_template(link: StateLink | None) -> str:
    """The state of a write-only select: the option its ``state_from`` link shows for the
    label read (``{% set s = value_json.status %}{{ {"standby": "stop"}.get(s) }}``),
    else none; Home Assistant shows a rendered ``None`` as unknown, without a warning."""
    if link is None:
        return "{{ none }}"
    shown = json.dumps(link.labels, ensure_ascii=False)
    return f"{{% set s = value_json.{link.entity} %}}{{{{ {shown}.get(s) }}}}"


def _switch(key: str, entity: Entity, context: ComponentContext) -> Config:
    config = _command(key, entity, context) | {
        "payload_on": COMMAND_ON,
        "payload_off": COMMAND_OFF,
    }
    if entity.readable or entity.toggle_of is not None:
        config |= {"state_on": STATE_TRUE, "state_off": STATE_FALSE}
    if entity.ha.device_class in SWITCH_CLASSES:
        config["device_class"] = entity.ha.device_class
    return config


def _button(key: str, entity: Entity, context: ComponentContext) -> Config:
    config: Config = {
        "command_topic": context.topics.set(context.device_id, key),
        "payload_press": COMMAND_PRESS,
    }
    if entity.ha.device_class in BUTTON_CLASSES:
        config["device_class"] = entity.ha.device_class
    return config


def _text(key: str, entity: Entity, context: ComponentContext) -> Config:
    config = _command(key, entity, context) | {
        "max": min(2 * entity.register_count, TEXT_MAX),
        "mode": "text",
    }
    if entity.readable:  # unknown (null) shows as empty text, not as "None"
        config["value_template"] = (
            f"{{{{ value_json.{key} if value_json.{key} is not none else '' }}}}"
        )
    return config


_BUILDERS: dict[Component, Callable[[str, Entity, ComponentContext], Config]] = {
    Component.SENSOR: _sensor,
    Component.BINARY_SENSOR: _binary_sensor,
    Component.NUMBER: _number,
    Component.SELECT: _select,
    Component.SWITCH: _switch,
    Component.BUTTON: _button,
    Component.TEXT: _text,
}


def _step(entity: Entity) -> float:
    """A number's step: ``step``, else its scale; a ``scale_by`` value without ``step``
    takes its ``precision``'s (else Home Assistant's finest, 0.001): the bridge rounds
    to the exponent the device holds when it writes."""
    if entity.step is not None:
        return entity.step
    if entity.scale_by is None:
        return abs(entity.scale)
    return 10.0 ** -min(entity.precision if entity.precision is not None else 3, 3)
