"""Which words press a button or turn a switch (issue 11, item 2), for every shipped entity.

A button is pressed only by its press payload ``PRESS``; a switch takes only ON/OFF,
true/false and 1/0. Everything else is refused before an image is even consulted.
"""

from __future__ import annotations

import pytest

from bridge.core.codec import encode
from bridge.core.entity import Component
from bridge.core.mapping import Point, builtin_mapping_names, builtin_mapping_path, load_mapping
from bridge.errors import ValueRejectedError


def _all_points() -> list[Point]:
    points: list[Point] = []
    for name in builtin_mapping_names():
        mapping = load_mapping(builtin_mapping_path(name))
        for option, spec in mapping.options.items() or {"": None}.items():
            choices = spec.choices if spec is not None else [""]
            for choice in choices:
                chosen = {option: choice} if option else {}
                points.extend(mapping.points(chosen).values())
    return points


POINTS = _all_points()
BUTTONS = {p.key: p for p in POINTS if p.entity.writable and p.entity.press is not None}
SWITCHES = {
    p.key: p for p in POINTS if p.entity.writable and p.entity.component is Component.SWITCH
}
# Every register a button or switch could need (a bit field's word), holding zeros.
IMAGE = {(p.table, a): 0 for p in POINTS for a in p.span} | {
    (s.table, a): 0 for p in POINTS if p.sign is not None for s in (p.sign,) for a in s.span
}

NOT_A_PRESS = [
    "OFF", "off", "ON", "false", "true", "0", "1", "", " ", "open", "closed", "yes",
    "PRESSED", "PRESS!", "unpress", False, True, 0, 1, 2.5, None, [], {}, {"command_start": False},
]  # fmt: skip
NOT_ON_OFF = [
    "PRESS", "press", "open", "closed", "yes", "no", "2", "-1", "onn", "", 2, -1, 0.5, None,
    [], {}, "ON OFF",
]  # fmt: skip


def test_the_shipped_mappings_have_buttons_and_switches() -> None:
    assert len(BUTTONS) >= 15
    assert len(SWITCHES) >= 20


@pytest.mark.parametrize("key", sorted(BUTTONS))
@pytest.mark.parametrize("value", NOT_A_PRESS, ids=repr)
def test_a_button_is_not_pressed_by_anything_but_press(key: str, value: object) -> None:
    with pytest.raises(ValueRejectedError, match="only PRESS presses it"):
        encode(BUTTONS[key], value, IMAGE)


@pytest.mark.parametrize("key", sorted(BUTTONS))
@pytest.mark.parametrize("value", ["PRESS", "press", " Press\n"])
def test_a_button_is_pressed_by_its_press_payload(key: str, value: str) -> None:
    assert encode(BUTTONS[key], value, IMAGE)


@pytest.mark.parametrize("key", sorted(SWITCHES))
@pytest.mark.parametrize("value", NOT_ON_OFF, ids=repr)
def test_a_switch_takes_only_its_on_off_words(key: str, value: object) -> None:
    with pytest.raises(ValueRejectedError, match="is not ON/OFF"):
        encode(SWITCHES[key], value, IMAGE)


@pytest.mark.parametrize("key", sorted(SWITCHES))
@pytest.mark.parametrize(
    ("on", "off"), [("ON", "OFF"), ("on", "off"), ("true", "false"), (True, False), (1, 0)]
)
def test_a_switch_turns_on_and_off(key: str, on: object, off: object) -> None:
    point = SWITCHES[key]
    if point.entity.dangerous:
        return  # the guard is the poller's; the words are the same
    assert encode(point, on, IMAGE) != encode(point, off, IMAGE)
