"""Bus specs on the command line (tcp://, rtu-over-tcp://, rtu://, ascii://) and bus ids."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.cli.bus_spec import bus_from_config, parse_bus_spec, select_bus
from bridge.config import SerialBus, TcpBus
from bridge.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
SITE = ROOT / "examples" / "site.yaml"  # an RS-485 line and a gateway


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("tcp://127.0.0.1", TcpBus(id="bus", transport="tcp", host="127.0.0.1")),
        (
            "tcp://plc.local:1502?timeout=300ms",
            TcpBus(id="bus", transport="tcp", host="plc.local", tcp_port=1502, timeout=0.3),
        ),
        (
            "rtu-over-tcp://[::1]:4001/",
            TcpBus(id="bus", transport="rtu-over-tcp", host="::1", tcp_port=4001),
        ),
        ("rtu:///dev/ttyUSB0", SerialBus(id="bus", transport="rtu", port="/dev/ttyUSB0")),
        (
            "rtu:///dev/ttyUSB0?baudrate=19200&parity=e&stopbits=2&bytesize=7&timeout=0.5",
            SerialBus(
                id="bus",
                transport="rtu",
                port="/dev/ttyUSB0",
                baudrate=19200,
                parity="E",
                stopbits=2,
                bytesize=7,
                timeout=0.5,
            ),
        ),
        (
            "ascii:///dev/ttyS1?parity=O",
            SerialBus(id="bus", transport="ascii", port="/dev/ttyS1", parity="O"),
        ),
        ("rtu://COM3", SerialBus(id="bus", transport="rtu", port="COM3")),
    ],
)
def test_specs(text: str, expected: SerialBus | TcpBus) -> None:
    assert parse_bus_spec(text) == expected


@pytest.mark.parametrize(
    ("text", "issues"),
    [
        ("udp://host", ["use one of: tcp://HOST[:PORT], rtu-over-tcp://HOST[:PORT], rtu:///dev"]),
        ("/dev/ttyUSB0", ["use one of: tcp://"]),
        ("tcp://", ["host: missing; use tcp://HOST[:PORT]"]),
        ("tcp://host:abc", ["Port could not be cast to integer value as 'abc'"]),
        ("tcp://host:0", ["tcp_port: Input should be greater than or equal to 1"]),
        ("tcp://host/unit/1", ["/unit/1: a TCP bus has no path; use tcp://HOST[:PORT]"]),
        ("tcp://host?baudrate=9600", ["baudrate: unknown setting (known: timeout)"]),
        ("rtu://", ["port: missing; use rtu:///dev/ttyUSB0 (three slashes)"]),
        (
            "rtu:///dev/ttyUSB0?baudrate=fast&parity=X&stopbits=3",
            [
                "baudrate: Input should be a valid integer, unable to parse string as an integer",
                "parity: Input should be 'N', 'E' or 'O'",
                "stopbits: Input should be 1 or 2",
            ],
        ),
        (
            "rtu:///dev/ttyUSB0?speed=9600&parity=E&parity=N",
            [
                "speed: unknown setting (known: baudrate, parity, stopbits, bytesize, timeout)",
                "parity: given twice",
            ],
        ),
        ("rtu:///dev/ttyUSB0?parity", ["?parity: write settings as name=value&name=value"]),
        ("rtu:///dev/ttyUSB0?timeout=soon", ["timeout: invalid duration 'soon'"]),
        ("rtu:///dev/ttyUSB0#x", ["#x: a bus spec has no fragment"]),
    ],
)
def test_mistakes_name_the_bad_part(text: str, issues: list[str]) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_bus_spec(text)
    assert caught.value.source == f"bus {text!r}"
    assert len(caught.value.issues) == len(issues)
    for issue, expected in zip(caught.value.issues, issues, strict=True):
        assert issue.startswith(expected)


def test_a_bus_from_a_config_file() -> None:
    bus = bus_from_config(SITE, "rs485")
    assert isinstance(bus, SerialBus)
    assert select_bus("rs485", SITE) == bus
    with pytest.raises(ConfigError, match=r"buses: no bus 'nope' \(have \['gateway', 'rs485'\]\)"):
        bus_from_config(SITE, "nope")


def test_a_spec_wins_over_the_config_file() -> None:
    assert select_bus("tcp://10.0.0.1", SITE) == TcpBus(id="bus", transport="tcp", host="10.0.0.1")


def test_a_bus_id_needs_a_config_file() -> None:
    with pytest.raises(ConfigError, match="a bus id needs -c CONFIG; or give a spec: tcp://"):
        select_bus("rs485", None)


def test_a_bad_config_file_is_reported_as_such(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        select_bus("rs485", tmp_path / "missing.yaml")
