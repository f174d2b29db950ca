"""The config file: MQTT connection, buses, devices. ``load_config`` validates it whole.

Errors are reported as ``path: message`` rows (``devices.borehole_pump.unit: ...``), all
at once, and nothing is started on a bad file. Secrets (the MQTT password) come from the
file, a file named by ``password_file`` or an environment variable named by
``password_env``; they are ``SecretStr`` so that dumps and logs show ``**********``.
"""

from __future__ import annotations

import ipaddress
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, Self
from urllib.parse import unquote, urlsplit

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    IPvAnyAddress,
    SecretStr,
    TypeAdapter,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from bridge.config.checks import (
    folder_errors,
    reference_errors,
    secret_errors,
    topic_errors,
    unique,
    with_ids,
)
from bridge.core.duration import Duration
from bridge.core.mapping import Mapping, format_validation_errors, load_mapping, mapping_warnings
from bridge.core.mapping import resolve_mapping_path as _resolve
from bridge.core.yaml_source import parse_yaml
from bridge.errors import ConfigError, MappingError

_ID = re.compile(r"^[a-z0-9][a-z0-9_-]*$")
_TOPIC_FORBIDDEN = re.compile(r"[#+\x00]")
MAX_PREFIX_BYTES = 1024  # base_topic, discovery_prefix: room left for device, entity, suffix


class _Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


def _from_config_folder(path: Path, info: ValidationInfo) -> Path:
    """A relative path is taken from the config file's folder (``context["base"]``), as
    mapping paths are: a service's working directory is often ``/``."""
    base = info.context.get("base") if isinstance(info.context, dict) else None
    return path if base is None or path.is_absolute() else base / path


def _without_credentials(url: str) -> tuple[str, str | None, str | None]:
    """The URL without ``user:password@``, and the user and password it gave (decoded)."""
    parts = urlsplit(url)
    user, password, port = parts.username, parts.password, parts.port
    if user is None:
        return url, None, None
    host = parts.hostname or ""
    netloc = (f"[{host}]" if ":" in host else host) + (f":{port}" if port else "")
    decoded = unquote(password) if password is not None else None
    return parts._replace(netloc=netloc).geturl(), unquote(user), decoded


def _one_source(name: str, *given: object) -> None:
    """At most one of ``<name>``, ``<name>_file``, ``<name>_env`` is given."""
    if sum(value is not None for value in given) > 1:
        raise ValueError(f"give one of {name}, {name}_file, {name}_env")


FilePath = Annotated[Path, AfterValidator(_from_config_folder)]
"""A file a config names (a secret, a certificate); relative to the config file."""


MAX_BROKERS = 16  # broker URLs in mqtt.url


class TlsConfig(_Strict):
    """TLS for mqtts://: CA bundle, optional client certificate, or no verification."""

    ca: FilePath | None = None
    cert: FilePath | None = None
    key: FilePath | None = None
    insecure: bool = Field(False, description="skip certificate verification (testing only)")


