"""Every transcribed source definition is well-formed, and every library device is listed."""

from __future__ import annotations

import re

import pytest

from bridge.core.mapping import library_index
from tests.library.source import (
    TABLES,
    TYPES,
    UNITS,
    WORD_ORDERS,
    SourceDefinition,
    SourcePoint,
    disagreements,
    overlaps,
    registers,
)
from tests.library.sources import SOURCES

# every device of the library (mappings/library/; the seeds were written from their own
# manuals): each has its independent sources here (a device with none maps to ())
DEVICES = frozenset(name for name, path in library_index().items() if "library" in path.parts)
SOURCE_NAMES = re.compile(
    r"^(mbmd|evcc|openems|openwb|tasmota|victron|vendor|(ha-)?community:[\w.-]+/[\w.-]+)$"
)
REPO_REF = re.compile(r"^[\w.-]+/[\w.-]+@[0-9a-f]{40}:\S+$")
KEY = re.compile(r"^[a-z][a-z0-9]*(_[a-z0-9]+)*$")
# (device, source, key, other key) pairs where a source really reads one register twice
SHARED_REGISTERS: frozenset[tuple[str, str, str, str]] = frozenset()
# "<key> <field>" where a device's sources read a point differently (field "key": a start
# address read under different keys); the mapping authors resolve each one in their notes
KNOWN_DISAGREEMENTS: dict[str, frozenset[str]] = {
    "growatt_sph": frozenset(
        f"{key} type"
        for key in (
            "input_power",
            "pv_energy_total",
            "battery_discharge_power",
            "battery_charge_power",
            "battery_energy_charged",
            "battery_energy_discharged",
            "grid_import_power",
            "grid_export_power",
            "grid_energy_import",
            "grid_energy_export",
        )
    ),
    "growatt_min_mod": frozenset(
        {"grid_import_power address", "grid_export_power address"}
        | {
            f"{key} type"
            for key in (
                "input_power",
                "pv1_power",
                "pv2_power",
                "pv3_power",
                "pv4_power",
                "grid_import_power",
                "grid_export_power",
                "pv_energy_total",
                "grid_energy_import",
                "grid_energy_export",
                "battery_energy_charged",
                "battery_energy_discharged",
                "battery_charge_power",
                "battery_discharge_power",
            )
        }
    ),
    "huawei_sun2000": frozenset(
        {
            "storage_soc type",
            "grid_energy_export type",
            "grid_energy_import type",
            "export_limit_percent type",
        }
    ),
    "eastron_sdm630": frozenset({"frequency scale"}),
    "carlo_gavazzi_em24": frozenset(
        {
            "current_l1 scale",
            "current_l2 scale",
            "current_l3 scale",
            "frequency type",
            "energy_import address",
        }
    ),
    "carlo_gavazzi_em340": frozenset({"frequency type"}),
    "carlo_gavazzi_em24_e1": frozenset(
        {"frequency type"}
        | {
            f"{key} table"
            for key in (
                "voltage_l1",
                "voltage_l2",
                "voltage_l3",
                "current_l1",
                "current_l2",
                "current_l3",
                "power_l1",
                "power_l2",
                "power_l3",
                "power",
                "frequency",
                "energy_import",
                "energy_import_l1",
                "energy_import_l2",
                "energy_import_l3",
                "energy_export",
            )
        }
    ),
    "chint_dtsu666": frozenset(
        {"energy_import address", "energy_export address", "power_factor scale"}
        | {
            f"{key} table"
            for key in (
                "voltage_l1",
                "voltage_l2",
                "voltage_l3",
                "current_l1",
                "current_l2",
                "current_l3",
                "power",
                "power_l1",
                "power_l2",
                "power_l3",
                "power_factor",
                "frequency",
                "energy_export",
            )
        }
    ),
    "chint_ddsu666": frozenset(
        {"0x4000 key", "energy_export address"}
        | {f"{key} table" for key in ("voltage", "current", "power", "frequency", "energy_export")}
    ),
    "orno_we514": frozenset(
        {
            "frequency type",
            "voltage type",
            "power_factor type",
            "energy_total type",
            "energy_total scale",
            "reactive_energy_total type",
            "reactive_energy_total scale",
        }
    ),
    "abb_terra_ac": frozenset({"error_code_raw type", "error_code_raw word_order"}),
    "phoenix_contact_ev": frozenset(
        {"current_limit_setpoint scale"}
        | {
            f"{key} type"
            for key in (
                "voltage_l1",
                "voltage_l2",
                "voltage_l3",
                "current_l1",
                "current_l2",
                "current_l3",
                "power",
            )
        }
    ),
    "saia_ale3": frozenset({"0x001b key", "0x001f key"}),
    "finder_7m38": frozenset({"frequency address"}),
    "deye_hybrid": frozenset(
        {f"{key} type" for key in ("load_power_l1", "load_power_l2", "load_power_l3", "load_power")}
        | {f"{key} type" for key in ("load_voltage_l1", "load_voltage_l2", "load_voltage_l3")}
        | {"pv1_power type", "pv2_power type", "battery_soc type", "grid_frequency type"}
    ),
    "orno_we516": frozenset(
        {"reactive_power_l1 scale", "reactive_power_l2 scale", "reactive_power_l3 scale"}
    ),
    # evcc reads the GX with function 4, the others with 3 (the GX answers both alike)
    "victron_gx_system": frozenset(
        f"{key} table"
        for key in (
            "pv_ac_output_power_l1",
            "pv_ac_output_power_l2",
            "pv_ac_output_power_l3",
            "pv_ac_input_power_l1",
            "pv_ac_input_power_l2",
            "pv_ac_input_power_l3",
            "grid_power_l1",
            "grid_power_l2",
            "grid_power_l3",
            "battery_power",
            "battery_soc",
            "pv_dc_power",
        )
    ),
    "marstek_venus_e": frozenset(
        {
            "ac_frequency type",
            "ac_offgrid_current type",
            "energy_discharge type",
            "max_cell_voltage type",
            "min_cell_voltage type",
        }
    ),
    "sungrow_sh_rt": frozenset(
        {
            "total_output_energy scale",
            "reactive_power scale",
            "power_factor scale",
            "battery_soc type",
            "nominal_power scale",
            "grid_frequency_coarse scale",
        }
    ),
    # 0x138f: input 5007 (temperature) and holding 5007 (power limitation ratio), two tables
    # at one wire address, which the "key" comparison does not tell apart
    "sungrow_sg_rt": frozenset(
        {
            "active_power type",
            "current_l1 type",
            "current_l2 type",
            "current_l3 type",
            "0x138f key",
        }
    ),
    "nibe_s": frozenset(
        {
            "hot_water_top_temperature type",
            "hot_water_charging_temperature type",
            "power_consumption type",
            "power_consumption word_order",
            "energy_consumed type",
            "energy_consumed word_order",
            # input 11 (brine out) and holding 11 (degree minutes): one address, two tables
            "0x000b key",
        }
    ),
    "idm_navigator": frozenset(
        {
            f"{key} table"
            for key in (
                "pv_surplus",
                "heat_storage_temperature",
                "hot_water_bottom_temperature",
                "hot_water_top_temperature",
                "electrical_power",
            )
        }
    ),
}

