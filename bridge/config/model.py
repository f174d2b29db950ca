"""The config file's model: buses, devices, the ``bridge`` section (management, metrics,
web page) and the whole file, ``Config``, with its invariants across sections (ids used
once, a device's bus exists, units a serial line can address, one device per unit, one
bus per gateway line). The ``mqtt`` section is ``bridge.config.mqtt``.

Secrets (the MQTT password, a device password, the web token) come from the file, a file
named by ``*_file`` or an environment variable named by ``*_env``; they are ``SecretStr``
so that dumps and logs show ``**********``.
"""

from __future__ import annotations

import ipaddress
import re
from collections import Counter
from collections.abc import Collection, Iterable, Sequence
from pathlib import Path
from typing import Annotated, Any, Literal, Self

from pydantic import (
    BeforeValidator,
    Field,
    IPvAnyAddress,
    SecretStr,
    field_validator,
    model_validator,
)

from bridge.config.field import FilePath, Strict, one_source, secret_of
from bridge.config.mqtt import MqttConfig
from bridge.core.duration import Duration
from bridge.core.entity import PollClass, parse_poll
from bridge.core.schedule import PollRule

PollChoice = Annotated[PollClass | float, BeforeValidator(parse_poll)]

_ID = re.compile(r"^[a-z0-9][a-z0-9_-]*$")
MAX_SERIAL_UNIT = 247


class _BusBase(Strict):
    id: str
    timeout: Duration = Field(1.0, gt=0, le=60, description="seconds to wait for a reply")
    retries: int = Field(
        1, ge=0, le=5, description="resends of a write after a timeout (reads: next poll)"
    )
    connect_delay: Duration = Field(
        0.0,
        ge=0,
        le=60,
        description="seconds of silence after each (re)connect before the first request (a "
        "gateway or device that needs time after a connection; Home Assistant's hub delay)",
    )

    @field_validator("id")
    @classmethod
    def _check_id(cls, value: str) -> str:
        return _check_identifier(value)


class SerialLine(Strict):
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


class PollConfig(Strict):
    """The device's named poll intervals, and intervals of its own for some entities."""

    fast: Duration = Field(2.0, gt=0)
    slow: Duration = Field(60.0, gt=0)
    entities: dict[Annotated[str, Field(min_length=1, max_length=200)], PollChoice] = Field(
        default_factory=dict,
        max_length=10000,
        description="entity key or glob (`grid_*`) -> `fast`, `slow`, `once` or an interval "
        "(seconds or `10s`, 0.1 s to 31 days), over the mapping's `poll`; an exact key wins "
        "over a glob, else the first glob that matches; one that names no entity is an error",
    )

    def rule(self, fast: float | None = None) -> PollRule:
        """The rule that resolves each entity's interval (``fast``: a shorter fast)."""
        chosen = tuple(self.entities.items())
        return PollRule(self.fast if fast is None else fast, self.slow, chosen)


class ProtocolOverride(Strict):
    """Per-device overrides of the mapping's protocol numbers (what a real unit allows)."""

    max_read_registers: int | None = Field(None, ge=1, le=125)
    max_read_bits: int | None = Field(None, ge=1, le=2000)
    coil_on_value: int | None = Field(None, ge=0, le=0xFFFF)
    min_request_interval: Duration | None = None
    response_timeout: Duration | None = Field(None, gt=0)


SUNSPEC = "sunspec"  # a device's mapping built from its SunSpec model chain
MAX_SUNSPEC_BASE = 65532  # the marker and the first model's ID and L fit below 65536


def _sunspec_base(value: object) -> object:
    """``auto`` or a register the marker and a model header fit after; one message."""
    if value == "auto" or (
        isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= MAX_SUNSPEC_BASE
    ):
        return value
    raise ValueError(f"auto, or the holding register of the SunS marker (0..{MAX_SUNSPEC_BASE})")


class SunSpecConfig(Strict):
    """Where a ``mapping: sunspec`` device's ``SunS`` marker is."""

    base: Annotated[
        Literal["auto"] | Annotated[int, Field(ge=0, le=MAX_SUNSPEC_BASE)],
        BeforeValidator(_sunspec_base),
    ] = Field(
        "auto",
        description="holding register of the SunS marker; auto tries 40000, 50000, then 0",
    )