class MqttConfig(_Strict):
    url: str | list[str] = "mqtt://127.0.0.1:1883"
    url_order: Literal["in_order", "random"] = Field(
        "in_order",
        description="with several broker URLs: the next one after a failure, or a random one",
    )
    base_topic: str = "modbus"
    discovery_prefix: str = "homeassistant"
    discovery: Literal["device", "entity", "off"] = Field(
        "device", description="device-based discovery, per-entity (older HA), or none"
    )
    client_id: str | None = None
    username: str | None = None
    password: SecretStr | None = None
    password_file: FilePath | None = None
    password_env: str | None = None
    tls: TlsConfig | None = None
    version: Literal["5", "3.1.1"] = Field("5", description="MQTT 5, falls back to 3.1.1")
    keepalive: Duration = Field(60.0, ge=1, le=65535, description="MQTT keepalive, 1..65535 s")
    qos: Literal[0, 1, 2] = 1
    output: Literal["json", "values", "both"] = Field(
        "json",
        description=(
            "what a device publishes: its JSON document (<base>/<device>, what Home "
            "Assistant and the Node-RED example read), a plain topic per value "
            "(<base>/<device>/<key>), or both (about 1 + changed values messages per poll); "
            "values alone needs discovery: off"
        ),
    )
    state_refresh: Duration = Field(300.0, gt=0, description="republish every value this often")
    command_expiry: Duration = Field(5.0, gt=0, description="drop commands not executed in time")

    @model_validator(mode="before")
    @classmethod
    def _credentials_from_url(cls, data: Any) -> Any:
        """``mqtt://user:pass@host`` logs in as user with pass; the URL keeps only the
        host, so no log line, error or ``bridge/info`` ever shows the password."""
        url = data.get("url") if isinstance(data, dict) else None
        urls: list[Any] = url if isinstance(url, list) else [url]
        texts = [u for u in urls if isinstance(u, str)]
        if len(texts) != len(urls) or not any("@" in u for u in texts):
            return data
        try:
            found = [_without_credentials(u) for u in texts]
        except ValueError:
            return data  # _check_url names the problem
        logins = {(user, password) for _, user, password in found if user is not None}
        if not logins:
            return data
        if len(logins) > 1 or any(user is None for _, user, _ in found):
            raise ValueError("url: the brokers of a list take the same user and password")
        ((user, password),) = logins
        if data.get("username") is not None or (
            password is not None
            and any(data.get(k) is not None for k in ("password", "password_file", "password_env"))
        ):
            raise ValueError(
                "url: give the user and password in the URL or in their fields, not both"
            )
        bare = [u for u, _, _ in found]
        moved = {**data, "url": bare if isinstance(url, list) else bare[0], "username": user}
        if password is not None:
            moved["password"] = password
        return moved

    @field_validator("url")
    @classmethod
    def _check_url(cls, url: str | list[str]) -> str | list[str]:
        urls = url if isinstance(url, list) else [url]
        if not 1 <= len(urls) <= MAX_BROKERS:
            raise ValueError(f"give 1 to {MAX_BROKERS} broker URLs")
        for each in urls:
            parts = urlsplit(each)
            if parts.scheme not in ("mqtt", "mqtts") or not parts.hostname:
                which = f"{each!r}: " if isinstance(url, list) else ""
                raise ValueError(f"{which}use mqtt://host[:port] or mqtts://host[:port]")
        if len({urlsplit(u).scheme for u in urls}) > 1:
            raise ValueError("the brokers of a list all use mqtt:// or all mqtts://")
        return url

    @field_validator("base_topic", "discovery_prefix")
    @classmethod
    def _check_topic(cls, topic: str) -> str:
        if not topic or topic.startswith("/") or topic.endswith("/"):
            raise ValueError("a topic prefix is non-empty and has no leading or trailing '/'")
        if _TOPIC_FORBIDDEN.search(topic):
            raise ValueError("a topic prefix cannot contain '#', '+' or NUL")
        if topic.startswith("$"):
            raise ValueError("topics starting with '$' belong to the broker ($SYS); drop the '$'")
        if len(topic.encode("utf-8")) > MAX_PREFIX_BYTES:
            raise ValueError(f"a topic prefix is at most {MAX_PREFIX_BYTES} bytes")
        return topic

    @model_validator(mode="after")
    def _prefixes_apart(self) -> Self:
        base, prefix = self.base_topic, self.discovery_prefix
        if base == prefix or base.startswith(prefix + "/") or prefix.startswith(base + "/"):
            raise ValueError(
                "discovery_prefix and base_topic must not be equal or nested: the bridge's "
                "commands and Home Assistant's discovery would share topics"
            )
        return self

    @model_validator(mode="after")
    def _discovery_reads_json(self) -> Self:
        if self.output == "values" and self.discovery != "off":
            raise ValueError(
                "output: values publishes no device JSON, which Home Assistant's discovered "
                "entities read; use output: json or both, or discovery: off"
            )
        return self

    @model_validator(mode="after")
    def _tls_needs_mqtts(self) -> Self:
        if self.tls is not None and urlsplit(self.broker_url).scheme != "mqtts":
            raise ValueError("tls: settings apply to mqtts:// URLs; use mqtts://host[:port]")
        return self

    @model_validator(mode="after")
    def _one_password_source(self) -> Self:
        _one_source("password", self.password, self.password_file, self.password_env)
        return self

    @property
    def urls(self) -> list[str]:
        """Every broker, in the configured order (one unless ``url`` is a list)."""
        return list(self.url) if isinstance(self.url, list) else [self.url]

    @property
    def broker_url(self) -> str:
        """The broker of this connection: the first (the MQTT client connects to a copy
        of the config that names only the node it tries)."""
        return self.urls[0]

    @property
    def host(self) -> str:
        return urlsplit(self.broker_url).hostname or "127.0.0.1"

    @property
    def port(self) -> int:
        parts = urlsplit(self.broker_url)
        return parts.port or (8883 if parts.scheme == "mqtts" else 1883)

    def password_value(self) -> str | None:
        """The password from whichever source is configured (read now, never logged)."""
        return secret_of(self.password, self.password_file, self.password_env)


