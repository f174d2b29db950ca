"""A switch's own words (``words``) and a reading's shaping (``clamp``, ``zero_suppress``).

Both come from Home Assistant's modbus integration (``command_on``/``command_off`` with
``verify``'s ``state_on``/``state_off``; a sensor's ``min_value``/``max_value`` and
``zero_suppress``), read at home-assistant/core ``homeassistant/components/modbus/entity.py``:
``BaseSwitch._async_update`` (a word in state_on is on, in state_off off, another is logged
and ignored) and ``BaseStructPlatform.__process_raw_value`` (scale * raw + offset, then min,
then max, then ``abs(val) <= zero_suppress`` shows 0, then the precision).
"""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import ValidationError

from bridge.core.codec import decode, encode
from bridge.core.entity import Table
from bridge.core.request import Write
from bridge.core.simulation import initial_image, words_for
from bridge.errors import ValueRejectedError
from tests.factory import make_mapping, make_point

H = Table.HOLDING
SWITCH: dict[str, Any] = {"type": "bool", "access": "rw", "address": 0x10}
RELAY = SWITCH | {"words": {"write_on": 0x0100, "write_off": 0x0200}}
LISTED = SWITCH | {
    "words": {"write_on": 0xAA, "write_off": 0x55, "read_on": [0xAA, 0xAB], "read_off": [0x55, 0]}
}


@pytest.mark.parametrize(
    ("fields", "word", "expected"),
    [
        (RELAY, 0x0100, True),
        (RELAY, 0x0200, False),
        (RELAY, 0x0000, None),  # neither word: unknown, not guessed
        (RELAY, 0x0001, None),
        (LISTED, 0xAA, True),
        (LISTED, 0xAB, True),
        (LISTED, 0x55, False),
        (LISTED, 0x00, False),
        (LISTED, 0x56, None),
        (SWITCH, 0x0200, True),  # without words: any non-zero word is on
        (SWITCH, 0x0000, False),
    ],
)
def test_a_switch_reads_its_words(fields: dict[str, Any], word: int, expected: object) -> None:
    point = make_point("relay", **fields)
    assert decode(point, {(H, 0x10): word}) is expected


@pytest.mark.parametrize(
    ("fields", "command", "word"),
    [
        (RELAY, "ON", 0x0100),
        (RELAY, "off", 0x0200),
        (RELAY, True, 0x0100),
        (RELAY, 0, 0x0200),
        (LISTED, "ON", 0xAA),  # the word written is `on`, not another word read as on
        (LISTED, "OFF", 0x55),
        (SWITCH, "ON", 1),
    ],
)
def test_a_switch_writes_its_words(fields: dict[str, Any], command: object, word: int) -> None:
    point = make_point("relay", **fields)
    assert encode(point, command, {}) == (Write(6, H, 0x10, (word,)),)


def test_a_switch_with_words_on_fc16_and_apart_from_its_state() -> None:
    point = make_point("relay", **RELAY, write_function=16, write_address=0x20)
    assert encode(point, "ON", {}) == (Write(16, H, 0x20, (0x0100,)),)


