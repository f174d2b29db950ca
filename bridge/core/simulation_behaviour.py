"""How a simulated device answers its commands and raises faults. Pure, behind the simulator.

Read from a mapping's entities and their words, so that every mapping gets it, the
shipped ones and a user's:

* the **status** (the mapping's ``status:``) has a running label (``running``,
  ``running_forward``, ``normal_running``), a stopped one (``off``, ``stopped``,
  ``standby``...) and maybe a fault one (``alarm``, ``fault``); a yes/no status is on
  while running;
* **run commands**: a writable yes/no entity whose key says run or start (``start_stop``,
  ``motor_run``, the Vacon's ``run`` bit) starts with 1 and stops with 0; buttons and
  command words whose key or label is made of command words only start (``command_start``,
  ``reverse_run``, ``forward_jog``) or stop (``stop``, ``coast_stop``, ``command_stop``);
* a **fault reset** (``fault_reset``, a command word labelled so) clears every fault; a
  device without one clears them on a stop (a genset's Stop key, an inverter switched off);
* **faults**: ``raise_fault`` sets an alarm entity (a bit on, a fault code's label), the
  summary alarms with it (``fault``, ``common_alarm``, ``common_shutdown``...), and unless
  it is a warning or about the mains stops the device: status to its fault label, the
  newest alarm-history slot to the fault's name;
* **motion**: measurements of the moving machine (output, motor, generator, engine:
  speed, frequency, current, power, torque, load, their voltages) are 0 while stopped and
  back to their running values on a start.

Every function returns the cells that change; the new image is the old one updated with them.
"""

from __future__ import annotations

from collections.abc import Mapping as AnyMapping
from dataclasses import dataclass

from bridge.core.codec import Image, Value, decode
from bridge.core.entity import Access, Entity
from bridge.core.mapping import Mapping, Point
from bridge.core.request import Write
from bridge.core.simulation import Cell, numbered, stored_cells, words_for
from bridge.errors import ValueRejectedError

RUN, STOP, RESET = "run", "stop", "reset"
_COMMAND_WORDS = frozenset(
    {"command", "run", "start", "stop", "forward", "reverse", "jog", "coast", "motor", "quick"}
)
_RESET_WORDS = frozenset({"fault", "alarm", "reset", "command"})
_STOPPED_LABELS = ("off", "stopped", "standby", "stop", "ready", "idle")
_OUTSIDE_WORDS = frozenset({"warning", "mains"})  # alarms that do not stop the device
_FAULT_LABEL_WORDS = frozenset({"alarm", "fault", "trip"})
_MOTION_WORDS = frozenset(
    {"output", "motor", "speed", "frequency", "current", "power", "torque", "load"}
    | {"generator", "engine", "rpm"}
)
_STILL_WORDS = frozenset(
    {"mains", "dc", "bus", "link", "battery", "charger", "rated", "set", "reference"}
    | {"factor", "temperature", "max", "min", "input", "setpoint"}
)


@dataclass(frozen=True, slots=True)
class Behaviour:
    """The parts of one simulated device that follow commands and faults."""

    status: Point | None
    running: tuple[Value, ...]  # status values while running (first: forward/default)
    stopped: Value
    fault: Value  # the status while faulted (the stopped value without a fault label)
    switches: tuple[Point, ...]  # yes/no run commands: 1 runs, 0 stops
    commands: tuple[Point, ...]  # buttons and command words
    alarms: tuple[Point, ...]
    summaries: tuple[Point, ...]  # yes/no alarms set with any fault of their kind
    history: tuple[Point, ...]  # alarm-history slots, newest first
    motion: tuple[Point, ...]
    running_values: dict[Cell, int]  # what the motion points hold while running
    has_reset: bool


def words(text: str) -> frozenset[str]:
    return frozenset(text.lower().replace("-", "_").split("_"))


