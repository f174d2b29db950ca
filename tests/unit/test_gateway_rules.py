"""The gateway's pure decisions (bridge/core/gateway.py): which requests are served, which
exception code answers a failure, when the image answers a read, which bytes end a
connection, and the per-client counters."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.config import load_config_data
from bridge.core.entity import Table
from bridge.core.gateway import (
    ClientBook,
    Code,
    ProxyRequest,
    cached_words,
    check_request,
    code_for,
    header_problem,
)
from bridge.core.request import Read, Write
from bridge.errors import (
    BridgeError,
    BusError,
    CommandExpiredError,
    CommandRejectedError,
    ConfigError,
    DeviceExceptionError,
    DeviceTimeoutError,
    FrameError,
    PartialWriteError,
    ValueRejectedError,
    WriteForbiddenError,
)

H, C = Table.HOLDING, Table.COIL


@pytest.mark.parametrize(
    ("request_", "code"),
    [
        (ProxyRequest(1, 3, 0, 125), None),
        (ProxyRequest(1, 4, 0, 126), Code.ILLEGAL_VALUE),
        (ProxyRequest(1, 3, 0, 0), Code.ILLEGAL_VALUE),
        (ProxyRequest(1, 1, 0, 2000), None),
        (ProxyRequest(1, 2, 0, 2001), Code.ILLEGAL_VALUE),
        (ProxyRequest(1, 3, 0xFFFF, 1), None),
        (ProxyRequest(1, 3, 0xFFFF, 2), Code.ILLEGAL_ADDRESS),
        (ProxyRequest(1, 3, -1, 1), Code.ILLEGAL_ADDRESS),
        (ProxyRequest(1, 8, 0, 1), Code.ILLEGAL_FUNCTION),
        (ProxyRequest(1, 23, 0, 1), Code.ILLEGAL_FUNCTION),
        (ProxyRequest(1, 6, 10, 1, (0xFFFF,)), None),
        (ProxyRequest(1, 6, 10, 1, (0x10000,)), Code.ILLEGAL_VALUE),
        (ProxyRequest(1, 6, 10, 2, (1, 2)), Code.ILLEGAL_VALUE),
        (ProxyRequest(1, 5, 10, 1, (1,)), None),
        (ProxyRequest(1, 5, 10, 1, (2,)), Code.ILLEGAL_VALUE),
        (ProxyRequest(1, 15, 10, 3, (1, 0, 1)), None),
        (ProxyRequest(1, 15, 10, 3, (1, 0)), Code.ILLEGAL_VALUE),
        (ProxyRequest(1, 16, 10, 123, (0,) * 123), None),
        (ProxyRequest(1, 16, 10, 124, (0,) * 124), Code.ILLEGAL_VALUE),
        (ProxyRequest(1, 15, 0, 1969, (0,) * 1969), Code.ILLEGAL_VALUE),
        (ProxyRequest(1, 16, 0xFFFF, 2, (0, 0)), Code.ILLEGAL_ADDRESS),
    ],
)
def test_which_requests_are_served(request_: ProxyRequest, code: Code | None) -> None:
    assert check_request(request_) == code


def test_a_request_names_its_table_and_its_bus_request() -> None:
    assert ProxyRequest(1, 4, 7, 2).read() == Read(Table.INPUT, 7, 2)
    assert not ProxyRequest(1, 2, 7, 2).is_write
    assert ProxyRequest(1, 5, 7, 1, (1,)).write(0x00FF) == Write(5, C, 7, (0x00FF,))
    assert ProxyRequest(1, 5, 7, 1, (0,)).write(0x00FF) == Write(5, C, 7, (0,))
    assert ProxyRequest(1, 16, 7, 2, (3, 4)).write(0xFF00) == Write(16, H, 7, (3, 4))


@pytest.mark.parametrize(
    ("error", "code"),
    [
        (DeviceExceptionError(2, "illegal data address", "refused"), 2),
        (DeviceExceptionError(0x0C, "vendor", "fail"), 0x0C),
        (DeviceTimeoutError("unit 3 did not answer"), Code.TARGET_NO_RESPONSE),
        (FrameError("CRC"), Code.TARGET_NO_RESPONSE),
        (PartialWriteError(1, 2, restored=True, cause=FrameError("x")), Code.TARGET_NO_RESPONSE),
        (BusError("port gone"), Code.PATH_UNAVAILABLE),
        (CommandExpiredError("busy"), Code.BUSY),
        # a refused write by its type, whatever its words say
        (WriteForbiddenError("ramp is read-only"), Code.ILLEGAL_FUNCTION),
        (WriteForbiddenError("any wording at all"), Code.ILLEGAL_FUNCTION),
        (ValueRejectedError("value 201 above the maximum 200"), Code.ILLEGAL_VALUE),
        (ValueRejectedError("mode: 'locked' is not one of 'manual', 'auto'"), 3),
        (ValueRejectedError("x is a guarded write, read-only, EEPROM, no such"), 3),
        (CommandRejectedError({"x": ValueRejectedError("201: above 200")}, ["x"]), 3),
        (CommandRejectedError({"x": WriteForbiddenError("201: above 200")}, ["x", "y"]), 1),
        (
            CommandRejectedError(
                {"x": ValueRejectedError("201: above 200"), "y": WriteForbiddenError("too soon")},
                ["x", "y"],
            ),
            Code.ILLEGAL_FUNCTION,  # fixing the value would not let y through
        ),
        (BridgeError("anything else"), Code.DEVICE_FAILURE),
    ],
)
def test_the_exception_code_of_each_failure(error: BridgeError, code: int) -> None:
    assert code_for(error) == code


def test_a_read_is_answered_from_the_image_only_when_every_word_is_young_enough() -> None:
    image = {(H, 10): 1, (H, 11): 2, (H, 12): 3}
    read_at = {(H, 10): 100.0, (H, 11): 100.5, (H, 12): 98.0}
    assert cached_words(Read(H, 10, 2), image, read_at, 101.0, 1.0) == (1, 2)
    assert cached_words(Read(H, 10, 3), image, read_at, 101.0, 1.0) is None  # 12 too old
    assert cached_words(Read(H, 10, 3), image, read_at, 101.0, 3.0) == (1, 2, 3)
    assert cached_words(Read(H, 10, 2), image, read_at, 101.0, 0.0) is None  # off
    assert cached_words(Read(H, 13, 1), image, read_at | {(H, 13): 101.0}, 101.0, 5) is None
    assert cached_words(Read(Table.INPUT, 10, 1), image, read_at, 101.0, 5.0) is None


@pytest.mark.parametrize(
    ("data", "problem"),
    [
        (b"", None),
        (b"\x00\x01\x00\x00\x00", None),  # too few to tell
        (b"\x00\x01\x00\x00\x00\x06\x01", None),
        (b"\x00\x01\x00\x00\x00\x02\x01", None),
        (b"\x00\x01\x00\x00\x00\xfe\x01", None),
        (b"\x00\x01\x00\x07\x00\x06\x01", "protocol id 7, not 0 (Modbus)"),
        (b"\x00\x01\x00\x00\x00\x01\x01", "length 1: a Modbus TCP frame carries 2..254"),
        (b"\x00\x01\x00\x00\x00\xff\x01", "length 255: a Modbus TCP frame carries 2..254"),
    ],
)
def test_bytes_that_cannot_start_a_frame(data: bytes, problem: str | None) -> None:
    assert header_problem(data) == problem


def test_clients_are_counted_by_address_and_the_oldest_idle_forgotten() -> None:
    book = ClientBook(kept=2)
    book.of("10.0.0.1").served += 2
    busy = book.of("10.0.0.2")
    busy.queued = 1
    book.of("10.0.0.1").cached += 1  # the most recent now
    book.of("10.0.0.3").refused += 1  # 10.0.0.2 is busy: 10.0.0.1 goes
    assert list(book.clients) == ["10.0.0.2", "10.0.0.3"]
    assert book.totals().as_dict() | {"queued": 0} == {
        "connections": 0,
        "rejected": 0,
        "dropped": 0,
        "requests": 0,
        "served": 0,
        "cached": 0,
        "refused": 1,
        "failed": 0,
        "queued": 0,
        "delayed": 0,
        "busy": 0,
    }
    everyone_busy = ClientBook(kept=1)
    everyone_busy.of("a").queued = 1
    everyone_busy.of("b").queued = 1
    assert list(everyone_busy.clients) == ["a", "b"]  # never forgets one still waiting


def test_a_bad_gateway_config_names_the_field() -> None:
    data = {
        "bridge": {
            "gateway": {
                "enabled": True,
                "units": {
                    1: "pump",
                    2: "nope",
                    3: "spare",
                    4: {"bus": "nowhere", "unit": 1},
                    5: {"bus": "rs485", "unit": 250},
                },
            }
        },
        "buses": [{"id": "rs485", "transport": "rtu", "port": "/dev/null"}],
        "devices": [
            {"id": "pump", "bus": "rs485", "unit": 1, "mapping": "nastec_vasco"},
            {"id": "spare", "bus": "rs485", "unit": 2, "mapping": "nastec_vasco", "enabled": False},
        ],
    }
    with pytest.raises(ConfigError) as caught:
        load_config_data(data, Path("gateway.yaml"))
    assert list(caught.value.issues) == [
        "bridge.gateway.units.2: no device 'nope' (have ['pump', 'spare'])",
        "bridge.gateway.units.3: device 'spare' is disabled",
        "bridge.gateway.units.4.bus: no bus 'nowhere' (have ['rs485'])",
        "bridge.gateway.units.5.unit: serial lines address units 1..247",
    ]
    data["bridge"] = {"gateway": {"enabled": True}}
    with pytest.raises(ConfigError, match=r"bridge.gateway.units: name the units"):
        load_config_data(data, Path("gateway.yaml"))
    del data["bridge"]
    assert not load_config_data(data, Path("gateway.yaml")).config.bridge.gateway.enabled