class _BusBase(_Strict):
    id: str
    timeout: Duration = Field(1.0, gt=0, le=60, description="seconds to wait for a reply")
    retries: int = Field(
        1, ge=0, le=5, description="resends of a write after a timeout (reads: next poll)"
    )

    @field_validator("id")
    @classmethod
    def _check_id(cls, value: str) -> str:
        return _check_identifier(value)


class SerialLine(_Strict):
    """A serial line's settings."""

    baudrate: int = Field(9600, ge=300, le=921600)
    parity: Literal["N", "E", "O"] = "N"
    stopbits: Literal[1, 2] = 1
    bytesize: Literal[7, 8] = 8


class SerialBus(_BusBase, SerialLine):
    transport: Literal["rtu", "ascii"]
    port: str = Field(description="serial device, e.g. /dev/ttyUSB0")


class TcpBus(_BusBase):
    transport: Literal["tcp", "rtu-over-tcp"]
    host: str
    tcp_port: int = Field(502, ge=1, le=65535)
    serial_behind: SerialLine | None = Field(
        None,
        description=(
            "the RS485 line behind a TCP gateway (its baudrate, parity, stopbits): reads are "
            "planned for the least time on that line, not on the network"
        ),
    )
    raw_units: list[Annotated[int, Field(ge=1, le=255)]] = Field(
        default_factory=list,
        description=(
            "units no device is configured at that raw writes (bridge/request/device/write) "
            "may address on this bus; other such units, 255 included, are refused, as a "
            "gateway or a device that ignores the unit id may answer them; the guards of "
            "every device on the bus still apply"
        ),
    )


Bus = Annotated[SerialBus | TcpBus, Field(discriminator="transport")]


class PollConfig(_Strict):
    fast: Duration = Field(2.0, gt=0)
    slow: Duration = Field(60.0, gt=0)


class ProtocolOverride(_Strict):
    """Per-device overrides of the mapping's protocol numbers (what a real unit allows)."""

    max_read_registers: int | None = Field(None, ge=1, le=125)
    max_read_bits: int | None = Field(None, ge=1, le=2000)
    coil_on_value: int | None = Field(None, ge=0, le=0xFFFF)
    min_request_interval: Duration | None = None
    response_timeout: Duration | None = Field(None, gt=0)


class DeviceConfig(_Strict):
    id: str
    name: str | None = None
    bus: str
    unit: int = Field(ge=1, le=255, description="Modbus unit id (1..247 on serial lines)")
    mapping: str = Field(description="shipped mapping name or path to a mapping YAML file")
    poll: PollConfig = PollConfig()
    options: dict[str, str] = Field(default_factory=dict)
    protocol: ProtocolOverride = ProtocolOverride()
    allow_dangerous_writes: bool = Field(False, description="permit writes marked dangerous")
    password: SecretStr | None = Field(
        None, description="the device's user password (a mapping with protocol.unlock)"
    )
    password_file: FilePath | None = Field(None, description="a file holding the device password")
    password_env: str | None = Field(
        None, description="an environment variable holding the device password"
    )
    enabled: bool = True

    @field_validator("id")
    @classmethod
    def _check_id(cls, value: str) -> str:
        return _check_identifier(value)

    @model_validator(mode="after")
    def _one_password_source(self) -> Self:
        _one_source("password", self.password, self.password_file, self.password_env)
        return self

    @property
    def display_name(self) -> str:
        return self.name or self.id.replace("_", " ").capitalize()

    @property
    def has_password(self) -> bool:
        return any(v is not None for v in (self.password, self.password_file, self.password_env))

    def password_value(self) -> str | None:
        """The device password from whichever source is configured (read now, never
        logged); None when none is configured or its source is gone."""
        try:
            return secret_of(self.password, self.password_file, self.password_env)
        except (OSError, UnicodeDecodeError):  # gone, unreadable, or not text
            return None


