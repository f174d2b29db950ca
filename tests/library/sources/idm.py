"""iDM Navigator 2.0 as the kodebach/hacs-idm-heatpump integration and evcc read it (facts
only).

Both send the printed address as the wire address and read float32 low word first. The
integration reads input registers (04), evcc holding registers (03). Enum and on/off rows
(system mode, smart grid status, heat pump status, sum fault, compressor) are left out:
the mapping decodes them to labels or booleans; they are named in the notes.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC

KODEBACH = "kodebach/hacs-idm-heatpump@d49b5eacc90a131c0202ceae9b8f8036c1eecfde"


def _f(key: str, table: str, address: int, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, table, address, "f32", unit, scale, "little", name=name)


# custom_components/idm_heatpump/sensor_addresses.py: read_input_registers, float32
# word_order "little", uint16 rows with 0xFFFF as unavailable
KODEBACH_NAVIGATOR = (
    _f("pv_surplus", "input", 74, "kW", 1.0, "power_solar_surplus"),
    _f("outdoor_temperature", "input", 1000, "°C", 1.0, "temp_outside"),
    _f("outdoor_temperature_average", "input", 1002, "°C", 1.0, "temp_outside_avg"),
    SourcePoint("fault_number", "input", 1004, "u16", "", 1.0, name="failure_id"),
    _f("heat_storage_temperature", "input", 1008, "°C", 1.0, "temp_heat_storage"),
    _f("cold_storage_temperature", "input", 1010, "°C", 1.0, "temp_cold_storage"),
    _f("hot_water_bottom_temperature", "input", 1012, "°C", 1.0, "temp_water_heater_top"),
    _f("hot_water_top_temperature", "input", 1014, "°C", 1.0, "temp_water_heater_bottom"),
    _f("hot_water_tap_temperature", "input", 1030, "°C", 1.0, "temp_water_heater_tap"),
    SourcePoint(
        "hot_water_set_temperature", "input", 1032, "u16", "°C", 1.0, name="temp_water_target"
    ),
    _f("flow_temperature", "input", 1050, "°C", 1.0, "temp_heat_pump_flow"),
    _f("return_temperature", "input", 1052, "°C", 1.0, "temp_heat_pump_return"),
    _f("source_inlet_temperature", "input", 1056, "°C", 1.0, "temp_heat_source_input"),
    _f("source_outlet_temperature", "input", 1058, "°C", 1.0, "temp_heat_source_output"),
    _f("heat_energy_heating", "input", 1748, "kWh", 1.0, "energy_heat_heating"),
    _f("heat_energy_total", "input", 1750, "kWh", 1.0, "energy_heat_total"),
    _f("heat_energy_cooling", "input", 1752, "kWh", 1.0, "energy_heat_total_cooling"),
    _f("heat_energy_hot_water", "input", 1754, "kWh", 1.0, "energy_heat_total_water"),
    _f("thermal_power", "input", 1790, "kW", 1.0, "power_current"),
    _f("electrical_power", "input", 4122, "kW", 1.0, "power_usage"),
)

# templates/definition/charger/idm.yaml (heatpump): setmaxpower, power, temp by tempsource
EVCC_IDM = (
    _f("pv_surplus", "holding", 74, "kW", 1.0, "setmaxpower"),
    _f("heat_storage_temperature", "holding", 1008, "°C", 1.0, "temp (buffer)"),
    _f("hot_water_bottom_temperature", "holding", 1012, "°C", 1.0, "temp (warmwater_bottom)"),
    _f("hot_water_top_temperature", "holding", 1014, "°C", 1.0, "temp (warmwater_top)"),
    _f("electrical_power", "holding", 4122, "W", 1000.0, "power"),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "idm_navigator": (
        SourceDefinition(
            device="idm_navigator",
            source="community:kodebach/hacs-idm-heatpump",
            ref=f"{KODEBACH}:custom_components/idm_heatpump/sensor_addresses.py",
            points=KODEBACH_NAVIGATOR,
            notes=(
                "reads input registers (04) in contiguous runs of at most 32 registers, "
                "device id 1; writes with 16",
                "1012's key says top, its German title (SENSOR_NAMES) says "
                "'unten' (bottom); 1014 the reverse: keyed here by the titles",
                "a float of -1 in a value with minimum 0 (energies, power use) is 'unavailable'",
                "1005 system mode: 0xFFFF off, 0 standby, 1 automatic, 2 away, 3 holiday, "
                "4 hot water only, 5 heating/cooling only; 1006 smart grid: 0 grid blocked "
                "solar off, 1 grid allowed solar off, 2 grid unused solar on, 4 grid blocked "
                "solar on; 1090 heat pump status flags 1 heating, 2 cooling, 4 water, "
                "8 defrosting; 1099 sum fault and 1100-1103 compressors as on/off",
            ),
        ),
        SourceDefinition(
            device="idm_navigator",
            source="evcc",
            ref=f"{EVCC}:templates/definition/charger/idm.yaml",
            points=EVCC_IDM,
            notes=(
                "reads holding registers (03), decode float32s (low word first); writes "
                "the surplus to 74 with 16 (writeholdings), its watts x0.001",
                "comments: 1014 Trinkwasser oben (top), 1012 unten (bottom), 1008 "
                "Wärmespeicher (heat storage), 4122 the pump's present power input",
            ),
        ),
    ),
}