def build_behaviour(mapping: Mapping, points: AnyMapping[str, Point], image: Image) -> Behaviour:
    """The behaviour of a device whose start image (running, no fault) is ``image``."""
    status = points.get(mapping.status or "")
    running, stopped, fault = _status_values(status)
    commands = tuple(p for p in points.values() if _intent(p) is not None)
    switches = tuple(
        p
        for p in points.values()
        if p.entity.writable
        and p.entity.kind == "bool"
        and p.entity.press is None
        and _commanding(p.key)
        and words(p.key) & {"run", "start"}
    )
    alarms = tuple(p for p in points.values() if p.entity.alarm and p.entity.readable)
    motion = tuple(p for p in points.values() if _moves(p))
    return Behaviour(
        status=status,
        running=running,
        stopped=stopped,
        fault=fault,
        switches=switches,
        commands=commands,
        alarms=alarms,
        summaries=tuple(p for p in alarms if _summary(p) is not None),
        history=_history(points),
        motion=motion,
        running_values={(p.table, a): image.get((p.table, a), 0) for p in motion for a in p.span},
        has_reset=any(_intent(p) == RESET for p in commands),
    )


def _status_values(status: Point | None) -> tuple[tuple[Value, ...], Value, Value]:
    if status is None:
        return (), None, None
    entity = status.entity
    if entity.kind == "bool":
        return (True,), False, False
    labels = list((entity.enum or {}).values())
    running = tuple(x for x in labels if "running" in words(x) and "stopping" not in words(x))
    stopped = next((x for want in _STOPPED_LABELS for x in labels if want in words(x)), None)
    fault = next((x for x in labels if words(x) & _FAULT_LABEL_WORDS and "stop" not in x), None)
    return running, stopped, fault if fault is not None else stopped


def _commanding(text: str) -> bool:
    return words(text) <= _COMMAND_WORDS


def _intent_of(text: str) -> str | None:
    """What a button or command label does: run, stop, reset, or nothing we know."""
    found = words(text)
    if "reset" in found and found <= _RESET_WORDS:
        return RESET
    if not _commanding(text):
        return None
    if "stop" in found:
        return STOP
    return RUN if found & {"run", "start", "jog"} else None


def _intent(point: Point) -> str | None:
    entity = point.entity
    if entity.press is not None:
        return _intent_of(point.key)
    if entity.access is Access.WRITE and entity.enum:
        return RUN if any(_intent_of(label) for label in entity.enum.values()) else None
    return None


def _summary(point: Point) -> str | None:
    """The faults a summary alarm stands for: ``any`` alarm (``common_alarm``), any that
    stops the device (``fault``), a ``shutdown`` or a ``warning``."""
    if point.entity.kind != "bool":
        return None
    found = words(point.key)
    if found in ({"common", "alarm"}, {"alarm"}):
        return "any"
    if found == {"fault"}:
        return "stopping"
    if found in ({"common", "shutdown"}, {"common", "warning"}):
        return sorted(found - {"common"})[0]
    return None


def _kinds(key: str) -> set[str]:
    """The summary kinds a fault raised on ``key`` sets."""
    found = words(key)
    kinds = {"any", "warning" if "warning" in found else "stopping"}
    return kinds | ({"shutdown"} if "shutdown" in found else set())


def _stops(key: str) -> bool:
    return not words(key) & _OUTSIDE_WORDS


def _moves(point: Point) -> bool:
    entity = point.entity
    found = words(point.key)
    return (
        entity.access is Access.READ
        and entity.kind == "number"
        and entity.ha.state_class == "measurement"
        and bool(found & _MOTION_WORDS)
        and not found & _STILL_WORDS
    )


def _history(points: AnyMapping[str, Point]) -> tuple[Point, ...]:
    """The alarm-history slots (``alarm_history_1``...): enums sharing labels, by number."""
    slots: dict[str, list[tuple[int, Point]]] = {}
    for key, point in points.items():
        found = numbered(key)
        if found and point.entity.enum and "history" in words(found[0]):
            stem, number = found
            slots.setdefault(stem, []).append((number, point))
    family = max(slots.values(), key=len, default=[])
    return tuple(point for _, point in sorted(family, key=lambda item: item[0]))