class MetricsConfig(_Strict):
    """The optional Prometheus/OpenMetrics endpoint (off by default)."""

    enabled: bool = False
    host: str = Field("127.0.0.1", description="address to listen on (0.0.0.0 in a container)")
    port: int = Field(9464, ge=1, le=65535)


MIN_TOKEN = 16  # characters of a web token: guessing must be hopeless


class WebConfig(_Strict):
    """The web page: devices, live values, bus health, refused commands, commissioning
    (off by default; see the README, The web page)."""

    enabled: bool = False
    host: str = Field(
        "127.0.0.1", description="address to listen on; beyond loopback a token is required"
    )
    port: int = Field(8099, ge=1, le=65535)
    token: SecretStr | None = None
    token_file: FilePath | None = None
    token_env: str | None = None
    ingress_proxies: list[IPvAnyAddress] = Field(
        default_factory=list,
        description="Home Assistant's ingress proxy (172.30.32.2 in an add-on): requests "
        "from it need no token, Home Assistant has logged the user in",
    )

    @model_validator(mode="after")
    def _token_beyond_loopback(self) -> Self:
        given = [self.token, self.token_file, self.token_env]
        _one_source("token", *given)
        if self.token is not None and len(self.token.get_secret_value().strip()) < MIN_TOKEN:
            raise ValueError(f"token: at least {MIN_TOKEN} characters (spaces do not count)")
        if self.enabled and not self.loopback and given == [None] * 3 and not self.ingress_proxies:
            raise ValueError(
                f"token: the page listens beyond loopback ({self.host}): give a token "
                "(token, token_file or token_env), or listen on 127.0.0.1"
            )
        return self

    @property
    def loopback(self) -> bool:
        """Listening on this machine only (nobody else can open the page)."""
        if self.host == "localhost":
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return False  # a host name: it may resolve to anything

    def token_value(self) -> str | None:
        """The token from whichever source is configured (read now, never logged)."""
        token = secret_of(self.token, self.token_file, self.token_env)
        return None if token is None else token.strip()


class ManagementConfig(_Strict):
    """The ``<base>/bridge/*`` management side: health reports, raw writes, metrics."""

    health_interval: Duration = Field(
        60.0, description="publish <base>/bridge/health this often; 0 turns it off"
    )
    allow_raw_writes: bool = Field(
        False,
        description="permit bridge/request/device/write (raw register writes) and raw reads "
        "of secret registers; a register guarded by any device that may answer the unit "
        "still needs that device's allow_dangerous_writes",
    )
    scan_timeout: Duration = Field(
        0.2, gt=0, le=5, description="per-unit answer timeout of device/scan"
    )
    mapping_switch: bool = Field(
        False,
        description="permit bridge/request/mapping/reload to switch a device to another "
        "mapping: a shipped name, or a file under mapping_dirs",
    )
    mapping_dirs: list[Path] = Field(
        default_factory=list,
        description="folders (relative to the config file) whose mapping files a switch may name",
    )
    metrics: MetricsConfig = MetricsConfig()
    web: WebConfig = WebConfig()


class Config(_Strict):
    mqtt: MqttConfig = MqttConfig()
    bridge: ManagementConfig = ManagementConfig()
    buses: list[Bus] = Field(min_length=1)
    devices: list[DeviceConfig] = Field(default_factory=list)

    @model_validator(mode="after")
    def _check_references(self) -> Self:
        errors = reference_errors(self.buses, self.devices)
        if errors:
            raise ValueError("\n".join(errors))
        return self


def _check_identifier(value: str) -> str:
    if not _ID.match(value):
        raise ValueError("ids are lowercase letters, digits, '_' and '-' (used in MQTT topics)")
    if value == "bridge":
        raise ValueError("'bridge' is reserved for <base>/bridge/... topics")
    return value


@dataclass(frozen=True, slots=True)
class LoadedConfig:
    """A validated config with each device's mapping loaded and its options checked."""

    path: Path
    config: Config
    mappings: dict[str, Mapping]
    warnings: tuple[str, ...] = ()  # the conventions a user's mapping breaks: not refused


