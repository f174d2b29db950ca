"""The rules the Home Assistant Supervisor applies to an add-on's config.yaml, as its
developer documentation states them (developers.home-assistant.io, App configuration):
required and known keys with their types, architectures, services, folder maps, and the
options schema language (``str``, ``int(min,max)``, ``list(a|b)``, ``match(REGEX)``,
``device(subsystem=tty)``, a trailing ``?`` for optional; lists and dicts nested at most
two deep). ``problems(config)`` lists every rule a config breaks; ``option_problems``
checks options against a schema the way the Supervisor does before it starts an add-on.
"""

from __future__ import annotations

import re
from typing import Any
from urllib.parse import urlsplit

REQUIRED = {"name": str, "version": str, "slug": str, "description": str, "arch": list}
BOOLEANS = frozenset(
    [
        "host_network",
        "host_ipc",
        "host_dbus",
        "host_pid",
        "host_uts",
        "hassio_api",
        "homeassistant_api",
        "docker_api",
        "full_access",
        "audio",
        "video",
        "gpio",
        "usb",
        "uart",
        "udev",
        "devicetree",
        "kernel_modules",
        "stdin",
        "legacy",
        "auth_api",
        "ingress",
        "ingress_stream",
        "panel_admin",
        "tmpfs",
        "init",
        "realtime",
        "journald",
        "apparmor",
    ]
)
STRINGS = frozenset(
    [
        "url",
        "startup",
        "webui",
        "boot",
        "homeassistant",
        "hassio_role",
        "image",
        "ingress_entry",
        "panel_icon",
        "panel_title",
        "backup",
        "backup_pre",
        "backup_post",
        "stage",
        "watchdog",
    ]
)
LISTS = frozenset(
    [
        "machine",
        "devices",
        "privileged",
        "map",
        "discovery",
        "services",
        "backup_exclude",
        "breaking_versions",
    ]
)
DICTS = frozenset(["ports", "ports_description", "environment", "options", "schema", "ulimits"])
INTEGERS = frozenset({"timeout", "ingress_port"})
KNOWN = frozenset(REQUIRED) | BOOLEANS | STRINGS | LISTS | DICTS | INTEGERS
ARCHITECTURES = frozenset({"aarch64", "amd64"})  # armhf, armv7, i386: gone since 2025.12
ENUMS = {
    "startup": {"initialize", "system", "services", "application", "once"},
    "boot": {"auto", "manual", "manual_only"},
    "stage": {"stable", "experimental", "deprecated"},
    "backup": {"hot", "cold"},
}
FOLDERS = "homeassistant_config|addon_config|ssl|addons|backup|share|media|all_addon_configs|data"
_MAP = re.compile(rf"^({FOLDERS})(:(ro|rw))?$")
_SERVICE = re.compile(r"^(mqtt|mysql):(provide|want|need)$")
_SLUG = re.compile(r"^[-_.A-Za-z0-9]+$")
_NUMBER = r"-?\d*\.?\d+"
_ELEMENT = re.compile(
    r"^(?:(?P<type>str|password|int|float)(?:\((?P<low>"
    + _NUMBER
    + r")?,(?P<high>"
    + _NUMBER
    + r")?\))?"
    r"|(?P<plain>bool|email|url|port)"
    r"|device(?:\((?P<filter>subsystem=[a-z]+)\))?"
    r"|match\((?P<match>.+)\)"
    r"|list\((?P<choices>[^)]+)\)"
    r")(?P<optional>\?)?$"
)


def problems(config: dict[str, Any]) -> list[str]:
    """Every rule of the add-on config format that ``config`` breaks."""
    found = [f"{key}: required" for key in REQUIRED if key not in config]
    found += [f"{key}: not an add-on config key" for key in config if key not in KNOWN]
    for key, value in config.items():
        found += _type_problems(key, value)
    found += [
        f"arch: {a} is not supported" for a in config.get("arch", []) if a not in ARCHITECTURES
    ]
    if not _SLUG.match(str(config.get("slug", ""))):
        found.append("slug: letters, digits, '-', '_' and '.' only (URI friendly)")
    for key, allowed in ENUMS.items():
        if key in config and config[key] not in allowed:
            found.append(f"{key}: one of {sorted(allowed)}")
    found += [f"services: {s!r}" for s in config.get("services", []) if not _SERVICE.match(s)]
    found += [f"map: {m!r}" for m in config.get("map", []) if not _map_entry_ok(m)]
    if "url" in config and urlsplit(config["url"]).scheme not in ("http", "https"):
        found.append("url: an http(s) address")
    schema = config.get("schema", {})
    found += [f"schema.{row}" for row in schema_problems(schema)]
    found += [f"options.{row}" for row in option_problems(config.get("options", {}), schema)]
    return found


