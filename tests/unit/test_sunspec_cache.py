"""``mapping: sunspec`` in a config (bridge/config) and the built mapping's cache in the
state folder (bridge/sunspec/cache.py): what is accepted, what is refused with the
device and field named, and which cache a device may use."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import pytest

from bridge.config import load_config_data
from bridge.core.identify import snippet
from bridge.core.yaml_source import parse_yaml
from bridge.errors import ConfigError, DeviceExceptionError
from bridge.sunspec import cache
from bridge.sunspec.image import build_image
from bridge.sunspec.mapping import BuiltMapping, build_from_device
from bridge.sunspec.walk import Chain
from tests.sunspec_devices import every_image

BUSES = [
    {"id": "tcp", "transport": "tcp", "host": "127.0.0.1"},
    {"id": "line", "transport": "ascii", "port": "/dev/ttyUSB0"},
]


def load(folder: Path, *devices: dict[str, Any], **bridge: Any) -> Any:
    data = {"bridge": bridge, "buses": BUSES, "devices": list(devices)}
    return load_config_data(data, folder / "config.yaml")


def issues(folder: Path, *devices: dict[str, Any]) -> tuple[str, ...]:
    with pytest.raises(ConfigError) as caught:
        load(folder, *devices)
    return tuple(caught.value.issues)


def device(**fields: Any) -> dict[str, Any]:
    return {"id": "inverter", "bus": "tcp", "unit": 1, "mapping": "sunspec"} | fields


def built(name: str = "inverter_123", base: int = 40000) -> tuple[Chain, BuiltMapping]:
    registers = build_image(every_image()[name], base, name).registers

    async def read(address: int, count: int) -> list[int]:
        if not all(a in registers for a in range(address, address + count)):
            raise DeviceExceptionError(2, "illegal data address", "fail")
        return [registers[a] for a in range(address, address + count)]

    return asyncio.run(build_from_device(read))


# --- the config ---------------------------------------------------------------------------


def test_mapping_sunspec_needs_no_file_and_polls_nothing_until_walked(tmp_path: Path) -> None:
    loaded = load(tmp_path, device(poll={"entities": {"ac_power*": "fast"}}))
    config = loaded.config.devices[0]
    assert config.is_sunspec and config.sunspec_bases is None  # auto: 40000, 50000, 0
    assert loaded.mappings["inverter"].entities == {}
    assert loaded.config.bridge.state_dir == Path("state")


@pytest.mark.parametrize(("base", "bases"), [("auto", None), (0, (0,)), (50000, (50000,))])
def test_a_configured_base_is_the_only_one_walked(
    tmp_path: Path, base: Any, bases: tuple[int, ...] | None
) -> None:
    loaded = load(tmp_path, device(sunspec={"base": base}))
    assert loaded.config.devices[0].sunspec_bases == bases


def test_sunspec_settings_only_with_mapping_sunspec(tmp_path: Path) -> None:
    (found,) = issues(tmp_path, device(mapping="soft_starter", sunspec={"base": 40000}))
    assert found.startswith("devices.inverter: sunspec: only with mapping: sunspec")


@pytest.mark.parametrize("base", [-1, 65533, "40000x", "manual", True, 1.5])
def test_a_base_outside_the_register_space_is_refused(tmp_path: Path, base: Any) -> None:
    assert issues(tmp_path, device(sunspec={"base": base})) == (
        "devices.inverter.sunspec.base: auto, or the holding register of the SunS marker "
        "(0..65532)",
    )


def test_options_and_modbus_ascii_are_refused(tmp_path: Path) -> None:
    found = issues(tmp_path, device(bus="line", options={"model": "x"}))
    assert found == (
        "devices.inverter.options.model: a SunSpec mapping has no options",
        "devices.inverter.bus: SunSpec devices are read over tcp, rtu and rtu-over-tcp",
    )


def test_a_mapping_file_named_sunspec_is_not_read(tmp_path: Path) -> None:
    (tmp_path / "sunspec").write_text("not a mapping", encoding="utf-8")
    assert load(tmp_path, device()).mappings["inverter"].entities == {}


# --- the cache ----------------------------------------------------------------------------


def test_the_config_loads_the_cached_mapping(tmp_path: Path) -> None:
    chain, mapping = built()
    cache.store(tmp_path / "kept", "inverter", chain, mapping, bases=None, read_limit=125)
    loaded = load(tmp_path, device(), state_dir="kept")
    assert loaded.mappings["inverter"] == mapping.mapping()
    assert not list((tmp_path / "kept" / "sunspec").glob(".*"))  # no temporary file left


def test_a_cache_round_trips_with_its_signature(tmp_path: Path) -> None:
    chain, mapping = built("inverter_mppt", 50000)
    cache.store(tmp_path, "pv", chain, mapping, bases=(50000,), read_limit=60)
    found = cache.load(tmp_path, "pv", (50000,), 60)
    assert found is not None
    assert found.mapping == mapping.mapping()
    assert found.signature == cache.signature(chain)
    assert found.signature["base"] == 50000
    assert [m[0] for m in found.signature["models"]] == list(chain.model_ids)


@pytest.mark.parametrize(("bases", "read_limit"), [(None, 60), ((40000,), 125), (None, 125)])
def test_a_cache_built_another_way_is_not_used(
    tmp_path: Path, bases: tuple[int, ...] | None, read_limit: int
) -> None:
    chain, mapping = built()
    cache.store(tmp_path, "inverter", chain, mapping, bases=(50000,), read_limit=125)
    assert cache.load(tmp_path, "inverter", bases, read_limit) is None


def test_another_bridge_version_builds_afresh(tmp_path: Path) -> None:
    chain, mapping = built()
    cache.store(tmp_path, "inverter", chain, mapping, bases=None, read_limit=125)
    _, sidecar = cache.paths(tmp_path, "inverter")
    record = json.loads(sidecar.read_text())
    record["setting"]["bridge"] = "0.0.1"
    sidecar.write_text(json.dumps(record))
    assert cache.load(tmp_path, "inverter", None, 125) is None


@pytest.mark.parametrize("damage", ["sidecar", "mapping", "no mapping", "no signature"])
def test_a_damaged_cache_is_ignored(
    tmp_path: Path, damage: str, caplog: pytest.LogCaptureFixture
) -> None:
    chain, mapping = built()
    cache.store(tmp_path, "inverter", chain, mapping, bases=None, read_limit=125)
    mapping_file, sidecar = cache.paths(tmp_path, "inverter")
    if damage == "sidecar":
        sidecar.write_text("{not json")
    elif damage == "mapping":
        mapping_file.write_text("entities: 3\n")
    elif damage == "no mapping":
        mapping_file.unlink()
    else:
        record = json.loads(sidecar.read_text())
        record["signature"] = None
        sidecar.write_text(json.dumps(record))
    assert cache.load(tmp_path, "inverter", None, 125) is None
    assert "the cached SunSpec mapping is not usable" in caplog.text


def test_no_cache_without_its_signature(tmp_path: Path) -> None:
    """A stop between the two writes leaves a mapping without a signature: not used."""
    chain, mapping = built()
    cache.store(tmp_path, "inverter", chain, mapping, bases=None, read_limit=125)
    cache.paths(tmp_path, "inverter")[1].unlink()
    assert cache.load(tmp_path, "inverter", None, 125) is None


def test_the_snippet_identify_prints_for_a_sunspec_device_is_a_valid_device(
    tmp_path: Path,
) -> None:
    (entry,) = parse_yaml(snippet("tcp", 3, "sunspec"), "identify's snippet")
    loaded = load(tmp_path, entry)
    assert loaded.config.devices[0].is_sunspec
    assert loaded.mappings[entry["id"]].entities == {}  # built at its first walk
