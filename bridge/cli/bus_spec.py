"""A bus named on the command line, for commissioning without a config file.

    tcp://192.168.1.50[:502]                 Modbus TCP (port 502 by default)
    rtu-over-tcp://10.0.0.7[:4001]           RTU frames through a serial gateway
    rtu:///dev/ttyUSB0?baudrate=9600&parity=E&stopbits=1&bytesize=8&timeout=0.5
    ascii:///dev/ttyUSB0?baudrate=9600&parity=E&bytesize=7

Serial settings default to 9600 8N1, the answer timeout to the config file's default;
``timeout`` also applies to TCP. ``select_bus`` takes either such a spec or the id of a
bus in a config file (``-c config.yaml --bus rs485``). Every mistake is a ConfigError
naming the part of the spec that is wrong.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import parse_qsl, urlsplit

from pydantic import ValidationError

from bridge.config import SerialBus, TcpBus, load_config
from bridge.core.mapping import format_validation_errors
from bridge.errors import ConfigError

FORMS = (
    "tcp://HOST[:PORT]",
    "rtu-over-tcp://HOST[:PORT]",
    "rtu:///dev/ttyUSB0?baudrate=9600&parity=N&stopbits=1&bytesize=8&timeout=1",
    "ascii:///dev/ttyUSB0?...",
)
DEFAULT_ID = "bus"
_SERIAL_SETTINGS = ("baudrate", "parity", "stopbits", "bytesize", "timeout")
_TCP_SETTINGS = ("timeout",)


def parse_bus_spec(text: str, bus_id: str = DEFAULT_ID) -> SerialBus | TcpBus:
    """The bus ``text`` describes (see the module docstring); ConfigError if it is wrong."""
    source = f"bus {text!r}"
    scheme, sep, _ = text.partition("://")
    if not sep or scheme not in ("tcp", "rtu-over-tcp", "rtu", "ascii"):
        raise ConfigError(source, [f"use one of: {', '.join(FORMS)}"])
    try:
        parts = urlsplit(text)
        host, port = parts.hostname, parts.port
    except ValueError as exc:
        raise ConfigError(source, [f"{exc}"]) from None
    settings, problems = _settings(
        parts.query, _TCP_SETTINGS if "tcp" in scheme else _SERIAL_SETTINGS
    )
    if parts.fragment:
        problems.append(f"#{parts.fragment}: a bus spec has no fragment")
    fields: dict[str, object] = {"id": bus_id, "transport": scheme, **settings}
    if scheme in ("tcp", "rtu-over-tcp"):
        if not host:
            problems.append(f"host: missing; use {scheme}://HOST[:PORT]")
        if parts.path not in ("", "/"):
            problems.append(f"{parts.path}: a TCP bus has no path; use {scheme}://HOST[:PORT]")
        fields |= {"host": host or "", **({"tcp_port": port} if port is not None else {})}
    else:
        serial_port = parts.netloc + parts.path
        if not serial_port:
            problems.append(f"port: missing; use {scheme}:///dev/ttyUSB0 (three slashes)")
        fields["port"] = serial_port
    if problems:
        raise ConfigError(source, problems)
    return _validated(source, fields)


def bus_from_config(config_path: Path, bus_id: str) -> SerialBus | TcpBus:
    """The bus ``bus_id`` of a config file (the file is validated whole)."""
    buses = {bus.id: bus for bus in load_config(config_path).config.buses}
    if bus_id not in buses:
        raise ConfigError(str(config_path), [f"buses: no bus {bus_id!r} (have {sorted(buses)})"])
    return buses[bus_id]


def select_bus(spec_or_id: str, config_path: Path | None) -> SerialBus | TcpBus:
    """A spec (anything with ``://``) or, with a config file, the id of one of its buses."""
    if "://" in spec_or_id:
        return parse_bus_spec(spec_or_id)
    if config_path is None:
        raise ConfigError(
            f"bus {spec_or_id!r}",
            [f"a bus id needs -c CONFIG; or give a spec: {', '.join(FORMS)}"],
        )
    return bus_from_config(config_path, spec_or_id)


def _settings(query: str, allowed: tuple[str, ...]) -> tuple[dict[str, str | int], list[str]]:
    settings: dict[str, str | int] = {}
    problems: list[str] = []
    try:
        pairs = parse_qsl(query, keep_blank_values=True, strict_parsing=bool(query))
    except ValueError:
        return {}, [f"?{query}: write settings as name=value&name=value"]
    for name, value in pairs:
        if name not in allowed:
            problems.append(f"{name}: unknown setting (known: {', '.join(allowed)})")
        elif name in settings:
            problems.append(f"{name}: given twice")
        else:
            settings[name] = _setting(name, value)
    return settings, problems


def _setting(name: str, value: str) -> str | int:
    if name == "parity":
        return value.upper()
    if name in ("baudrate", "stopbits", "bytesize") and value.isdigit():
        return int(value)  # the config's Literal[1, 2] takes no "1"
    return value


def _validated(source: str, fields: dict[str, object]) -> SerialBus | TcpBus:
    model = SerialBus if fields["transport"] in ("rtu", "ascii") else TcpBus
    try:
        return model.model_validate(fields)
    except ValidationError as exc:
        raise ConfigError(source, list(format_validation_errors(exc))) from None
