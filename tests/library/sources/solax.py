"""SolaX X3-Hybrid G4 as independent sources read it (facts only).

Both read input registers (function 4) for measurements at the document's hex addresses
(offset 0) and take 32-bit values low word first. wills106's plugin reads the settings
back from holding registers; evcc reads no setting and writes with function 6.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC

SOLAX_MODBUS = "wills106/homeassistant-solax-modbus@27875b3b2ea9fa81f870e8e34590a000730234c0"


def _in(
    key: str, address: int, kind: str, unit: str, scale: float = 1.0, name: str = ""
) -> SourcePoint:
    order = "little" if kind in ("u32", "s32") else "big"
    return SourcePoint(key, "input", address, kind, unit, scale, order, name=name)


def _hold(key: str, address: int, unit: str, scale: float = 1.0, name: str = "") -> SourcePoint:
    return SourcePoint(key, "holding", address, "u16", unit, scale, name=name)


def _phases(
    key: str, addresses: tuple[int, int, int], kind: str, unit: str, scale: float, name: str
) -> tuple[SourcePoint, ...]:
    return tuple(
        _in(f"{key}_l{i}", a, kind, unit, scale, f"{name}_l{i}") for i, a in enumerate(addresses, 1)
    )


# custom_components/solax_modbus/plugin_solax.py: the entries a HYBRID | GEN4 | X3 unit gets
WILLS106_X3_G4 = (
    _in("pv1_voltage", 0x03, "u16", "V", 0.1, "pv_voltage_1"),
    _in("pv2_voltage", 0x04, "u16", "V", 0.1, "pv_voltage_2"),
    _in("pv1_current", 0x05, "u16", "A", 0.1, "pv_current_1"),
    _in("pv2_current", 0x06, "u16", "A", 0.1, "pv_current_2"),
    _in("inverter_temperature", 0x08, "s16", "°C", 1.0, "inverter_temperature"),
    _in("pv1_power", 0x0A, "u16", "W", 1.0, "pv_power_1"),
    _in("pv2_power", 0x0B, "u16", "W", 1.0, "pv_power_2"),
    _in("battery_voltage", 0x14, "s16", "V", 0.1, "battery_voltage_charge"),
    _in("battery_current", 0x15, "s16", "A", 0.1, "battery_current_charge"),
    _in("battery_power", 0x16, "s16", "W", 1.0, "battery_power_charge"),
    _in("battery_temperature", 0x18, "s16", "°C", 1.0, "battery_temperature"),
    _in("battery_soc", 0x1C, "u16", "%", 1.0, "battery_capacity"),
    _in("battery_discharge_energy_total", 0x1D, "u32", "kWh", 0.1, "battery_output_energy_total"),
    _in("battery_discharge_energy_today", 0x20, "u16", "kWh", 0.1, "battery_output_energy_today"),
    _in("battery_charge_energy_total", 0x21, "u32", "kWh", 0.1, "battery_input_energy_total"),
    _in("battery_charge_energy_today", 0x23, "u16", "kWh", 0.1, "battery_input_energy_today"),
    _in("bms_charge_max_current", 0x24, "u16", "A", 0.1, "bms_charge_max_current"),
    _in("bms_discharge_max_current", 0x25, "u16", "A", 0.1, "bms_discharge_max_current"),
    _in("feedin_power", 0x46, "s32", "W", 1.0, "measured_power"),
    _in("grid_export_energy_total", 0x48, "u32", "kWh", 0.01, "grid_export_total"),
    _in("grid_import_energy_total", 0x4A, "u32", "kWh", 0.01, "grid_import_total"),
    _in("inverter_energy_today", 0x50, "u16", "kWh", 0.1, "today_s_yield"),
    _in("inverter_energy_total", 0x52, "u32", "kWh", 0.1, "total_yield"),
    _in("bus_voltage", 0x66, "u16", "V", 0.1, "bus_volt"),
    *_phases("inverter_voltage", (0x6A, 0x6E, 0x72), "u16", "V", 0.1, "inverter_voltage"),
    *_phases("inverter_current", (0x6B, 0x6F, 0x73), "s16", "A", 0.1, "inverter_current"),
    *_phases("inverter_power", (0x6C, 0x70, 0x74), "s16", "W", 1.0, "inverter_power"),
    *_phases("inverter_frequency", (0x6D, 0x71, 0x75), "u16", "Hz", 0.01, "inverter_frequency"),
    *_phases("feedin_power", (0x82, 0x84, 0x86), "s32", "W", 1.0, "measured_power"),
    _in("pv_energy_total", 0x94, "u32", "kWh", 0.1, "total_solar_energy"),
    _in("pv_energy_today", 0x96, "u16", "kWh", 0.1, "today_s_solar_energy"),
    _in("grid_export_energy_today", 0x98, "u32", "kWh", 0.01, "today_s_export_energy"),
    _in("grid_import_energy_today", 0x9A, "u32", "kWh", 0.01, "today_s_import_energy"),
    _in("battery_soh", 0xBF, "u16", "%", 1.0, "battery_soh"),
    _in("grid_frequency", 0xC8, "u16", "Hz", 0.01, "grid_frequency"),
    *_phases("grid_voltage", (0xCA, 0xCB, 0xCC), "u16", "V", 0.1, "grid_voltage"),
    *_phases("grid_current", (0xCE, 0xCF, 0xD0), "s16", "A", 0.1, "grid_current"),
    _hold("battery_charge_max_current", 0x90, "A", 0.1, "battery_charge_max_current"),
    _hold("battery_discharge_max_current", 0x91, "A", 0.1, "battery_discharge_max_current"),
    _hold("export_factory_limit", 0xB5, "W", 1.0, "export_control_factory_limit"),
    _hold("export_limit", 0xB6, "W", 10.0, "export_control_user_limit"),
    _hold("rated_power", 0xBA, "W", 1.0, "inverter_power_type"),
)

# templates/definition/meter/solax.yaml (usage grid, pv and battery)
EVCC_SOLAX = (
    _in("pv1_power", 0x0A, "u16", "W", 1.0, "pv power (Powerdc1)"),
    _in("pv2_power", 0x0B, "u16", "W", 1.0, "pv power (Powerdc2)"),
    _in("battery_power", 0x16, "s16", "W", 1.0, "battery power"),
    _in("battery_soc", 0x1C, "u16", "%", 1.0, "battery soc"),
    _in("feedin_power", 0x46, "s32", "W", 1.0, "grid power"),
    _in("grid_import_energy_total", 0x4A, "u32", "kWh", 0.01, "grid energy"),
    _in("pv_energy_total", 0x94, "u32", "kWh", 0.1, "pv energy"),
    *_phases("grid_voltage", (0xCA, 0xCB, 0xCC), "u16", "V", 0.1, "grid voltages"),
    *_phases("grid_current", (0xCE, 0xCF, 0xD0), "s16", "A", 0.1, "grid currents"),
)

SOLAX_X3_HYBRID = (
    SourceDefinition(
        device="solax_x3_hybrid",
        source="community:wills106/homeassistant-solax-modbus",
        ref=f"{SOLAX_MODBUS}:custom_components/solax_modbus/plugin_solax.py",
        points=WILLS106_X3_G4,
        notes=(
            "tells the family by the serial number at holding 0x0000 (7 registers): H34 is "
            "an X3-Hybrid G4 of 5-15 kW",
            "its 32-bit default is low word first (order32 little)",
            "measured_power (0x46) goes through a user gain and offset (default 100 %, 0 W)",
            "writes the settings at the document's write addresses: charger use mode 0x1F, "
            "manual mode 0x20, battery currents 0x24/0x25 (0.1 A), export limit 0x42 (10 W "
            "on the X3), the remote control block from 0x7C with function 16",
            "reads the power factor 0xC4 raw as a percentage (no point here: a unit of its own)",
            "reads no fault words for the G4 (0x40-0x45)",
        ),
    ),
    SourceDefinition(
        device="solax_x3_hybrid",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/solax.yaml",
        points=EVCC_SOLAX,
        notes=(
            "negates the feed-in power (0x46, scale -1) into its grid power (+ import) and "
            "the battery power (0x16, scale -1) into + discharging: the register and its "
            "scale are the same, the sign is evcc's convention",
            "modbus default 19200 baud",
            "battery control writes with function 6: charger use mode 0x1F, manual mode "
            "0x20, battery awaken 0x56",
        ),
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {"solax_x3_hybrid": SOLAX_X3_HYBRID}
