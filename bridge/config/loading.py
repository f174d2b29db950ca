"""Loading a config file: ``load_config`` validates it whole and loads every mapping it
names; ``load_device_mapping`` loads one device's mapping and checks the device against it.

Errors are reported as ``path: message`` rows (``devices.borehole_pump.unit: ...``), all
at once, and nothing is started on a bad file.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import TypeAdapter, ValidationError

from bridge.config.checks import (
    device_password_errors,
    folder_errors,
    secret_errors,
    topic_errors,
    unique,
    web_token_errors,
    whole_read_errors,
    with_ids,
)
from bridge.config.model import (
    Bus,
    Config,
    DeviceConfig,
    ManagementConfig,
    SerialBus,
    TcpBus,
    reference_errors,
)
from bridge.config.mqtt import MqttConfig
from bridge.core.counters import counters_of
from bridge.core.mapping import Mapping, format_validation_errors, load_mapping
from bridge.core.mapping import resolve_mapping_path as _resolve
from bridge.core.override import EXTENDS
from bridge.core.yaml_source import parse_yaml, read_yaml
from bridge.errors import ConfigError, MappingError
from bridge.sunspec import cache as sunspec_cache

DEFAULT_STATE = Path("state")  # ManagementConfig.state_dir's default
OVERRIDES = (
    "mappings"  # under bridge.state_dir: each device's override (bridge/config/user_mapping.py)
)
MAX_READ_REGISTERS = 125  # a SunSpec walk's read limit unless the device's protocol says less


@dataclass(frozen=True, slots=True)
class LoadedConfig:
    """A validated config with each device's mapping loaded and its options checked."""

    path: Path
    config: Config
    mappings: dict[str, Mapping]


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
    state = path.parent / config.bridge.state_dir
    mappings, errors = _load_mappings(config.buses, config.devices, path.parent, state)
    errors += secret_errors(config.mqtt)
    errors += web_token_errors(config.bridge.web)
    errors += device_password_errors(config.devices, mappings)
    errors += whole_read_errors(config.devices, mappings)
    errors += topic_errors(config.mqtt, config.devices, mappings)
    errors += folder_errors(config.bridge, path.parent)
    if errors:
        raise ConfigError(str(path), errors)
    return LoadedConfig(path=path, config=config, mappings=mappings)


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
    state = path.parent / (bridge.state_dir if bridge is not None else DEFAULT_STATE)
    mappings, more = _load_mappings(buses, devices, path.parent, state)
    errors += more + device_password_errors(devices, mappings)
    if mqtt is not None:
        errors += secret_errors(mqtt) + topic_errors(mqtt, devices, mappings)
    if bridge is not None:
        errors += folder_errors(bridge, path.parent) + web_token_errors(bridge.web)
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
    buses: Iterable[SerialBus | TcpBus],
    devices: Iterable[DeviceConfig],
    base: Path,
    state_dir: Path,
) -> tuple[dict[str, Mapping], list[str]]:
    loaded: dict[str, Mapping] = {}
    cache: dict[Path, Mapping] = {}
    errors: list[str] = []
    known = {bus.id: bus for bus in buses}
    for device in devices:
        if device.bus not in known:
            continue  # reported as a reference
        mapping, problems = load_device_mapping(
            device, known[device.bus], base, cache, state_dir=state_dir
        )
        errors += problems
        if mapping is not None:
            loaded[device.id] = mapping
    return loaded, errors


def load_device_mapping(
    device: DeviceConfig,
    bus: SerialBus | TcpBus,
    base: Path,
    cache: dict[Path, Mapping] | None = None,
    *,
    state_dir: Path | None = None,
) -> tuple[Mapping | None, list[str]]:
    """A device's mapping (relative paths from ``base``) and every problem with it for
    this device, as ``devices.<id>.<field>: message`` rows: the file itself, the device's
    options, a transport the model does not speak. The mapping is None if it cannot load.
    The device's override under ``state_dir`` (bridge/config/user_mapping.py) is its
    mapping when it exists.
    A ``mapping: sunspec`` device's is the one cached under ``state_dir`` (bridge/sunspec/
    cache.py), else one with no entity until its chain is walked (bridge/sunspec_devices.py)."""
    where = f"devices.{device.id}"
    cache = {} if cache is None else cache
    if device.is_sunspec:
        return _sunspec_mapping(device, bus, state_dir or base / DEFAULT_STATE)
    try:
        path = _with_override(
            device, _resolve(device.mapping, base), state_dir or base / DEFAULT_STATE
        )
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
    counters = counters_of(mapping.points(device.options).values()) if not errors else {}
    for key in device.counter_confirm if not errors else ():
        if key not in counters:
            known = ", ".join(sorted(counters)) or "none"
            errors.append(f"{where}.counter_confirm.{key}: not a counter of the mapping ({known})")
    for pattern in device.poll.rule().unmatched(mapping.entities):
        errors.append(f"{where}.poll.entities.{pattern}: no entity of {mapping.model} matches")
    if bus.transport == "ascii" and "ascii" not in mapping.protocol.transports:
        errors.append(f"{where}.bus: {mapping.model} does not speak Modbus ASCII")
    return mapping, errors


def _with_override(device: DeviceConfig, path: Path, state_dir: Path) -> Path:
    """The device's override file (bridge/config/user_mapping.py) when there is one, else
    ``path``; MappingError when it extends another mapping than ``path``."""
    override = override_path(state_dir, device.id)
    try:
        if not override.is_file() or override.resolve() == path.resolve():
            return path
    except (OSError, ValueError):  # an id no file can be named after has no override
        return path
    try:
        ref = read_yaml(override).get(EXTENDS)
        extended = _resolve(ref, override.parent) if isinstance(ref, str) else None
    except (OSError, ValueError, AttributeError) as exc:
        raise MappingError(str(override), [f"cannot read it: {exc}"]) from None
    if extended is None or extended.resolve() != path.resolve():
        raise MappingError(
            str(override),
            [
                f"extends {ref!r}, not the device's mapping {device.mapping!r}: remove the "
                "file or make it extend the device's mapping"
            ],
        )
    return override


def _sunspec_mapping(
    device: DeviceConfig, bus: SerialBus | TcpBus, state_dir: Path
) -> tuple[Mapping, list[str]]:
    """A SunSpec device's cached mapping (or the pending one) and the settings it cannot
    have: options (a built mapping has none), Modbus ASCII. Its ``poll.entities`` name
    entities of a mapping not built yet: one that names none is not an error."""
    where = f"devices.{device.id}"
    errors = [f"{where}.options.{o}: a SunSpec mapping has no options" for o in device.options]
    if bus.transport == "ascii":
        errors.append(f"{where}.bus: SunSpec devices are read over tcp, rtu and rtu-over-tcp")
    limit = device.protocol.max_read_registers or MAX_READ_REGISTERS
    cached = sunspec_cache.load(state_dir, device.id, device.sunspec_bases, limit)
    return (cached.mapping if cached is not None else sunspec_cache.pending()), errors


def override_path(state_dir: Path, device_id: str) -> Path:
    """Where a device's override file lives (bridge/config/user_mapping.py)."""
    return state_dir / OVERRIDES / f"{device_id}.yaml"