class DeviceConfig(Strict):
    id: str
    name: str | None = None
    bus: str
    unit: int = Field(ge=1, le=255, description="Modbus unit id (1..247 on serial lines)")
    mapping: str = Field(
        description="shipped mapping name, path to a mapping YAML file, or `sunspec`: "
        "built from the device's SunSpec model chain (no file)"
    )
    sunspec: SunSpecConfig | None = Field(
        None, description="with `mapping: sunspec`: where its marker is (default base: auto)"
    )
    poll: PollConfig = PollConfig()
    options: dict[str, str] = Field(default_factory=dict)
    protocol: ProtocolOverride = ProtocolOverride()
    allow_dangerous_writes: bool = Field(False, description="permit writes marked dangerous")
    counter_confirm: dict[str, Annotated[int, Field(ge=1, le=100)]] = Field(
        default_factory=dict,
        description="counter key -> lower readings in a row that confirm its reset (default "
        "3, or the mapping's confirm_reset); fewer reads it sooner, more holds longer",
    )
    password: SecretStr | None = Field(
        None, description="the device's user password (a mapping with protocol.unlock)"
    )
    password_file: FilePath | None = Field(None, description="a file holding the device password")
    password_env: str | None = Field(
        None, description="an environment variable holding the device password"
    )
    enabled: bool = True
    offline_after: int | None = Field(
        None,
        ge=1,
        le=100,
        description="failed requests in a row before the device is offline (default 3); "
        "Home Assistant's lazy_error_count N is N + 1",
    )
    gateway_raw_writes: bool = Field(
        False,
        description="let masters of the Modbus TCP server (bridge.gateway, with allow_writes) "
        "write registers this device's mapping has no writable entity for; guarded "
        "registers still need allow_dangerous_writes",
    )
    gateway_max_age: Duration | None = Field(
        None,
        ge=0,
        description="this device's bridge.gateway.max_age: answer a read from the bridge's "
        "own image when all of it is younger than this (0: always read the bus)",
    )
    gateway_poll_share: float | None = Field(
        None,
        ge=0,
        le=1,
        description="this device's bridge.gateway.poll_share: its due polls' part of its "
        "request slots that masters' requests contend for",
    )

    @field_validator("id")
    @classmethod
    def _check_id(cls, value: str) -> str:
        return _check_identifier(value)

    @model_validator(mode="after")
    def _one_password_source(self) -> Self:
        one_source("password", self.password, self.password_file, self.password_env)
        return self

    @model_validator(mode="after")
    def _sunspec_with_its_mapping(self) -> Self:
        if self.sunspec is not None and not self.is_sunspec:
            raise ValueError(
                f"sunspec: only with mapping: sunspec (device {self.id!r} has mapping: "
                f"{self.mapping!r})"
            )
        return self

    @property
    def is_sunspec(self) -> bool:
        """Its mapping is built from its SunSpec model chain (``mapping: sunspec``)."""
        return self.mapping == SUNSPEC

    @property
    def sunspec_bases(self) -> tuple[int, ...] | None:
        """The bases a walk tries (None: the walk's default order); None if not SunSpec."""
        if not self.is_sunspec:
            return None
        base = (self.sunspec or SunSpecConfig()).base
        return None if base == "auto" else (base,)

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


class MetricsConfig(Strict):
    """The optional Prometheus/OpenMetrics endpoint (off by default)."""

    enabled: bool = False
    host: str = Field("127.0.0.1", description="address to listen on (0.0.0.0 in a container)")
    port: int = Field(9464, ge=1, le=65535)


MIN_TOKEN = 16  # characters of a web token: guessing must be hopeless


class WebConfig(Strict):
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
        one_source("token", *given)
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


class GatewayUnit(Strict):
    """A unit on a bus, for a gateway unit no configured device answers."""

    bus: str
    unit: int = Field(ge=1, le=255)


class GatewayConfig(Strict):
    """The Modbus TCP server other masters read (and, if allowed, write) the buses through
    (off by default; see the README, Sharing the bus with other Modbus masters)."""

    enabled: bool = False
    host: str = Field("127.0.0.1", description="address to listen on; 0.0.0.0 for every one")
    port: int = Field(5020, ge=0, le=65535, description="TCP port (502 needs privileges)")
    units: dict[Annotated[int, Field(ge=1, le=255)], str | GatewayUnit] = Field(
        default_factory=dict,
        description="unit id the server answers -> a configured device id, or {bus, unit}",
    )
    max_age: Duration = Field(
        0.0,
        ge=0,
        description="answer a read from the bridge's own image when every register of it "
        "was read within this many seconds (0: every read goes to the bus)",
    )
    allow_writes: bool = Field(
        False,
        description="permit FC05/06/15/16; they pass the checks of MQTT commands "
        "(writable, range, allow_dangerous_writes, EEPROM spacing, password lock)",
    )
    max_clients: int = Field(8, ge=1, le=64, description="connections at a time")
    max_queued_per_client: int = Field(
        4, ge=1, le=32, description="requests of one connection waiting; more answer 0x06"
    )
    max_queued_per_bus: int = Field(
        8, ge=1, le=64, description="gateway requests waiting per bus; more answer 0x06"
    )
    poll_share: float = Field(
        0.5,
        ge=0,
        le=1,
        description="the bridge's own due polls' part of a device's (and a bus's) request "
        "slots that masters' requests contend for (0: the masters always first; 1: the "
        "polls first); commands go first whatever it is",
    )
    max_wait: Duration | None = Field(
        None,
        gt=0,
        description="seconds a master's request may wait for the bus before it answers "
        "0x06 (busy) instead (default: twice the bus timeout, a transaction in flight may "
        "take one and the silence after a timeout another, plus the device's own "
        "min_request_interval)",
    )
    idle_timeout: Duration = Field(
        120.0, gt=0, description="close a connection silent this long (or a half frame)"
    )


