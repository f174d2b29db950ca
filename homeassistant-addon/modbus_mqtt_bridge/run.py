"""Start of the Home Assistant add-on: the broker from the Supervisor, the rest from the
add-on's options, then ``modbus-mqtt-bridge run``.

1. The broker: the ``mqtt_url`` option (with ``mqtt_username`` and ``mqtt_password``)
   when given, for a broker that no add-on provides (a NAS, another broker add-on); else
   ask the Supervisor for the MQTT service (``GET http://supervisor/services/mqtt`` with
   ``SUPERVISOR_TOKEN``): host, port, user name and password of the broker add-on, so no
   user types a broker address. The password goes to the bridge in an environment
   variable, never into a file.
2. Build the bridge config from ``/data/options.json``: the buses and devices of the
   options, or a whole bridge config file named by ``config_file`` (relative to the
   add-on's folder, /config, or a full path under /config or /share; a path that leads
   elsewhere, through ``..`` or a symbolic link, is refused), whose MQTT connection is
   replaced by the Supervisor's. Mapping files named by a path are looked up in that
   file's folder.
3. Validate it with the bridge's own config model (the rows name the field: ``devices.
   pump.unit: ...``), write it to /tmp, and replace this process with the bridge.

Exit codes: 2 the options or the config file are invalid, 1 the Supervisor has no broker
to give or an answer the add-on cannot use (the add-on log says what, in one line).
``ADDON_OPTIONS``, ``ADDON_CONFIG_DIR``, ``ADDON_SHARE_DIR``, ``ADDON_GENERATED`` and
``SUPERVISOR_API`` move the paths and the API (tests do).
"""

from __future__ import annotations

import json
import os
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import yaml

from bridge.config import load_config_data
from bridge.core.mapping import builtin_mapping_names
from bridge.errors import InputError

OPTIONS = Path(os.environ.get("ADDON_OPTIONS", "/data/options.json"))
CONFIG_DIR = Path(os.environ.get("ADDON_CONFIG_DIR", "/config"))
SHARE_DIR = Path(os.environ.get("ADDON_SHARE_DIR", "/share"))
# The web page behind Home Assistant's ingress: the Supervisor's proxy is the only client
# let in (it logged the user in); anybody else who reaches the port gets 403.
INGRESS_WEB = {"enabled": True, "host": "0.0.0.0", "port": 8099, "ingress_proxies": ["172.30.32.2"]}  # noqa: S104
GENERATED = Path(os.environ.get("ADDON_GENERATED", "/tmp/modbus-mqtt-bridge.yaml"))  # noqa: S108
SUPERVISOR = os.environ.get("SUPERVISOR_API", "http://supervisor")
PASSWORD_ENV = "BRIDGE_MQTT_PASSWORD"  # noqa: S105 - the name of a variable, not a secret
# The metrics endpoint serves the image's HEALTHCHECK, which asks BRIDGE_HEALTH_URL.
HEALTH_URL = urlsplit(os.environ.get("BRIDGE_HEALTH_URL", "http://127.0.0.1:9464/health"))
CONNECTION_KEYS = ("url", "username", "password", "password_file", "password_env", "tls")
ATTEMPTS = 10  # the Supervisor may still be starting: 10 tries, 3 s apart


class AddonError(Exception):
    """Something the user of the add-on has to fix; ``code`` is the exit code."""

    def __init__(self, message: str, code: int = 2) -> None:
        super().__init__(message)
        self.code = code


def mqtt_service() -> dict[str, Any]:
    """The Supervisor's answer for the MQTT service: host, port, username, password, ssl."""
    token = os.environ.get("SUPERVISOR_TOKEN")
    if not token:
        raise AddonError("SUPERVISOR_TOKEN is not set: this runs as a Home Assistant add-on", 1)
    request = urllib.request.Request(  # noqa: S310 - SUPERVISOR is http://supervisor
        f"{SUPERVISOR}/services/mqtt", headers={"Authorization": f"Bearer {token}"}
    )
    for attempt in range(1, ATTEMPTS + 1):
        try:
            with urllib.request.urlopen(request, timeout=10) as answer:  # noqa: S310
                return broker_of(json.loads(answer.read()))
        except urllib.error.HTTPError as refused:
            if refused.code < 500:
                raise AddonError(_refusal(refused), 1) from None
            reason = f"HTTP {refused.code}"
        except (OSError, ValueError) as failed:  # ValueError: not JSON (yet)
            reason = str(failed)
        print(f"the Supervisor does not answer yet ({reason}); try {attempt}/{ATTEMPTS}")
        time.sleep(3)
    raise AddonError(f"cannot reach the Supervisor at {SUPERVISOR}", 1)