# --- state ---------------------------------------------------------------------------


def is_running(behaviour: Behaviour, image: Image) -> bool:
    """Running as the device shows it: its status; without running labels, switched on (or
    without a switch, always) and not tripped by a fault."""
    if behaviour.status is not None and behaviour.running:
        return decode(behaviour.status, image) in behaviour.running
    return _switched_on(behaviour, image, default=True) and not _stopping(behaviour, image)


def _switched_on(behaviour: Behaviour, image: Image, *, default: bool) -> bool:
    readable = [p for p in behaviour.switches if p.entity.readable]
    return bool(decode(readable[0], image)) if readable else default


def active_faults(behaviour: Behaviour, image: Image) -> list[str]:
    """Keys of the alarm entities that are on (or off their normal code)."""
    return [p.key for p in behaviour.alarms if _alarming(p, decode(p, image))]


def _alarming(point: Point, value: Value) -> bool:
    entity = point.entity
    if entity.kind == "bool":
        return value is True
    normal = {(entity.enum or {}).get(raw) for raw in entity.normal}
    return value is not None and value not in normal


def _stopping(behaviour: Behaviour, image: Image) -> bool:
    return any(_stops(key) for key in active_faults(behaviour, image))


def start_image(behaviour: Behaviour, image: Image) -> dict[Cell, int]:
    """The run switches as the status shows it: a simulated device starts running, so it
    was switched on (a device whose status says nothing of running is switched on too)."""
    shown = behaviour.status is not None and bool(behaviour.running)
    on = is_running(behaviour, image) if shown else True
    changes: dict[Cell, int] = {}
    for switch in behaviour.switches:
        if switch.entity.readable:
            changes |= words_for(switch, on, {**image, **changes})
    return changes


# --- commands ------------------------------------------------------------------------


def follow(behaviour: Behaviour, write: Write, image: Image) -> dict[Cell, int]:
    """The cells a write accepted by the device changes besides itself: ``image`` is the
    image after the write (command coils leave no bit behind)."""
    changes: dict[Cell, int] = {}
    for effect, reverse in _effects(behaviour, write):
        changes |= _apply(behaviour, effect, reverse, {**image, **changes})
    return changes


def _effects(behaviour: Behaviour, write: Write) -> list[tuple[str, bool]]:
    written = stored_cells(write)
    effects: list[tuple[str, bool]] = []
    for point in (*behaviour.switches, *behaviour.commands):
        raw = _written_raw(point, written)
        if raw is None:
            continue
        entity = point.entity
        if point in behaviour.switches:
            effects.append((RUN if raw else STOP, False))
        elif entity.press is not None and raw == _raw_press(entity):
            intent = _intent_of(point.key)
            effects.append((intent or "", "reverse" in words(point.key)))
        elif entity.enum and raw in entity.enum:
            label = entity.enum[raw]
            effects.append((_intent_of(label) or "", "reverse" in words(label)))
    return [effect for effect in dict.fromkeys(effects) if effect[0]]


def _written_raw(point: Point, written: dict[Cell, int]) -> int | None:
    cell = (point.table, point.write_address)
    if cell not in written:
        return None
    word, entity = written[cell], point.entity
    if entity.field_width is not None:
        return (word >> (entity.bit or 0)) & ((1 << entity.field_width) - 1)
    if entity.words is not None:
        return int(entity.words.state(word) is True)
    return int(word != 0) if entity.kind == "bool" else word


def _raw_press(entity: Entity) -> int | None:
    press = entity.press
    if isinstance(press, bool):
        return int(press)
    return press if isinstance(press, int) else None


def _apply(behaviour: Behaviour, effect: str, reverse: bool, image: Image) -> dict[Cell, int]:
    if effect == RESET or (effect == STOP and not behaviour.has_reset):
        cleared = clear_faults(behaviour, image)
        if effect == RESET:
            return cleared
        image = dict(image) | cleared
        return cleared | _set_running(behaviour, False, False, image)
    if effect == RUN and _stopping(behaviour, image):
        return {}  # a faulted device does not start
    return _set_running(behaviour, effect == RUN, reverse, image)