def load_config(path: Path) -> LoadedConfig:
    """Read and validate a config file and every mapping it names; ConfigError on problems."""
    try:
        text = path.read_text(encoding="utf-8")
        data = parse_yaml(text, str(path))
    except OSError as exc:
        raise ConfigError(str(path), [f"cannot read {path.absolute()}: {exc.strerror}"]) from None
    except ValueError as exc:
        raise ConfigError(str(path), [str(exc)]) from None
    return load_config_data(data, path)


def load_config_data(data: object, path: Path) -> LoadedConfig:
    """Validate parsed config data; mapping paths are relative to ``path``'s folder.

    Every problem of the file is reported at once: when some fields are invalid, the parts
    that validate on their own (sections, buses, devices) are still checked against each
    other and their mappings, so nothing waits for a second run."""
    if not isinstance(data, dict):
        raise ConfigError(str(path), ["the file must hold a mapping with mqtt, buses, devices"])
    try:
        config = Config.model_validate(data, context=_context(path))
    except ValidationError as exc:
        rows = with_ids(format_validation_errors(exc), data)
        raise ConfigError(str(path), unique(rows + _errors_of_valid_parts(data, path))) from None
    mappings, errors = _load_mappings(config.buses, config.devices, path.parent)
    errors += secret_errors(config.mqtt)
    errors += _web_token_errors(config.bridge.web)
    errors += _device_password_errors(config.devices, mappings)
    errors += topic_errors(config.mqtt, config.devices, mappings)
    errors += folder_errors(config.bridge, path.parent)
    if errors:
        raise ConfigError(str(path), errors)
    warnings = _mapping_warnings(config.devices, mappings)
    return LoadedConfig(path=path, config=config, mappings=mappings, warnings=warnings)


def _mapping_warnings(
    devices: Iterable[DeviceConfig], mappings: dict[str, Mapping]
) -> tuple[str, ...]:
    """Each mapping's convention warnings once, under the first device that uses it."""
    rows: list[str] = []
    seen: set[int] = set()
    for device in devices:
        mapping = mappings.get(device.id)
        if mapping is None or id(mapping) in seen:
            continue
        seen.add(id(mapping))
        where = f"devices.{device.id}.mapping: {device.mapping}"
        rows += [f"{where}: {row}" for row in mapping_warnings(mapping)]
    return tuple(rows)


def _errors_of_valid_parts(data: dict[str, Any], path: Path) -> list[str]:
    """The checks beyond fields, run on the sections, buses and devices that validate on
    their own (the invalid ones are reported already)."""
    context = _context(path)
    mqtt = _valid(MqttConfig, data.get("mqtt", {}), context)
    bridge = _valid(ManagementConfig, data.get("bridge", {}), context)
    raw_buses, raw_devices = _listed(data, "buses"), _listed(data, "devices")
    buses = [bus for bus in (_valid(_BUS, item, context) for item in raw_buses) if bus]
    devices = [d for d in (_valid(DeviceConfig, item, context) for item in raw_devices) if d]
    valid_ids = {bus.id for bus in buses}
    invalid = {b.get("id") for b in raw_buses if isinstance(b, dict)} - valid_ids
    errors = reference_errors(buses, devices, invalid_buses={str(i) for i in invalid})
    mappings, more = _load_mappings(buses, devices, path.parent)
    errors += more + _device_password_errors(devices, mappings)
    if mqtt is not None:
        errors += secret_errors(mqtt) + topic_errors(mqtt, devices, mappings)
    if bridge is not None:
        errors += folder_errors(bridge, path.parent) + _web_token_errors(bridge.web)
    return errors


def _listed(data: dict[str, Any], section: str) -> list[Any]:
    items = data.get(section)
    return items if isinstance(items, list) else []


def _context(path: Path) -> dict[str, Path]:
    """The validation context of the config at ``path``: where its relative files are."""
    return {"base": path.parent.absolute()}


def _valid(model: Any, data: object, context: dict[str, Path]) -> Any:
    """``data`` validated as ``model`` (a model class or a TypeAdapter), or None."""
    validate = model.validate_python if isinstance(model, TypeAdapter) else model.model_validate
    try:
        return validate(data, context=context)
    except ValidationError:
        return None


_BUS: TypeAdapter[SerialBus | TcpBus] = TypeAdapter(Bus)