def broker_of(answer: Any) -> dict[str, Any]:
    """The ``data`` of the Supervisor's answer, checked: AddonError (1) saying in one line
    what is missing (never a value: the answer holds the broker's password)."""
    data = answer.get("data") if isinstance(answer, dict) else None
    if not isinstance(data, dict):
        if isinstance(answer, dict):
            raise _unusable(f"'data' is {_json_kind(data)}" if "data" in answer else "no 'data'")
        raise _unusable(f"{_json_kind(answer)} instead of an object")
    if problems := _broker_problems(data):
        raise _unusable("; ".join(problems))
    return dict(data)


def _unusable(problem: str) -> AddonError:
    return AddonError(
        f"the Supervisor's answer for the MQTT service is not usable ({problem}): restart "
        "the Mosquitto broker add-on, then this add-on",
        1,
    )


def _broker_problems(data: dict[str, Any]) -> list[str]:
    port = data.get("port")
    problems = [] if isinstance(data.get("host"), str) and data["host"] else ["no host"]
    if isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536:
        problems.append("no port number")
    for key, kind in (("ssl", bool), ("username", str), ("password", str)):
        if data.get(key) is not None and not isinstance(data[key], kind):
            problems.append(f"{key} is {_json_kind(data[key])}")
    return problems


def _json_kind(value: Any) -> str:
    kinds = {type(None): "null", bool: "a boolean", int: "a number", float: "a number",
             str: "a string", list: "a list", dict: "an object"}  # fmt: skip
    return kinds.get(type(value), type(value).__name__)


def _refusal(refused: urllib.error.HTTPError) -> str:
    try:
        message = str(json.loads(refused.read()).get("message", ""))
    except (ValueError, AttributeError):
        message = ""
    if refused.code == 400:  # the Supervisor's answer while no add-on provides MQTT
        return (
            f"no MQTT broker in Home Assistant ({message or 'HTTP 400'}): install and start "
            "the Mosquitto broker app (Settings > Apps > App store), or give your "
            "broker's address in the mqtt_url option, then start this add-on again"
        )
    return f"the Supervisor refused the MQTT service: HTTP {refused.code} {message}".rstrip()


def own_broker(options: dict[str, Any]) -> dict[str, Any] | None:
    """The broker the options name (``mqtt_url``...), which wins over the Supervisor's;
    None when they name none."""
    url = options.get("mqtt_url")
    if not url:
        if options.get("mqtt_username") or options.get("mqtt_password"):
            raise AddonError(
                "mqtt_username and mqtt_password go with mqtt_url (the broker they log in "
                "to); without mqtt_url the broker and its login are Home Assistant's"
            )
        return None
    return {"url": str(url), "username": options.get("mqtt_username"),
            "password": options.get("mqtt_password"), "source": "the add-on's options"}  # fmt: skip


def mqtt_section(service: dict[str, Any], file_mqtt: dict[str, Any]) -> dict[str, Any]:
    """The file's MQTT settings (topics, QoS...) with the broker: the options' own
    (``url`` given) or the Supervisor's (host, port, ssl)."""
    section = {k: v for k, v in file_mqtt.items() if k not in CONNECTION_KEYS}
    if service.get("url"):
        section["url"] = service["url"]  # TLS verified as for any broker
    else:
        ssl = bool(service.get("ssl"))
        section["url"] = f"{'mqtts' if ssl else 'mqtt'}://{service['host']}:{service['port']}"
        if ssl:  # the broker's certificate names its public host, not the internal one
            section["tls"] = {"insecure": True}
    if service.get("username"):
        section["username"] = service["username"]
    if service.get("password"):
        section["password_env"] = PASSWORD_ENV
    return section


def from_options(options: dict[str, Any]) -> tuple[dict[str, Any], Path]:
    """The bridge config the options describe, and the folder relative paths start from."""
    if options.get("config_file"):
        if options.get("buses") or options.get("devices"):
            raise AddonError(
                "give buses and devices in the options or in config_file, not both "
                "(empty the options' buses and devices to use the file)"
            )
        path = config_file(str(options["config_file"]))
        try:
            data = yaml.safe_load(path.read_text(encoding="utf-8"))
        except (OSError, yaml.YAMLError) as failed:
            raise AddonError(f"config_file {path}: {failed}") from None
        if not isinstance(data, dict):
            raise AddonError(f"config_file {path}: not a bridge config (mqtt, buses, devices)")
        return data, path.parent
    if not options.get("devices"):
        raise AddonError(
            "no devices yet: add them on the add-on's Configuration tab (id, bus, unit, "
            "mapping), or name a whole bridge config in config_file; see the Documentation tab"
        )
    buses = [_bus(bus) for bus in options.get("buses", [])]
    devices = [_device(device) for device in options["devices"]]
    mqtt = {k: options[k] for k in ("base_topic", "discovery_prefix") if options.get(k)}
    return {"mqtt": mqtt, "buses": buses, "devices": devices}, CONFIG_DIR