DEFINITIONS = [d for defs in SOURCES.values() for d in defs]
IDS = [f"{d.device}-{d.source}" for d in DEFINITIONS]


def test_every_device_is_listed() -> None:
    assert not DEVICES - SOURCES.keys(), "devices without a SOURCES entry"


@pytest.mark.parametrize(("device", "definitions"), SOURCES.items())
def test_definitions_belong_to_their_device(
    device: str, definitions: tuple[SourceDefinition, ...]
) -> None:
    assert all(d.device == device for d in definitions)
    sources = [d.source for d in definitions]
    assert len(sources) == len(set(sources)), "one definition per device per source"


@pytest.mark.parametrize("definition", DEFINITIONS, ids=IDS)
def test_definition_is_well_formed(definition: SourceDefinition) -> None:
    assert SOURCE_NAMES.match(definition.source)
    if definition.source != "vendor":
        assert REPO_REF.match(definition.ref), definition.ref
    assert definition.points
    keys = [p.key for p in definition.points]
    assert len(keys) == len(set(keys)), "keys unique per definition"
    for p in definition.points:
        assert KEY.match(p.key), p.key
        assert p.table in TABLES, p
        assert p.type in TYPES, p
        assert p.unit in UNITS, p
        assert p.word_order in WORD_ORDERS, p
        assert p.scale > 0, p
        assert p.address >= 0 and registers(p).stop <= 65536, p


