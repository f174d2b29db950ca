"""Whose guards apply to a raw request to one unit, on serial and TCP buses (a table)."""

from __future__ import annotations

import re
from collections.abc import Callable

import pytest

from bridge.core.entity import Table
from bridge.core.guard import WHOLE, Guard
from bridge.core.management_request import RequestError
from bridge.core.reach import Neighbour, check_raw_read, check_raw_write, reach_of
from bridge.core.request import Read, Write

H = Table.HOLDING


def guarded(dangerous: int, secret: int) -> Guard:
    return Guard(dangerous={(H, dangerous): WHOLE}, hidden=frozenset({(H, secret)}))


A = Neighbour("a", 1, guarded(10, 20))  # a: register 10 dangerous, 20 secret
B = Neighbour("b", 2, guarded(11, 21))
C = Neighbour("c", 255, guarded(13, 23))  # configured at the TCP alias
A_ALLOWS = Neighbour("a", 1, A.guard, allow_dangerous_writes=True)
B_ALLOWS = Neighbour("b", 2, B.guard, allow_dangerous_writes=True)
AB = (A, B)


@pytest.mark.parametrize(
    ("tcp", "unit", "devices", "reached", "configured"),
    [
        (False, 1, AB, "a", True),
        (False, 2, AB, "b", True),
        (False, 5, AB, "", False),  # a serial unit is one device: unknown here
        (False, 0, AB, "a b", False),  # broadcast: every device executes it
        (True, 1, AB, "a", True),
        (True, 2, AB, "b", True),
        (True, 5, AB, "a b", False),  # any device may answer an unconfigured unit
        (True, 255, AB, "a b", False),
        (True, 0, AB, "a b", False),
        (True, 255, (A, B, C), "a b c", True),  # an alias reaches everyone, configured or not
        (True, 1, (A, B, C), "a", True),
        (True, 5, (), "", False),
    ],
)
def test_who_may_answer_a_unit(
    tcp: bool, unit: int, devices: tuple[Neighbour, ...], reached: str, configured: bool
) -> None:
    reach = reach_of("bus", unit, devices, tcp=tcp)
    assert " ".join(d.device for d in reach.devices) == reached
    assert reach.configured is configured
    assert reach.indirect is any(d.unit != unit for d in reach.devices)


def refusal(action: Callable[[], None]) -> tuple[bool, str]:
    """(refused as an unconfigured unit, the devices named as guarding) of a check."""
    try:
        action()
    except RequestError as exc:
        text = str(exc)
        unconfigured = "no device is configured at it" in text
        names = re.findall(r"(?:^|; |: )(\w+): addresses", text)
        return unconfigured, " ".join(names)
    return False, ""


@pytest.mark.parametrize(
    ("tcp", "unit", "devices", "raw_units", "address", "count", "expected"),
    [
        (False, 1, AB, (), 10, 1, (False, "a")),
        (False, 1, AB, (), 11, 1, (False, "")),  # b's register, but b is not unit 1
        (False, 1, (A_ALLOWS, B), (), 10, 1, (False, "")),
        (False, 5, AB, (), 10, 2, (False, "")),  # serial: nobody the config knows
        (False, 0, AB, (), 11, 1, (False, "b")),  # broadcast
        (True, 1, AB, (), 11, 1, (False, "")),
        (True, 1, AB, (), 10, 2, (False, "a")),
        (True, 1, (A_ALLOWS, B), (), 10, 1, (False, "")),
        (True, 5, AB, (), 12, 1, (True, "")),  # harmless, but who answers is not known
        (True, 5, AB, (5,), 12, 1, (False, "")),
        (True, 5, AB, (5,), 11, 1, (False, "b")),
        (True, 5, AB, (), 10, 2, (True, "a b")),  # both reasons at once
        (True, 255, AB, (), 12, 1, (True, "")),
        (True, 255, AB, (255,), 10, 2, (False, "a b")),
        (True, 255, (A_ALLOWS, B), (255,), 10, 2, (False, "b")),
        (True, 255, (A_ALLOWS, B_ALLOWS), (255,), 10, 2, (False, "")),
        (True, 0, AB, (), 12, 1, (True, "")),
        (True, 0, AB, (0,), 10, 1, (False, "a")),
        (True, 255, (A, B, C), (), 12, 1, (False, "")),  # c is configured at 255
        (True, 255, (A, B, C), (), 10, 4, (False, "a b c")),
        (True, 5, (), (), 12, 1, (True, "")),
        (True, 5, (), (5,), 10, 1, (False, "")),
    ],
)
def test_a_raw_write_keeps_the_guard_of_every_device_that_may_answer(
    tcp: bool,
    unit: int,
    devices: tuple[Neighbour, ...],
    raw_units: tuple[int, ...],
    address: int,
    count: int,
    expected: tuple[bool, str],
) -> None:
    reach = reach_of("bus", unit, devices, tcp=tcp)
    write = Write(16, H, address, (2,) * count)
    assert refusal(lambda: check_raw_write(reach, write, raw_units)) == expected


