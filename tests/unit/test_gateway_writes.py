"""What a gateway master's write of words means as a command (bridge/core/gateway_writes.py),
on the soft starter's own mapping: every entity written whole, words that are a value the
entity is set to by exactly those words, a button's press word, raw words apart."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.codec import COMMAND_PRESS
from bridge.core.gateway import Code, ProxyRequest
from bridge.core.gateway_writes import GatewayRefusalError, items_of
from bridge.core.mapping import load_mapping
from tests.factory import make_mapping
from tests.unit import test_shared_register as shared_register

POINTS = load_mapping(Path(__file__).parents[2] / "mappings/soft_starter.yaml").points()
UNIT = 3


def write(address: int, *values: int) -> ProxyRequest:
    function = 6 if len(values) == 1 else 16
    return ProxyRequest(UNIT, function, address, len(values), values)


def test_a_register_of_an_entity_is_its_value() -> None:
    assert items_of(POINTS.values(), {}, write(4102, 12)) == {"soft_stop_time": 12}


def test_registers_of_several_entities_are_one_command() -> None:
    items = items_of(POINTS.values(), {}, write(4101, 8, 12))
    assert items == {"soft_start_time": 8, "soft_stop_time": 12}


def test_a_button_is_pressed_by_its_press_word_only() -> None:
    assert items_of(POINTS.values(), {}, write(4142, 0)) == {"fault_reset": COMMAND_PRESS}
    with pytest.raises(GatewayRefusalError) as refused:
        items_of(POINTS.values(), {}, write(4142, 5))
    assert refused.value.code == Code.ILLEGAL_VALUE


def test_registers_no_entity_writes_are_a_raw_write() -> None:
    assert items_of(POINTS.values(), {}, write(5000, 1, 2)) is None


@pytest.mark.parametrize(
    ("request_", "code"),
    [
        (write(4138, 0), Code.ILLEGAL_VALUE),  # one of a u32's two registers
        (write(4117, 7), Code.ILLEGAL_VALUE),  # an on/off register: the bridge writes 1
        (write(4130, 5, 5), Code.ILLEGAL_FUNCTION),  # an entity's word beside a raw one
    ],
    ids=["part-of-an-entity", "not-a-value-it-takes", "entity-beside-raw"],
)
def test_what_a_command_could_not_write_is_refused_whole(
    request_: ProxyRequest, code: Code
) -> None:
    with pytest.raises(GatewayRefusalError) as refused:
        items_of(POINTS.values(), {}, request_)
    assert refused.value.code == code


# --- a register several writable entities share ---------------------------------------------

SHARED = shared_register.SHARED.points({})


@pytest.mark.parametrize(
    ("request_", "items"),
    [
        (write(10, 1), {"mode_raw": 1, "mode": "backup", "backup": True, "bit_0": True}),
        (write(10, 2), {"mode_raw": 2, "mode": "feed_in", "bit_0": False}),  # backup: no 2
        (write(10, 7), {"mode_raw": 7, "bit_0": True}),  # no option 7
        (write(30, 5), {"energy_high": 5}),  # the u32's high word, as its raw word
        (write(30, 0, 5), {"energy": 5, "energy_high": 0, "energy_low": 5}),
        (write(20, 0x0400), {"breaker_raw": 0x0400, "breaker_command": "test"}),  # guarded later
    ],
)
def test_every_entity_that_takes_the_words_is_in_the_command(
    request_: ProxyRequest, items: dict[str, object]
) -> None:
    assert items_of(SHARED.values(), {}, request_) == items


def test_words_no_entity_of_the_register_takes_are_refused() -> None:
    points = make_mapping(
        {
            "mode": {"name": "Mode", "address": 1, "access": "rw", "enum": {0: "a", 1: "b"}},
            "on": {"name": "On", "address": 1, "type": "bool", "access": "rw"},
        }
    ).points({})
    assert items_of(points.values(), {}, write(1, 1)) == {"mode": "b", "on": True}
    with pytest.raises(GatewayRefusalError) as refused:
        items_of(points.values(), {}, write(1, 9))
    assert refused.value.code == Code.ILLEGAL_VALUE