def _type_problems(key: str, value: Any) -> list[str]:
    expected: type | tuple[type, ...] | None = REQUIRED.get(key)
    if key in BOOLEANS:
        expected = (bool, str) if key == "apparmor" else bool
    elif key in STRINGS:
        expected = str
    elif key in LISTS:
        expected = list
    elif key in DICTS:
        expected = dict
    elif key in INTEGERS:
        expected = int
    if expected is None or isinstance(value, expected):
        return []
    return [f"{key}: {type(value).__name__} instead of {expected}"]


def _map_entry_ok(entry: Any) -> bool:
    if isinstance(entry, str):
        return bool(_MAP.match(entry))
    return (
        isinstance(entry, dict)
        and set(entry) <= {"type", "read_only", "path"}
        and bool(_MAP.match(str(entry.get("type"))))
    )


def schema_problems(schema: dict[str, Any]) -> list[str]:
    """Types the schema language does not have, and nesting deeper than two."""
    rows = []
    for key, value in schema.items():
        rows += _element_problems(value, 0, key)
    return rows


def _element_problems(schema: Any, containers: int, where: str) -> list[str]:
    if isinstance(schema, dict | list) and containers == 2:
        return [f"{where}: lists and dicts nest at most two deep"]
    if isinstance(schema, dict):
        rows = []
        for key, value in schema.items():
            rows += _element_problems(value, containers + 1, f"{where}.{key}")
        return rows
    if isinstance(schema, list):
        if len(schema) != 1 or isinstance(schema[0], list):
            return [f"{where}: a list schema holds one element, not a list"]
        return _element_problems(schema[0], containers + 1, where)
    if not isinstance(schema, str):
        return [f"{where}: {schema!r} is not a type"]
    element = _ELEMENT.match(schema)
    if element is None:
        return [f"{where}: unknown type {schema!r}"]
    if element["match"]:
        try:
            re.compile(element["match"])
        except re.error as bad:
            return [f"{where}: match() regex: {bad}"]
    return []


def optional(schema: Any) -> bool:
    """The Supervisor may go without it: a ``?`` type, or a list of ``?`` types."""
    if isinstance(schema, list):
        schema = schema[0]
    return isinstance(schema, str) and schema.endswith("?")


def option_problems(options: Any, schema: Any, where: str = "") -> list[str]:
    """What the Supervisor would refuse in ``options`` (keys not in the schema are only
    dropped with a warning by the Supervisor, so they are reported too)."""
    if isinstance(schema, dict):
        if not isinstance(options, dict):
            return [f"{where}: a dict"]
        rows = [f"{_at(where, k)}: not in the schema" for k in options if k not in schema]
        rows += [
            f"{_at(where, k)}: required"
            for k, s in schema.items()
            if k not in options and not optional(s)
        ]
        for key, value in options.items():
            if key in schema:
                rows += option_problems(value, schema[key], _at(where, key))
        return rows
    if isinstance(schema, list):
        if not isinstance(options, list):
            return [f"{where}: a list"]
        rows = []
        for index, item in enumerate(options):
            rows += option_problems(item, schema[0], f"{where}.{index}")
        return rows
    return _value_problems(options, schema, where)


def _at(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _value_problems(value: Any, schema: str, where: str) -> list[str]:
    element = _ELEMENT.match(schema)
    if element is None:
        return [f"{where}: unknown type {schema!r}"]
    if value is None:
        return [f"{where}: required (null)"]
    kind = element["type"] or element["plain"]
    if element["choices"]:
        ok = str(value) in element["choices"].split("|")
    elif element["match"]:
        ok = re.match(element["match"], str(value)) is not None
    elif kind in ("str", "password"):
        ok = isinstance(value, str) and _within(len(value), element)
    elif kind in ("int", "float"):
        ok = _number(value, kind) is not None and _within(_number(value, kind), element)
    elif kind == "bool":
        ok = isinstance(value, bool)
    elif kind == "port":
        ok = _number(value, "int") is not None and 1 <= int(value) <= 65535
    else:
        ok = isinstance(value, str)
    return [] if ok else [f"{where}: {value!r} is not {schema}"]


def _number(value: Any, kind: str) -> float | None:
    if isinstance(value, bool):
        return None
    try:
        return float(int(value)) if kind == "int" else float(value)
    except (TypeError, ValueError):
        return None


def _within(number: float | None, element: re.Match[str]) -> bool:
    if number is None:
        return False
    low, high = element["low"], element["high"]
    return (low is None or number >= float(low)) and (high is None or number <= float(high))
