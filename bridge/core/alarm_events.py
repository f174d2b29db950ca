"""Alarms as events: each raise and clear the bridge sees, once. Pure.

The state document's ``alarms`` lists what is active now (bridge/core/state.py: an alarm
bit's key, a fault code's label, ``<key>_<n>`` for a code without a label). An automation
wants the moment one appears or goes, exactly once: ``alarm_events(points, values,
before)`` compares the alarms last published (``before``) with what the values say now
and returns the transitions, clears first (a fault code going from one fault to another
is one clear and one raise), with the set to remember. An alarm whose entity has no
value now (a device offline, a read refused, a slow poll not done yet after a mapping
reload) is neither raised nor cleared: it keeps what was last published.

``event_document`` is the message on ``<base>/<device>/event`` that Home Assistant's
event entity and device triggers, Node-RED and plain clients read.
"""

from __future__ import annotations

from collections.abc import Iterable
from collections.abc import Mapping as AnyMapping
from dataclasses import dataclass

from bridge.core.codec import Value
from bridge.core.mapping import Point
from bridge.core.state import active_alarms

RAISED, CLEARED = "raised", "cleared"


@dataclass(frozen=True, slots=True)
class AlarmEvent:
    """One alarm raised or cleared: its name in ``alarms``, the entity that reports it,
    and the raw code read (a fault code; for an alarm bit, whether it is on)."""

    alarm: str
    raised: bool
    key: str
    code: int | bool | None
    labelled: bool = True  # False: a fault code the mapping has no label for

    @property
    def state(self) -> str:
        return RAISED if self.raised else CLEARED

    @property
    def event_type(self) -> str:
        """What Home Assistant matches: one per alarm and state; a code without a label
        shares its entity's ``<key>_other`` (the event entity lists every event type)."""
        return event_type(self.alarm if self.labelled else other(self.key), self.state)


def event_type(alarm: str, state: str) -> str:
    """``dry_running_raised``: what the event entity and a device trigger match."""
    return f"{alarm}_{state}"


def other(key: str) -> str:
    """The alarm name of a fault code entity's codes without a label."""
    return f"{key}_other"


def alarm_events(
    points: AnyMapping[str, Point], values: AnyMapping[str, Value], before: frozenset[str]
) -> tuple[list[AlarmEvent], frozenset[str]]:
    """The transitions from the alarms ``before`` to those ``values`` say are active, and
    the alarms to remember (those of entities without a value stay as they were)."""
    said = active_alarms(points, values)
    active = set(said)
    owners = {name: owner for name in before | active if (owner := _owner(name, points))}
    known = {name for name, key in owners.items() if values.get(key) is not None}
    cleared = sorted((before & known) - active)
    raised = [name for name in said if name not in before]
    events = [_event(n, False, owners[n], points) for n in cleared]
    events += [_event(n, True, owners[n], points) for n in raised]
    return events, frozenset((before - set(cleared)) | active)


def reported(names: Iterable[str], points: AnyMapping[str, Point]) -> frozenset[str]:
    """The ``names`` some alarm entity of ``points`` can report (what a retained document
    says was active is taken only for those: anything else would be kept for nothing)."""
    return frozenset(name for name in names if _owner(name, points) is not None)


def _owner(name: str, points: AnyMapping[str, Point]) -> str | None:
    """The alarm entity that reports ``name``: the bit's key, the code's entity."""
    point = points.get(name)
    if point is not None and point.entity.alarm and point.entity.enum is None:
        return name
    for key, point in points.items():
        entity = point.entity
        if not entity.alarm or entity.enum is None:
            continue
        if name in entity.enum.values():
            return key
        code = name.removeprefix(f"{key}_")
        if code != name and code.isdigit():
            return key
    return None


def _event(name: str, raised: bool, key: str, points: AnyMapping[str, Point]) -> AlarmEvent:
    entity = points[key].entity
    if entity.enum is None:
        return AlarmEvent(name, raised, key, raised)
    codes = {label: raw for raw, label in entity.enum.items()}
    if name in codes:
        return AlarmEvent(name, raised, key, codes[name])
    return AlarmEvent(name, raised, key, int(name.removeprefix(f"{key}_")), labelled=False)


def event_document(event: AlarmEvent, name: str, when: str) -> dict[str, object]:
    """The JSON of one transition: ``event_type`` first (Home Assistant's event entity
    reads it; the other keys become its attributes), the alarm's key and the name a person
    reads, the transition (raised or cleared: not ``state``, which Home Assistant's entity has
    already), the entity and raw code, and when the bridge saw it."""
    return {
        "event_type": event.event_type,
        "alarm": event.alarm,
        "name": name,
        "transition": event.state,
        "entity": event.key,
        "code": event.code,
        "time": when,
    }