@pytest.mark.parametrize("definition", DEFINITIONS, ids=IDS)
def test_points_do_not_overlap(definition: SourceDefinition) -> None:
    for first, second, address in overlaps(definition):
        pair = (definition.device, definition.source, first, second)
        assert pair in SHARED_REGISTERS, f"{second} overlaps {first} at {address:#06x}"


def test_shared_registers_are_real() -> None:
    """Every declared exception names two points of one definition that do overlap."""
    for device, source, first, second in SHARED_REGISTERS:
        (definition,) = [d for d in SOURCES[device] if d.source == source]
        points = {p.key: p for p in definition.points}
        a, b = points[first], points[second]
        assert a.table == b.table and set(registers(a)) & set(registers(b))


@pytest.mark.parametrize(("device", "definitions"), SOURCES.items())
def test_disagreements_are_declared(device: str, definitions: tuple[SourceDefinition, ...]) -> None:
    found = {f"{d.key} {d.field}" for d in disagreements(definitions)}
    assert found == KNOWN_DISAGREEMENTS.get(device, frozenset())


def test_known_disagreements_name_listed_devices() -> None:
    assert KNOWN_DISAGREEMENTS.keys() <= SOURCES.keys()


def _definition(source: str, *points: SourcePoint) -> SourceDefinition:
    return SourceDefinition("demo", source, f"demo/{source}@{'0' * 40}:x", points)


def test_overlaps_finds_a_shared_register() -> None:
    a = SourcePoint("power", "input", 0x0C, "f32", "W")
    b = SourcePoint("power_l1", "input", 0x0D, "u16", "W")
    c = SourcePoint("current", "holding", 0x0C, "u16", "A")
    assert overlaps(_definition("x", a, b, c)) == [("power", "power_l1", 0x0D)]
    assert overlaps(_definition("x", a, c)) == []


def test_disagreements_compare_each_field() -> None:
    base = SourcePoint("power", "input", 0x0C, "s32", "W", 0.1)
    same_in_kw = SourcePoint("power", "input", 0x0C, "s32", "kW", 0.0001)
    assert disagreements((_definition("a", base), _definition("b", same_in_kw))) == []
    moved = SourcePoint("power", "holding", 0x0E, "s32", "W", 0.1, "little")
    found = disagreements((_definition("a", base), _definition("b", moved)))
    assert [(d.key, d.field) for d in found] == [
        ("power", "table"),
        ("power", "address"),
        ("power", "word_order"),
    ]
    assert found[1].values == (("a", "0x000c"), ("b", "0x000e"))


def test_disagreements_ignore_the_word_order_of_one_register() -> None:
    big = SourcePoint("frequency", "input", 0x33, "u16", "Hz", 0.1)
    little = SourcePoint("frequency", "input", 0x33, "u16", "Hz", 0.1, "little")
    assert disagreements((_definition("a", big), _definition("b", little))) == []


def test_disagreements_find_one_register_under_two_keys() -> None:
    imp = SourcePoint("energy_import", "input", 0x4000, "f32", "kWh")
    exp = SourcePoint("energy_export", "input", 0x4000, "f32", "kWh")
    found = disagreements((_definition("a", imp), _definition("b", exp)))
    assert [(d.key, d.field) for d in found] == [("0x4000", "key")]


@pytest.mark.parametrize("device", sorted(DEVICES))
def test_every_library_device_has_two_independent_sources(device: str) -> None:
    """docs/library.md says how the devices were chosen: each is read by at least two
    independent projects (the vendor's own document is not one of them)."""
    independent = {d.source for d in SOURCES.get(device, ()) if d.source != "vendor"}
    assert len(independent) >= 2, independent