@pytest.mark.parametrize(
    ("tcp", "unit", "devices", "address", "count", "allowed", "expected"),
    [
        (False, 1, AB, 20, 1, False, "a"),
        (False, 1, AB, 21, 1, False, ""),
        (False, 1, AB, 20, 1, True, ""),
        (False, 5, AB, 20, 2, False, ""),  # serial: nobody the config knows
        (True, 1, AB, 20, 2, False, "a"),
        (True, 5, AB, 21, 1, False, "b"),  # read, with every device's secrets hidden
        (True, 5, AB, 21, 1, True, ""),
        (True, 5, AB, 22, 1, False, ""),  # an unconfigured unit is read
        (True, 255, AB, 20, 2, False, "a b"),
        (True, 255, (A, B, C), 20, 4, False, "a b c"),
    ],
)
def test_a_raw_read_keeps_the_secrets_of_every_device_that_may_answer(
    tcp: bool,
    unit: int,
    devices: tuple[Neighbour, ...],
    address: int,
    count: int,
    allowed: bool,
    expected: str,
) -> None:
    reach = reach_of("bus", unit, devices, tcp=tcp)
    read = Read(H, address, count)
    checked = refusal(lambda: check_raw_read(reach, read, secrets_allowed=allowed))
    assert checked == (False, expected)


def test_the_refusals_say_why_and_what_to_configure() -> None:
    def message(action: Callable[[], None]) -> str:
        with pytest.raises(RequestError) as caught:
            action()
        return str(caught.value)

    own = reach_of("rs485", 1, AB, tcp=False)
    assert message(lambda: check_raw_write(own, Write(6, H, 10, (1,)), ())) == (
        "a: addresses 10 are guarded (dangerous); "
        "set allow_dangerous_writes: true for device a to permit it"
    )
    alias = reach_of("tcp1", 255, AB, tcp=True)
    assert message(lambda: check_raw_write(alias, Write(16, H, 10, (1, 1)), ())) == (
        "unit 255: no device is configured at it on TCP bus tcp1, where a gateway or a "
        "device that ignores the unit id may answer it (a, b); to write to it raw, add "
        "raw_units: [255] to bus tcp1; "
        "unit 255 on bus tcp1 may reach a, b (on a TCP bus a gateway, or a device that "
        "ignores the unit id, answers it): a: addresses 10; b: addresses 11 are guarded "
        "(dangerous); set allow_dangerous_writes: true for devices a, b to permit it"
    )
    empty = reach_of("tcp1", 5, (), tcp=True)
    assert message(lambda: check_raw_write(empty, Write(6, H, 10, (1,)), ())) == (
        "unit 5: no device is configured at it on TCP bus tcp1, where a gateway or a "
        "device that ignores the unit id may answer it; to write to it raw, add "
        "raw_units: [5] to bus tcp1"
    )
    broadcast = reach_of("rs485", 0, AB, tcp=False)
    assert message(lambda: check_raw_read(broadcast, Read(H, 20, 1), secrets_allowed=False)) == (
        "unit 0 on bus rs485 may reach a, b (it is broadcast, every device on the line "
        "executes it): a: addresses 20 hold secret or write-only values; raw reads of them "
        "need bridge.allow_raw_writes: true"
    )
    many = Neighbour("m", 1, Guard(dangerous={(H, a): WHOLE for a in range(10)}))
    listed = message(
        lambda: check_raw_write(reach_of("b", 1, [many], tcp=False), Write(16, H, 0, (0,) * 10), ())
    )
    assert listed.startswith("m: addresses 0, 1, 2, 3, 4, 5, 6, 7 and 2 more are guarded")