@pytest.mark.parametrize("command", ["0x0100", 256, "256", "TOGGLE", 2, None, "", "on off"])
def test_a_switch_with_words_takes_only_on_and_off(command: object) -> None:
    """The words are the mapping's: a command cannot name one (nor any other word)."""
    with pytest.raises(ValueRejectedError):
        encode(make_point("relay", **RELAY), command, {})


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        (
            SWITCH | {"words": {"write_on": 1, "write_off": 1}},
            "write_on and write_off are different words",
        ),
        (LISTED | {"words": {"write_on": 1, "write_off": 0, "read_off": [1]}}, "both on and off"),
        (SWITCH | {"words": {"write_on": 0x10000, "write_off": 0}}, "less than or equal to 65535"),
        (SWITCH | {"words": {"write_on": 1, "write_off": 0, "read_on": []}}, "at least 1"),
        (RELAY | {"access": "r"}, "a switch with access rw or w"),
        (RELAY | {"type": "u16"}, "a switch on a holding register"),
        (
            {"table": "coil", "access": "rw", "words": {"write_on": 1, "write_off": 0}},
            "holding register",
        ),
        (RELAY | {"byte_order": "little"}, "drop byte_order"),
        (RELAY | {"write_function": 5}, "write_function 6 or 16"),
        (RELAY | {"access": "w", "pulse": True}, "not a button or pulse"),
    ],
)
def test_words_that_are_refused(fields: dict[str, Any], message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        make_point("relay", **fields)


def test_the_simulator_stores_a_switch_by_its_words() -> None:
    point = make_point("relay", **RELAY)
    assert words_for(point, True, {}) == {(H, 0x10): 0x0100}
    assert words_for(point, False, {}) == {(H, 0x10): 0x0200}
    mapping = make_mapping({"relay": RELAY | {"name": "Relay"}})
    image = initial_image(mapping, mapping.points())
    assert decode(mapping.points()["relay"], image) in (True, False)


SENSOR: dict[str, Any] = {"address": 0, "type": "s16"}


@pytest.mark.parametrize(
    ("fields", "word", "expected"),
    [
        (SENSOR | {"clamp": {"min": 0, "max": 100}}, 50, 50),
        (SENSOR | {"clamp": {"min": 0, "max": 100}}, 0xFFFF, 0),  # -1 -> min
        (SENSOR | {"clamp": {"min": 0, "max": 100}}, 101, 100),
        (SENSOR | {"clamp": {"min": 5}}, 4, 5),
        (SENSOR | {"clamp": {"max": -5}}, 0, -5),
        # scale and offset first: raw 300 * 0.1 - 10 = 20.0, above max 15.5
        (SENSOR | {"scale": 0.1, "offset": -10, "clamp": {"max": 15.5}}, 300, 15.5),
        (SENSOR | {"scale": 0.1, "offset": -10, "clamp": {"max": 15.5}}, 250, 15.0),
        # clamped before rounding: 15.55 has more decimals than the value's one
        (SENSOR | {"scale": 0.1, "clamp": {"max": 15.55}}, 200, 15.6),
        (SENSOR | {"zero_suppress": 2}, 2, 0),  # at most: `abs(val) <= zero_suppress`
        (SENSOR | {"zero_suppress": 2}, 0xFFFE, 0),  # -2
        (SENSOR | {"zero_suppress": 2}, 3, 3),
        (SENSOR | {"zero_suppress": 2}, 0xFFFD, -3),
        (SENSOR | {"scale": 0.01, "zero_suppress": 0.05}, 5, 0.0),
        (SENSOR | {"scale": 0.01, "zero_suppress": 0.05}, 6, 0.06),
        # the clamp comes first: a reading clamped up to min 1 is not suppressed by 0.5
        (SENSOR | {"clamp": {"min": 1}, "zero_suppress": 0.5}, 0, 1),
        # and a limit within zero_suppress is suppressed after it, as Home Assistant does
        (SENSOR | {"clamp": {"min": -1}, "zero_suppress": 1}, 0xFFF0, 0),
        (SENSOR | {"clamp": {"min": 0}, "sentinels": {0x7FFF: "open"}}, 0x7FFF, None),
        (SENSOR | {"type": "f32", "clamp": {"max": 3}}, 0x4048, 3.0),  # 3.14 -> 3
        (SENSOR | {"type": "f32", "zero_suppress": 0.01}, 0x3C23, 0.0),  # 0.01, at most 0.01
        (SENSOR | {"type": "f32", "scale": 10, "zero_suppress": 0.01}, 0x3C23, 0.1),
    ],
)
def test_a_reading_is_clamped_then_zero_suppressed(
    fields: dict[str, Any], word: int, expected: object
) -> None:
    point = make_point("reading", **fields)
    image = {(H, 0): word, (H, 1): 0xD70A if fields.get("type") == "f32" else 0}
    assert decode(point, image) == expected


def test_clamp_and_zero_suppress_leave_writes_and_ranges_alone() -> None:
    """A writable number is written as asked, so it is not shaped when read either."""
    with pytest.raises(ValidationError, match="read-only number"):
        make_point("setting", **SENSOR, access="rw", clamp={"max": 5})
    with pytest.raises(ValidationError, match="read-only number"):
        make_point("flag", address=0, bit=3, zero_suppress=1)
    with pytest.raises(ValidationError, match=r"min 5\.0 is above max 1\.0"):
        make_point("reading", **SENSOR, clamp={"min": 5, "max": 1})
    with pytest.raises(ValidationError, match="give min, max or both"):
        make_point("reading", **SENSOR, clamp={})
    with pytest.raises(ValidationError, match="greater than or equal to 0"):
        make_point("reading", **SENSOR, zero_suppress=-1)
