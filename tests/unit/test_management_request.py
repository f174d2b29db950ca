"""Management requests: validation, unit ranges, transactions and the response shape."""

from __future__ import annotations

import json

import pytest

from bridge.core.management_request import (
    REQUESTS,
    DeviceIdentify,
    DeviceRead,
    DeviceScan,
    DeviceWrite,
    HealthCheck,
    MappingReload,
    RequestError,
    parse_request,
    parse_units,
    response,
)


@pytest.mark.parametrize(
    ("command", "payload", "expected"),
    [
        ("device/read", b'{"unit": 3, "address": 16}', DeviceRead(unit=3, address=16)),
        (
            "device/read",
            b'{"device": "pump", "address": 0, "count": 2, "table": "input"}',
            DeviceRead(device="pump", address=0, count=2, table="input"),
        ),
        (
            "device/write",
            b'{"bus": "rs485", "unit": 1, "address": 5, "values": [1, 2], "transaction": 7}',
            DeviceWrite(bus="rs485", unit=1, address=5, values=[1, 2], transaction=7),
        ),
        ("device/scan", b"", DeviceScan()),
        ("device/scan", b'{"timeout": "100ms"}', DeviceScan(timeout=0.1)),
        ("mapping/reload", b"{}", MappingReload()),
        (
            "mapping/reload",
            b'{"devices": ["pump"], "mapping": "new.yaml"}',
            MappingReload(devices=["pump"], mapping="new.yaml"),
        ),
        ("mapping/reload", b'{"rewalk": true}', MappingReload(rewalk=True)),
        (
            "mapping/reload",
            b'{"rewalk": true, "devices": ["inverter"]}',
            MappingReload(devices=["inverter"], rewalk=True),
        ),
        ("health_check", b"  ", HealthCheck()),
    ],
)
def test_valid_requests(command: str, payload: bytes, expected: object) -> None:
    assert parse_request(command, payload) == expected


@pytest.mark.parametrize(
    ("command", "payload", "words", "transaction"),
    [
        ("device/read", b"[1]", "JSON object", None),
        ("device/read", b"\xff\xfe", "not JSON", None),
        ("device/read", b'{"unit": 1, "transaction": "a"}', "address", "a"),
        ("device/read", b'{"address": 1, "transaction": 5}', "device, or a unit", 5),
        ("device/read", b'{"unit": 1, "address": -1}', "address", None),
        ("device/read", b'{"unit": 256, "address": 1}', "unit", None),
        ("device/read", b'{"unit": 1, "address": 1, "timeout": 9}', "timeout", None),
        ("device/read", b'{"unit": 1, "address": 1, "table": "x"}', "table", None),
        ("device/write", b'{"unit": 1, "address": 1, "values": []}', "values", None),
        (
            "device/write",
            b'{"unit": 1, "address": 1, "table": "input", "values": [1]}',
            "table",
            None,
        ),
        ("device/scan", b'{"timeout": 0}', "timeout", None),
        ("device/scan", b'{"bogus": 1, "transaction": true}', "bogus", None),
        ("mapping/reload", b'{"mapping": "x.yaml"}', "exactly one device", None),
        (
            "mapping/reload",
            b'{"devices": ["pv"], "mapping": "x.yaml", "rewalk": true}',
            "rewalk: a SunSpec device's mapping is built",
            None,
        ),
        ("mapping/reload", b'{"rewalk": "maybe"}', "rewalk", None),
        ("reboot", b'{"transaction": "r"}', "unknown request 'reboot'", "r"),
    ],
)
def test_invalid_requests_name_the_problem_and_keep_the_transaction(
    command: str, payload: bytes, words: str, transaction: object
) -> None:
    with pytest.raises(RequestError) as caught:
        parse_request(command, payload)
    assert words in str(caught.value)
    assert caught.value.transaction == transaction


@pytest.mark.parametrize(
    ("spec", "units"),
    [
        ("1-247", list(range(1, 248))),
        ("5", [5]),
        ("1-3, 10,2", [1, 2, 3, 10]),
        ([7, 3, 3], [3, 7]),
    ],
)
def test_unit_ranges(spec: str | list[int], units: list[int]) -> None:
    assert parse_units(spec) == units


@pytest.mark.parametrize("spec", ["0-3", "240-248", "", "a", "3-", [], [0], [248]])
def test_bad_unit_ranges(spec: str | list[int]) -> None:
    with pytest.raises(RequestError, match="units"):
        parse_units(spec)


def test_responses() -> None:
    assert json.loads(response({"x": 1}, transaction="t")) == {
        "status": "ok",
        "data": {"x": 1},
        "error": None,
        "transaction": "t",
    }
    assert json.loads(response(error="no", transaction=3)) == {
        "status": "error",
        "data": {},
        "error": "no",
        "transaction": 3,
    }


def test_every_request_has_a_model() -> None:
    assert set(REQUESTS) == {
        "device/read",
        "device/write",
        "device/scan",
        "device/identify",
        "mapping/reload",
        "health_check",
    }


def test_identify_takes_a_unit_or_units() -> None:
    one = parse_request("device/identify", b'{"unit": 3}')
    assert isinstance(one, DeviceIdentify) and one.unit_ids() == [3]
    many = parse_request("device/identify", b'{"units": "5,1-2", "timeout": 0.2}')
    assert isinstance(many, DeviceIdentify) and many.unit_ids() == [1, 2, 5]
    for payload, words in [
        (b'{"unit": 3, "units": [1]}', "give unit or units"),
        (b"{}", "give unit or units"),
        (b'{"unit": 248}', "unit: Input should be less than or equal to 247"),
        (b'{"units": "1-248"}', "1..247"),
        (b'{"units": [1], "timeout": 6}', "timeout"),
    ]:
        with pytest.raises(RequestError, match=words):
            _unit_ids(payload)


def _unit_ids(payload: bytes) -> list[int]:
    parsed = parse_request("device/identify", payload)
    assert isinstance(parsed, DeviceIdentify)
    return parsed.unit_ids()