def config_file(name: str) -> Path:
    """Where ``config_file`` leads, links followed: under the add-on's folder (a relative
    name starts there) or under /share, else AddonError."""
    try:
        path = (CONFIG_DIR / name).resolve()
    except (OSError, RuntimeError, ValueError) as failed:  # a link loop, a NUL
        raise AddonError(f"config_file {name!r}: {failed}") from None
    if not any(path.is_relative_to(root.resolve()) for root in (CONFIG_DIR, SHARE_DIR)):
        raise AddonError(
            f"config_file {name!r}: not in the add-on's folder ({CONFIG_DIR}) or under "
            f"{SHARE_DIR} (leads to {path})"
        )
    return path


def _bus(bus: dict[str, Any]) -> dict[str, Any]:
    return {key: value for key, value in bus.items() if value not in (None, "")}


def _device(device: dict[str, Any]) -> dict[str, Any]:
    result = {k: v for k, v in device.items() if v not in (None, "") and not k.startswith("poll")}
    poll = {k[5:]: device[k] for k in ("poll_fast", "poll_slow") if device.get(k)}
    return result | ({"poll": poll} if poll else {})


def bridge_config(options: dict[str, Any], service: dict[str, Any]) -> tuple[dict[str, Any], Path]:
    """The complete bridge config, paths absolute, and the folder they were relative to."""
    data, base = from_options(options)
    data["mqtt"] = mqtt_section(service, dict(data.get("mqtt") or {}))
    for key in ("base_topic", "discovery_prefix"):
        if options.get(key):
            data["mqtt"].setdefault(key, options[key])
    management = dict(data.get("bridge") or {})
    metrics = dict(management.get("metrics") or {})
    health = {"enabled": True, "port": HEALTH_URL.port or 80}
    management["metrics"] = {"host": "127.0.0.1"} | metrics | health
    management["mapping_dirs"] = [str(base / d) for d in management.get("mapping_dirs", [])]
    management["web"] = dict(management.get("web") or {}) | INGRESS_WEB
    data["bridge"] = management
    for device in data.get("devices") or []:
        mapping = device.get("mapping")
        if isinstance(mapping, str) and mapping not in builtin_mapping_names():
            device["mapping"] = str(base / mapping)  # an absolute path stays as it is
    return data, base


def main() -> int:
    options = json.loads(OPTIONS.read_text(encoding="utf-8"))
    try:
        service = own_broker(options) or mqtt_service()
        data, base = bridge_config(options, service)
        if service.get("password"):
            os.environ[PASSWORD_ENV] = str(service["password"])
        loaded = load_config_data(data, base / "config.yaml")
    except AddonError as problem:
        print(f"error: {problem}", file=sys.stderr)
        return problem.code
    except InputError as invalid:  # the rows name the option: devices.<id>.<field>
        where = options.get("config_file") or "the add-on's options"
        rows = "".join(f"\n  {issue}" for issue in invalid.issues)
        print(f"error: {where}: {len(invalid.issues)} error(s){rows}", file=sys.stderr)
        return 2
    # the first line tells the page's config store (bridge/config/store.py) that this copy
    # is not where the settings live: the page does not edit it
    source = options.get("config_file") or "the add-on's options (its Configuration tab)"
    header = f"# generated by modbus-mqtt-bridge from {source}\n"
    GENERATED.write_text(header + yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    config = loaded.config
    print(
        f"broker {config.mqtt.url} (from {service.get('source', 'the Supervisor')}), "
        f"{len(config.buses)} bus(es), "
        f"{len(config.devices)} device(s); config in {GENERATED}",
        flush=True,
    )
    level = str(options.get("log_level") or "info")
    command = ["modbus-mqtt-bridge", "run", "-c", str(GENERATED), "--log-level", level]
    os.execvp(command[0], command)  # noqa: S606 - the bridge replaces this process
    return 0  # pragma: no cover - execvp does not return


if __name__ == "__main__":
    sys.exit(main())
