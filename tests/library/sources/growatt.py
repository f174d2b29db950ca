"""Growatt MIN TL-X(H) / MOD TL3-X(H) inverters as independent sources read them (facts only).

The TL-X map of Growatt's "Inverter Modbus RTU Protocol" V1.24: input registers (function
4) 3000-3249, 32-bit values high word first. evcc's growatt-hybrid-tlxh template and
openWB's growatt module (version "TL-X") read the few points their energy managers need;
WouterTuinstra's Growatt Local Modbus integration reads the whole block for Home Assistant.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC, OPENWB

GROWATT_LOCAL = (
    "WouterTuinstra/Homeassistant-Growatt-Local-Modbus@3f81aca51cdb9cb33afdb202a12bf91272761f19"
)


def _i(
    key: str, address: int, type_: str, unit: str, scale: float = 1.0, name: str = ""
) -> SourcePoint:
    return SourcePoint(key, "input", address, type_, unit, scale, name=name)


def _h(
    key: str, address: int, type_: str, unit: str, scale: float = 1.0, name: str = ""
) -> SourcePoint:
    return SourcePoint(key, "holding", address, type_, unit, scale, name=name)


# templates/definition/meter/growatt-hybrid-tlxh.yaml (register scale; evcc's own signs in
# the notes)
EVCC_TLXH = (
    _i("pv1_power", 3005, "u32", "W", 0.1, "PV1 power"),
    _i("pv2_power", 3009, "u32", "W", 0.1, "PV2 power"),
    _i("pv3_power", 3013, "u32", "W", 0.1, "PV3 power"),
    _i("pv4_power", 3017, "u32", "W", 0.1, "PV4 power"),
    _i("grid_import_power", 3041, "u32", "W", 0.1, "Total forward power"),
    _i("grid_export_power", 3043, "u32", "W", 0.1, "Total reverse power"),
    _i("pv_energy_total", 3053, "u32", "kWh", 0.1, "PV energy total"),
    _i("grid_energy_import", 3069, "u32", "kWh", 0.1, "Total energy to user"),
    _i("battery_energy_discharged", 3127, "u32", "kWh", 0.1, "Total discharge energy"),
    _i("battery_soc", 3171, "u16", "%", 1.0, "SOC"),
    _i("battery_discharge_power", 3178, "u32", "W", 0.1, "Discharge power"),
    _i("battery_charge_power", 3180, "u32", "W", 0.1, "Pcharge1 Charge power"),
)

# packages/modules/devices/growatt/growatt/{inverter,counter,bat}.py, version TL-X
# (register scale; openWB's own signs in the notes; energies in Wh: raw x 100)
OPENWB_TLX = (
    _i("input_power", 3001, "u32", "W", 0.1, "inverter power"),
    _i("power_l1", 3028, "s32", "W", 0.1, "powers[0]"),
    _i("power_l2", 3032, "s32", "W", 0.1, "powers[1]"),
    _i("power_l3", 3036, "s32", "W", 0.1, "powers[2]"),
    _i("grid_import_power", 3041, "u32", "W", 0.1, "power_in"),
    _i("grid_export_power", 3043, "u32", "W", 0.1, "power_out"),
    _i("pv_energy_total", 3053, "u32", "Wh", 100.0, "inverter exported"),
    _i("grid_energy_import", 3069, "u32", "Wh", 100.0, "counter imported"),
    _i("grid_energy_export", 3073, "u32", "Wh", 100.0, "counter exported"),
    _i("battery_energy_discharged", 3127, "u32", "Wh", 100.0, "bat exported"),
    _i("battery_energy_charged", 3131, "u32", "Wh", 100.0, "bat imported"),
    _i("battery_soc", 3171, "u16", "%", 1.0, "bat soc"),
    _i("battery_discharge_power", 3178, "u32", "W", 0.1, "bat power_out"),
    _i("battery_charge_power", 3180, "u32", "W", 0.1, "bat power_in"),
)

# custom_components/growatt_local/API/device_type/inverter_120.py (INPUT_REGISTERS_120_TL_XH,
# HOLDING_REGISTERS_120) and storage_120.py (STORAGE_INPUT_REGISTERS_120_TL_XH): a 2-register
# value is decoded as a signed 32-bit integer, one register as unsigned; value = raw / scale
# (10 unless given)
LOCAL_TLXH = (
    _h("active_power_rate", 3, "u16", "%", 1.0, "output power limit"),
    _h("modbus_version", 88, "u16", "", 0.01, "modbus version"),
    _i("input_power", 3001, "s32", "W", 0.1, "input power"),
    _i("pv1_voltage", 3003, "u16", "V", 0.1, "input 1 voltage"),
    _i("pv1_current", 3004, "u16", "A", 0.1, "input 1 amperage"),
    _i("pv1_power", 3005, "s32", "W", 0.1, "input 1 power"),
    _i("pv2_voltage", 3007, "u16", "V", 0.1, "input 2 voltage"),
    _i("pv2_current", 3008, "u16", "A", 0.1, "input 2 amperage"),
    _i("pv2_power", 3009, "s32", "W", 0.1, "input 2 power"),
    _i("pv3_voltage", 3011, "u16", "V", 0.1, "input 3 voltage"),
    _i("pv3_current", 3012, "u16", "A", 0.1, "input 3 amperage"),
    _i("pv3_power", 3013, "s32", "W", 0.1, "input 3 power"),
    _i("pv4_voltage", 3015, "u16", "V", 0.1, "input 4 voltage"),
    _i("pv4_current", 3016, "u16", "A", 0.1, "input 4 amperage"),
    _i("pv4_power", 3017, "s32", "W", 0.1, "input 4 power"),
    _i("power", 3023, "s32", "W", 0.1, "output power"),
    _i("frequency", 3025, "u16", "Hz", 0.01, "grid frequency"),
    _i("voltage_l1", 3026, "u16", "V", 0.1, "output 1 voltage"),
    _i("current_l1", 3027, "u16", "A", 0.1, "output 1 amperage"),
    _i("power_l1", 3028, "s32", "W", 0.1, "output 1 power"),
    _i("voltage_l2", 3030, "u16", "V", 0.1, "output 2 voltage"),
    _i("current_l2", 3031, "u16", "A", 0.1, "output 2 amperage"),
    _i("power_l2", 3032, "s32", "W", 0.1, "output 2 power"),
    _i("voltage_l3", 3034, "u16", "V", 0.1, "output 3 voltage"),
    _i("current_l3", 3035, "u16", "A", 0.1, "output 3 amperage"),
    _i("power_l3", 3036, "s32", "W", 0.1, "output 3 power"),
    _i("grid_import_power", 30041, "s32", "W", 0.1, "power to user"),
    _i("grid_export_power", 30043, "s32", "W", 0.1, "power to grid"),
    _i("load_power", 30045, "s32", "W", 0.1, "power user load"),
    _i("energy_today", 3049, "s32", "kWh", 0.1, "output energy today"),
    _i("energy_total", 3051, "s32", "kWh", 0.1, "output energy total"),
    _i("pv_energy_total", 3053, "s32", "kWh", 0.1, "input energy total"),
    _i("pv1_energy_today", 3055, "s32", "kWh", 0.1, "input 1 energy today"),
    _i("pv1_energy_total", 3057, "s32", "kWh", 0.1, "input 1 energy total"),
    _i("pv2_energy_today", 3059, "s32", "kWh", 0.1, "input 2 energy today"),
    _i("pv2_energy_total", 3061, "s32", "kWh", 0.1, "input 2 energy total"),
    _i("pv3_energy_today", 3063, "s32", "kWh", 0.1, "input 3 energy today"),
    _i("pv3_energy_total", 3065, "s32", "kWh", 0.1, "input 3 energy total"),
    _i("grid_import_today", 3067, "s32", "kWh", 0.1, "energy to user today"),
    _i("grid_energy_import", 3069, "s32", "kWh", 0.1, "energy to user total"),
    _i("grid_export_today", 3071, "s32", "kWh", 0.1, "energy to grid today"),
    _i("grid_energy_export", 3073, "s32", "kWh", 0.1, "energy to grid total"),
    _i("pv4_energy_today", 71, "s32", "kWh", 0.1, "input 4 energy today"),
    _i("pv4_energy_total", 73, "s32", "kWh", 0.1, "input 4 energy total"),
    _i("temperature", 3093, "u16", "°C", 0.1, "temperature"),
    _i("ipm_temperature", 3094, "u16", "°C", 0.1, "ipm temperature"),
    _i("boost_temperature", 3095, "u16", "°C", 0.1, "boost temperature"),
    _i("p_bus_voltage", 3098, "u16", "V", 0.1, "p bus voltage"),
    _i("n_bus_voltage", 3099, "u16", "V", 0.1, "n bus voltage"),
    _i("fault_code", 3105, "u16", "", 1.0, "fault code"),
    _i("warning_bits", 3110, "u16", "", 1.0, "warning code"),
    _i("battery_discharge_today", 3125, "s32", "kWh", 0.1, "discharge energy today"),
    _i("battery_energy_discharged", 3127, "s32", "kWh", 0.1, "discharge energy total"),
    _i("battery_charge_today", 3129, "s32", "kWh", 0.1, "charge energy today"),
    _i("battery_energy_charged", 3131, "s32", "kWh", 0.1, "charge energy total"),
    _i("battery_soc", 3171, "u16", "%", 1.0, "soc"),
    _i("battery_discharge_power", 3178, "s32", "W", 0.1, "discharge power"),
    _i("battery_charge_power", 3180, "s32", "W", 0.1, "charge power"),
)

# templates/definition/meter/growatt-hybrid.yaml (SPH/SPA/MIX storage layout; register
# scale, evcc's own signs in the notes)
EVCC_SPH = (
    _i("input_power", 1, "u32", "W", 0.1, "Ppv Input power"),
    _i("pv_energy_total", 91, "u32", "kWh", 0.1, "PV Energy total"),
    _i("battery_discharge_power", 1009, "u32", "W", 0.1, "Pdischarge1"),
    _i("battery_charge_power", 1011, "u32", "W", 0.1, "Pcharge1"),
    _i("battery_soc", 1014, "u16", "%", 1.0, "SOC"),
    _i("grid_import_power", 1021, "u32", "W", 0.1, "PactouserTotal"),
    _i("grid_export_power", 1029, "u32", "W", 0.1, "Pactogrid total"),
    _i("grid_energy_import", 1046, "u32", "kWh", 0.1, "Etouser_total"),
    _i("battery_energy_discharged", 1054, "u32", "kWh", 0.1, "Edischarge1_total"),
)

# packages/modules/devices/growatt/growatt/{inverter,counter,bat}.py, version "MAX" (the
# storage layout: input 0-124 and 1000-1124; register scale, energies in Wh: raw x 100)
OPENWB_SPH = (
    _i("input_power", 1, "u32", "W", 0.1, "inverter power"),
    _i("power_l1", 40, "s32", "W", 0.1, "powers[0]"),
    _i("power_l2", 44, "s32", "W", 0.1, "powers[1]"),
    _i("power_l3", 48, "s32", "W", 0.1, "powers[2]"),
    _i("pv_energy_total", 91, "u32", "Wh", 100.0, "inverter exported"),
    _i("battery_discharge_power", 1009, "u32", "W", 0.1, "bat power_out"),
    _i("battery_charge_power", 1011, "u32", "W", 0.1, "bat power_in"),
    _i("battery_soc", 1014, "u16", "%", 1.0, "bat soc"),
    _i("grid_import_power", 1021, "u32", "W", 0.1, "power_in"),
    _i("grid_export_power", 1029, "u32", "W", 0.1, "power_out"),
    _i("grid_energy_import", 1046, "u32", "Wh", 100.0, "counter imported"),
    _i("grid_energy_export", 1050, "u32", "Wh", 100.0, "counter exported"),
    _i("battery_energy_discharged", 1054, "u32", "Wh", 100.0, "bat exported"),
    _i("battery_energy_charged", 1058, "u32", "Wh", 100.0, "bat imported"),
)

# custom_components/growatt_local/API/device_type/inverter_120.py (INPUT_REGISTERS_120) and
# storage_120.py (STORAGE_INPUT_REGISTERS_120, STORAGE_HOLDING_REGISTERS_120), device type
# hybrid_120; 2-register values signed 32-bit, single registers unsigned
LOCAL_SPH = (
    _h("modbus_version", 88, "u16", "", 0.01, "modbus version"),
    _i("input_power", 1, "s32", "W", 0.1, "input power"),
    _i("pv1_voltage", 3, "u16", "V", 0.1, "input 1 voltage"),
    _i("pv1_current", 4, "u16", "A", 0.1, "input 1 amperage"),
    _i("pv1_power", 5, "s32", "W", 0.1, "input 1 power"),
    _i("pv2_voltage", 7, "u16", "V", 0.1, "input 2 voltage"),
    _i("pv2_current", 8, "u16", "A", 0.1, "input 2 amperage"),
    _i("pv2_power", 9, "s32", "W", 0.1, "input 2 power"),
    _i("power", 35, "s32", "W", 0.1, "output power"),
    _i("frequency", 37, "u16", "Hz", 0.01, "grid frequency"),
    _i("voltage_l1", 38, "u16", "V", 0.1, "output 1 voltage"),
    _i("current_l1", 39, "u16", "A", 0.1, "output 1 amperage"),
    _i("power_l1", 40, "s32", "W", 0.1, "output 1 power"),
    _i("voltage_l2", 42, "u16", "V", 0.1, "output 2 voltage"),
    _i("current_l2", 43, "u16", "A", 0.1, "output 2 amperage"),
    _i("power_l2", 44, "s32", "W", 0.1, "output 2 power"),
    _i("voltage_l3", 46, "u16", "V", 0.1, "output 3 voltage"),
    _i("current_l3", 47, "u16", "A", 0.1, "output 3 amperage"),
    _i("power_l3", 48, "s32", "W", 0.1, "output 3 power"),
    _i("energy_today", 53, "s32", "kWh", 0.1, "output energy today"),
    _i("energy_total", 55, "s32", "kWh", 0.1, "output energy total"),
    _i("pv1_energy_today", 59, "s32", "kWh", 0.1, "input 1 energy today"),
    _i("pv1_energy_total", 61, "s32", "kWh", 0.1, "input 1 energy total"),
    _i("pv2_energy_today", 63, "s32", "kWh", 0.1, "input 2 energy today"),
    _i("pv2_energy_total", 65, "s32", "kWh", 0.1, "input 2 energy total"),
    _i("pv_energy_total", 91, "s32", "kWh", 0.1, "input energy total"),
    _i("temperature", 93, "u16", "°C", 0.1, "temperature"),
    _i("ipm_temperature", 94, "u16", "°C", 0.1, "ipm temperature"),
    _i("boost_temperature", 95, "u16", "°C", 0.1, "boost temperature"),
    _i("p_bus_voltage", 98, "u16", "V", 0.1, "p bus voltage"),
    _i("n_bus_voltage", 99, "u16", "V", 0.1, "n bus voltage"),
    _i("fault_code", 105, "u16", "", 1.0, "fault code"),
    _i("battery_discharge_power", 1009, "s32", "W", 0.1, "discharge power"),
    _i("battery_charge_power", 1011, "s32", "W", 0.1, "charge power"),
    _i("battery_soc", 1014, "u16", "%", 1.0, "soc"),
    _i("grid_import_power", 1021, "s32", "W", 0.1, "pac to user total"),
    _i("grid_export_power", 1029, "s32", "W", 0.1, "pac to grid total"),
    _i("grid_import_today", 1044, "s32", "kWh", 0.1, "energy to user today"),
    _i("grid_energy_import", 1046, "s32", "kWh", 0.1, "energy to user total"),
    _i("grid_export_today", 1048, "s32", "kWh", 0.1, "energy to grid today"),
    _i("grid_energy_export", 1050, "s32", "kWh", 0.1, "energy to grid total"),
    _i("battery_discharge_today", 1052, "s32", "kWh", 0.1, "discharge energy today"),
    _i("battery_energy_discharged", 1054, "s32", "kWh", 0.1, "discharge energy total"),
    _i("battery_charge_today", 1056, "s32", "kWh", 0.1, "charge energy today"),
    _i("battery_energy_charged", 1058, "s32", "kWh", 0.1, "charge energy total"),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "growatt_min_mod": (
        SourceDefinition(
            device="growatt_min_mod",
            source="evcc",
            ref=f"{EVCC}:templates/definition/meter/growatt-hybrid-tlxh.yaml",
            points=EVCC_TLXH,
            notes=(
                "grid power = 3041 - 3043, PV power = the sum of 3005/3009/3013/3017, "
                "battery power = 3178 - 3180 (discharge positive)",
                "battery mode writes holding 3038-3039 as one FC16 (time slot 1, bit 15 = "
                "enabled; the firmware refuses 3039 alone) and 3049 (AC charge 0/1)",
                "growatt-min-tlxe.yaml (MIN TL-XE without battery) reads input 35 (power, "
                "int32 x 0.1) and 55 (energy, uint32 x 0.1): the 0-124 layout of the older "
                "protocol, not the V1.24 TL-X block this mapping reads",
            ),
        ),
        SourceDefinition(
            device="growatt_min_mod",
            source="openwb",
            ref=f"{OPENWB}:packages/modules/devices/growatt/growatt",
            points=OPENWB_TLX,
            notes=(
                "one read per value (function 4), Modbus TCP through a gateway",
                "PV power x -0.1 (openWB counts generation negative), grid power = 3041 "
                "- 3043, battery power = 3180 - 3178 (charge positive)",
                "reads the phase powers 3028/3032/3036 as signed 32-bit values, as the "
                "grid meter's phase powers",
                "energies raw x 100 Wh (0.1 kWh)",
            ),
        ),
        SourceDefinition(
            device="growatt_min_mod",
            source="community:WouterTuinstra/Homeassistant-Growatt-Local-Modbus",
            ref=f"{GROWATT_LOCAL}:custom_components/growatt_local/API/device_type",
            points=LOCAL_TLXH,
            notes=(
                "hybrid_120_TL_XH device type: every 2-register value decoded as signed "
                "32-bit, every single register unsigned (temperatures too)",
                "reads the grid import/export and load power at 30041/30043/30045 (a digit "
                "too many: the V1.24 rows and evcc/openWB have 3041/3043/3045)",
                "reads the PV4 energy today/total at input 71/73 (the older 0-124 layout) "
                "inside the TL-X list; V1.24 has them at 3079/3081",
                "status: the low nibble of input 3000 (0 waiting, 1 normal, 2 discharge, 3 "
                "fault, 5-12 the hybrid charge states); 3086 derating mode; 3110 read as "
                "the warning code",
                "reads at most 100 registers a request on this protocol generation",
            ),
        ),
    ),
    "growatt_sph": (
        SourceDefinition(
            device="growatt_sph",
            source="evcc",
            ref=f"{EVCC}:templates/definition/meter/growatt-hybrid.yaml",
            points=EVCC_SPH,
            notes=(
                "grid power = 1021 - 1029, battery power = 1009 - 1011 (discharge positive)",
                "battery mode: holding 1102 (battery-first slot 1 enable) and 1092 (AC "
                "charge) written with FC16; 1100-1102 must first be set to 0, 5947, 0 in "
                "one write by hand (slot 00:00-23:59)",
            ),
        ),
        SourceDefinition(
            device="growatt_sph",
            source="openwb",
            ref=f"{OPENWB}:packages/modules/devices/growatt/growatt",
            points=OPENWB_SPH,
            notes=(
                "openWB calls this layout its 'MAX' version; the registers it reads there "
                "are the storage (SPH/MIX) rows of input 0-124 and 1000-1124",
                "PV power x -0.1, grid power = 1021 - 1029, battery power = 1011 - 1009 "
                "(charge positive), energies raw x 100 Wh",
                "reads the phase powers 40/44/48 as signed 32-bit values",
            ),
        ),
        SourceDefinition(
            device="growatt_sph",
            source="community:WouterTuinstra/Homeassistant-Growatt-Local-Modbus",
            ref=f"{GROWATT_LOCAL}:custom_components/growatt_local/API/device_type",
            points=LOCAL_SPH,
            notes=(
                "hybrid_120 device type: every 2-register value decoded as signed 32-bit, "
                "every single register unsigned (temperatures too)",
                "status: the low nibble of input 0; 104 derating mode, 110 warning code",
                "storage holding list reads the serial number at 3001 (15 registers) and "
                "the AC charge switch at 3049 (the TL-XH rows), not SPH's 1092",
            ),
        ),
    ),
}
