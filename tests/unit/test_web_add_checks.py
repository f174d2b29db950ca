"""The add flow's checks that need no bus: the library search and a new bus's settings."""

from __future__ import annotations

from http import HTTPStatus
from typing import Any

import pytest

from bridge.config import SerialBus, TcpBus
from bridge.web.library import MAX_QUERY, MAX_RESULTS, QueryError, search, shipped_rows
from bridge.web.new_bus import AskError, new_bus


@pytest.mark.parametrize(
    "query", ["", "eastron", "EASTRON sdm630", "meter", "inverter huawei", "nastec mida", "zzz"]
)
def test_a_search_finds_the_rows_holding_every_word(query: str) -> None:
    rows = shipped_rows()
    found = search(rows, query)
    words = query.lower().split()

    def holds(row: dict[str, Any]) -> bool:
        text = " ".join([row["mapping"], row["manufacturer"], row["model"], row["category"]])
        return all(w in (text + " " + " ".join(row["aliases"])).lower() for w in words)

    expected = [row for row in rows if holds(row)]
    assert found["total"] == len(expected)
    assert found["mappings"] == expected[:MAX_RESULTS]


def test_a_search_is_bounded() -> None:
    with pytest.raises(QueryError, match="characters"):
        search(shipped_rows(), "x" * (MAX_QUERY + 1))
    with pytest.raises(QueryError, match="words"):
        search(shipped_rows(), " ".join("abcdefghi"))


def test_new_buses_as_the_config_has_them() -> None:
    serial = new_bus({"transport": "rtu", "port": "/dev/ttyUSB0", "baudrate": 19200, "parity": "E"})
    assert isinstance(serial, SerialBus) and serial.id == "new" and serial.baudrate == 19200
    tcp = new_bus({"transport": "tcp", "host": "10.0.0.7", "tcp_port": 1502, "timeout": 0.5})
    assert isinstance(tcp, TcpBus) and (tcp.host, tcp.tcp_port, tcp.timeout) == (
        "10.0.0.7",
        1502,
        0.5,
    )


@pytest.mark.parametrize(
    ("given", "said"),
    [
        ({"transport": "rtu", "port": "/dev/ttyUSB0", "id": "x"}, "unknown fields ['id']"),
        ({"transport": "rtu", "port": "/dev/" + "x" * 300}, "bus.port: at most 255"),
        ({"transport": "tcp", "host": "h" * 300}, "bus.host: at most 255"),
        ({"transport": "tcp", "host": "h", "timeout": True}, "bus.timeout: seconds"),
        ({"transport": "tcp", "host": "h", "timeout": "1"}, "bus.timeout: seconds"),
        ({"transport": "tcp", "host": "h", "timeout": 0}, "bus.timeout: 0 to 5"),
        ({"transport": "tcp", "host": "h", "timeout": 6}, "bus.timeout: 0 to 5"),
        ({"transport": "rtu", "port": "/dev/ttyUSB0", "baudrate": 10}, "baudrate"),
        ({"transport": "rtu", "port": "/dev/ttyUSB0", "parity": "X"}, "parity"),
        ({"transport": "rtu"}, "port"),
        ({"transport": "carrier-pigeon", "host": "h"}, "transport"),
        ({"transport": "tcp", "host": "h", "tcp_port": 0}, "tcp_port"),
    ],
)
def test_a_new_bus_refused_names_its_field(given: dict[str, Any], said: str) -> None:
    with pytest.raises(AskError, match=None) as refused:
        new_bus(given)
    assert refused.value.status == HTTPStatus.BAD_REQUEST
    assert said in str(refused.value), str(refused.value)