def _set_running(
    behaviour: Behaviour, running: bool, reverse: bool, image: Image
) -> dict[Cell, int]:
    changes: dict[Cell, int] = {}
    status = behaviour.status
    if status is not None and behaviour.running:
        choices = [v for v in behaviour.running if "reverse" in str(v)] if reverse else []
        value = (choices or list(behaviour.running))[0] if running else behaviour.stopped
        if value is not None:
            changes |= words_for(status, value, image)
    if running:
        return changes | behaviour.running_values
    return changes | {cell: 0 for p in behaviour.motion for cell in _cells(p)}


def _cells(point: Point) -> list[Cell]:
    return [(point.table, address) for address in point.span]


# --- faults --------------------------------------------------------------------------


def raise_fault(behaviour: Behaviour, key: str, label: str | None, image: Image) -> dict[Cell, int]:
    """Set the alarm ``key`` (a fault code to ``label``, else its first fault), its summary
    alarms, and unless it is a warning stop the device; ValueRejectedError if the device
    has no such alarm or label."""
    point = next((p for p in behaviour.alarms if p.key == key), None)
    if point is None:
        known = ", ".join(p.key for p in behaviour.alarms) or "none"
        raise ValueRejectedError(f"no alarm {key!r} (alarms: {known})")
    entity = point.entity
    value: Value = True
    if entity.kind != "bool":
        faults = [v for raw, v in (entity.enum or {}).items() if raw not in entity.normal]
        if label is not None and label not in faults:
            raise ValueRejectedError(f"{key}: {label!r} is not one of its faults ({faults})")
        value = label if label is not None else faults[0]
    elif label is not None:
        raise ValueRejectedError(f"{key} is a yes/no alarm: give no label")
    changes = words_for(point, value, image)
    kinds = _kinds(key)
    for summary in behaviour.summaries:
        if _summary(summary) in kinds and summary is not point:
            changes |= words_for(summary, True, {**image, **changes})
    if not _stops(key):
        return changes
    changes |= _note_in_history(behaviour, str(value) if entity.kind != "bool" else key, image)
    changes |= _set_running(behaviour, False, False, {**image, **changes})
    if behaviour.status is not None and behaviour.status is not point and behaviour.running:
        changes |= words_for(behaviour.status, behaviour.fault, {**image, **changes})
    return changes


def _note_in_history(behaviour: Behaviour, name: str, image: Image) -> dict[Cell, int]:
    """Shift the history one slot down and write ``name`` (``alarm_x`` is ``x``) first."""
    if not behaviour.history:
        return {}
    labels = set((behaviour.history[0].entity.enum or {}).values())
    shown = name if name in labels else name.removeprefix("alarm_")
    if shown not in labels:
        return {}
    changes: dict[Cell, int] = {}
    slots = behaviour.history
    for newer, older in zip(slots[-2::-1], slots[:0:-1], strict=True):
        changes |= {
            (older.table, older.address + i): image.get((newer.table, newer.address + i), 0)
            for i in range(older.count)
        }
    return changes | words_for(slots[0], shown, image)


def clear_faults(behaviour: Behaviour, image: Image) -> dict[Cell, int]:
    """Every alarm back to normal; the status back to running if a run switch is on,
    else to stopped (a start command is needed, as on most drives)."""
    changes: dict[Cell, int] = {}
    for point in behaviour.alarms:
        if not _alarming(point, decode(point, {**image, **changes})):
            continue
        entity = point.entity
        normal: Value = False
        if entity.kind != "bool":
            normal = (entity.enum or {}).get(entity.normal[0])
        changes |= words_for(point, normal, {**image, **changes})
    image = dict(image) | changes
    status = behaviour.status
    if status is not None and behaviour.running:
        if decode(status, image) == behaviour.fault:
            on = _switched_on(behaviour, image, default=False)
            changes |= _set_running(behaviour, on, False, image)
        return changes
    return changes | _set_running(behaviour, is_running(behaviour, image), False, image)