def _load_mappings(
    buses: Iterable[SerialBus | TcpBus], devices: Iterable[DeviceConfig], base: Path
) -> tuple[dict[str, Mapping], list[str]]:
    loaded: dict[str, Mapping] = {}
    cache: dict[Path, Mapping] = {}
    errors: list[str] = []
    known = {bus.id: bus for bus in buses}
    for device in devices:
        if device.bus not in known:
            continue  # reported as a reference
        mapping, problems = load_device_mapping(device, known[device.bus], base, cache)
        errors += problems
        if mapping is not None:
            loaded[device.id] = mapping
    return loaded, errors


def load_device_mapping(
    device: DeviceConfig,
    bus: SerialBus | TcpBus,
    base: Path,
    cache: dict[Path, Mapping] | None = None,
) -> tuple[Mapping | None, list[str]]:
    """A device's mapping (relative paths from ``base``) and every problem with it for
    this device, as ``devices.<id>.<field>: message`` rows: the file itself, the device's
    options, a transport the model does not speak. The mapping is None if it cannot load."""
    where = f"devices.{device.id}"
    cache = {} if cache is None else cache
    try:
        path = _resolve(device.mapping, base)
        mapping = cache[path] if path in cache else cache.setdefault(path, load_mapping(path))
    except MappingError as exc:
        return None, [f"{where}.mapping: {exc.source}: {issue}" for issue in exc.issues]
    errors = []
    for name, value in device.options.items():
        spec = mapping.options.get(name)
        if spec is None:
            known = ", ".join(mapping.options) or "none"
            errors.append(f"{where}.options.{name}: the mapping has no such option ({known})")
        elif value not in spec.choices:
            errors.append(f"{where}.options.{name}: {value!r} is not one of {spec.choices}")
    if bus.transport == "ascii" and "ascii" not in mapping.protocol.transports:
        errors.append(f"{where}.bus: {mapping.model} does not speak Modbus ASCII")
    return mapping, errors


def _web_token_errors(web: WebConfig) -> list[str]:
    if not web.enabled or (web.token_file is None and web.token_env is None):
        return []
    where = "bridge.web.token_file" if web.token_file is not None else "bridge.web.token_env"
    try:
        token = web.token_value() or ""
    except OSError as exc:
        return [f"{where}: cannot read {str(web.token_file)!r}: {exc.strerror}"]
    if len(token) < MIN_TOKEN:
        return [f"{where}: the token is missing or shorter than {MIN_TOKEN} characters"]
    return []


def _device_password_errors(
    devices: Iterable[DeviceConfig], mappings: dict[str, Mapping]
) -> list[str]:
    """A device password needs a mapping that unlocks with one, a source that holds it,
    and a number the device register takes (0..65535); the value is never shown."""
    errors: list[str] = []
    for device in devices:
        if not device.has_password:
            continue
        where = f"devices.{device.id}"
        field = next(
            name
            for name in ("password", "password_file", "password_env")
            if getattr(device, name) is not None
        )
        mapping = mappings.get(device.id)
        if mapping is not None and mapping.protocol.unlock is None:
            errors.append(f"{where}.{field}: the mapping {device.mapping} has no password unlock")
            continue
        if device.password_file is not None and not device.password_file.is_file():
            errors.append(f"{where}.password_file: no such file {str(device.password_file)!r}")
        elif device.password_env is not None and device.password_env not in os.environ:
            errors.append(
                f"{where}.password_env: environment variable {device.password_env} is not set"
            )
        elif not is_register_number(device.password_value()):
            errors.append(f"{where}.{field}: the password must be a number 0..65535")
    return errors


def is_register_number(text: str | None) -> bool:
    """A password a device's unlock register takes: ASCII digits, 0..65535 ("12³" is none)."""
    return text is not None and text.isascii() and text.isdigit() and int(text) <= 0xFFFF


def secret_of(value: SecretStr | None, file: Path | None, env: str | None) -> str | None:
    """A secret from whichever source is configured: given, a file (stripped), or an
    environment variable (None while it is unset); read now, never logged. OSError if the
    file cannot be read."""
    if value is not None:
        return value.get_secret_value()
    if file is not None:
        return file.read_text(encoding="utf-8").strip()
    if env is not None:
        return os.environ.get(env)
    return None


def config_schema() -> dict[str, Any]:
    """JSON Schema of the config file (for editor completion)."""
    return Config.model_json_schema()