class ManagementConfig(Strict):
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
    state_dir: Path = Field(
        Path("state"),
        description="folder (relative to the config file) where the bridge keeps what it "
        "learnt of devices: the mappings built for `mapping: sunspec` devices, under sunspec/; "
        "the entities added on the web page, as each device's override under mappings/ "
        "(<device id>.yaml: the device's mapping when it exists, see docs/mappings.md)",
    )
    metrics: MetricsConfig = MetricsConfig()
    web: WebConfig = WebConfig()
    gateway: GatewayConfig = GatewayConfig()


class Config(Strict):
    mqtt: MqttConfig = MqttConfig()
    bridge: ManagementConfig = ManagementConfig()
    buses: list[Bus] = Field(min_length=1)
    devices: list[DeviceConfig] = Field(default_factory=list)

    @model_validator(mode="after")
    def _check_references(self) -> Self:
        errors = reference_errors(self.buses, self.devices)
        errors += gateway_errors(self.bridge.gateway, self.buses, self.devices)
        if errors:
            raise ValueError("\n".join(errors))
        return self


def _check_identifier(value: str) -> str:
    if not _ID.match(value):
        raise ValueError("ids are lowercase letters, digits, '_' and '-' (used in MQTT topics)")
    if value == "bridge":
        raise ValueError("'bridge' is reserved for <base>/bridge/... topics")
    return value


def reference_errors(
    buses: Sequence[SerialBus | TcpBus],
    devices: Sequence[DeviceConfig],
    invalid_buses: Collection[str] = (),
) -> list[str]:
    """Ids used twice, a device on a bus that does not exist, a unit a serial line cannot
    address, two enabled devices at one unit of a bus. ``invalid_buses``: ids of buses that
    exist in the file but did not validate (their devices are not checked against them)."""
    errors = duplicates("buses", [bus.id for bus in buses])
    errors += duplicates("devices", [device.id for device in devices])
    known = {bus.id: bus for bus in buses}
    units: dict[tuple[str, int], str] = {}
    for device in devices:
        where = f"devices.{device.id}"
        bus = known.get(device.bus)
        if bus is None:
            if device.bus not in invalid_buses:
                errors.append(f"{where}.bus: no bus {device.bus!r} (have {sorted(known)})")
            continue
        if bus.transport in ("rtu", "ascii") and device.unit > MAX_SERIAL_UNIT:
            errors.append(f"{where}.unit: serial lines address units 1..{MAX_SERIAL_UNIT}")
        if not device.enabled:
            continue
        other = units.setdefault((device.bus, device.unit), device.id)
        if other != device.id:
            errors.append(f"{where}.unit: unit {device.unit} is also {other!r} on {bus.id}")
    return errors + shared_gateway_errors(buses)


def gateway_errors(
    gateway: GatewayConfig, buses: Sequence[SerialBus | TcpBus], devices: Sequence[DeviceConfig]
) -> list[str]:
    """The gateway's units name enabled devices or buses that exist; serial units 1..247."""
    errors: list[str] = []
    known = {device.id: device for device in devices}
    lines = {bus.id: bus for bus in buses}
    if gateway.enabled and not gateway.units:
        errors.append("bridge.gateway.units: name the units to answer, e.g. {1: pump}")
    for unit, target in gateway.units.items():
        where = f"bridge.gateway.units.{unit}"
        if isinstance(target, str):
            device = known.get(target)
            if device is None:
                errors.append(f"{where}: no device {target!r} (have {sorted(known)})")
            elif not device.enabled:
                errors.append(f"{where}: device {target!r} is disabled")
            continue
        bus = lines.get(target.bus)
        if bus is None:
            errors.append(f"{where}.bus: no bus {target.bus!r} (have {sorted(lines)})")
        elif bus.transport in ("rtu", "ascii") and target.unit > MAX_SERIAL_UNIT:
            errors.append(f"{where}.unit: serial lines address units 1..{MAX_SERIAL_UNIT}")
    return errors


def shared_gateway_errors(buses: Iterable[SerialBus | TcpBus]) -> list[str]:
    """A gateway's serial line carries one frame at a time: one bus per gateway port."""
    seen: dict[tuple[str, int], str] = {}
    errors = []
    for bus in buses:
        if getattr(bus, "serial_behind", None) is None:
            continue
        host, port = getattr(bus, "host", ""), getattr(bus, "tcp_port", 0)
        other = seen.setdefault((host, port), bus.id)
        if other != bus.id:
            errors.append(
                f"buses.{bus.id}.host: {host}:{port} is bus {other!r} too; "
                "one serial line carries one frame at a time, so give its devices one bus"
            )
    return errors


def duplicates(section: str, ids: list[str]) -> list[str]:
    counts = Counter(ids)
    return [f"{section}.{i}: id used {n} times" for i, n in counts.items() if n > 1]


def config_schema() -> dict[str, Any]:
    """JSON Schema of the config file (for editor completion)."""
    return Config.model_json_schema()
