"""Sungrow SH-RT hybrid and SG-RT string inverters as independent sources read them (facts
only).

Addresses here are wire addresses: mkaiser's Home Assistant package, evcc and openWB give
them as sent; SunGather prints the document's 1-based numbers and subtracts 1 when it
reads, so its rows are transcribed one lower. Every source reads 32-bit values low word
first. A source that negates a value for its own sign convention (evcc's grid power,
openWB's battery and inverter values) is transcribed with the register's own sign and the
negation named in its notes (scales here are positive).
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC, OPENEMS_CONVENTION, OPENWB

MKAISER = (
    "mkaiser/Sungrow-SHx-Inverter-Modbus-Home-Assistant@63beec6770e8275670cdf01437cb305817f32988"
)
SUNGATHER = "bohdan-s/SunGather@2c2935d7e30002cc16c5f285c6f55c9642984e99"
SUNGATHER_READS = (
    "SunGather's rows carry the document's 1-based numbers and its client (bohdan-s/"
    "SungrowClient) reads each at number - 1; U32/S32 add the second register x 65536 (low "
    "word first); 0xFFFF (and 0x7FFF for S16, 0xFFFF/0x7FFF for S32) read as 0"
)
OPENWB_SUNGROW = "packages/modules/devices/sungrow"


def _in(
    key: str, address: int, kind: str, unit: str, scale: float = 1.0, name: str = ""
) -> SourcePoint:
    order = "little" if kind in ("u32", "s32") else "big"
    return SourcePoint(key, "input", address, kind, unit, scale, order, name)


def _hold(
    key: str, address: int, kind: str, unit: str, scale: float = 1.0, name: str = ""
) -> SourcePoint:
    order = "little" if kind in ("u32", "s32") else "big"
    return SourcePoint(key, "holding", address, kind, unit, scale, order, name)


# modbus_sungrow.yaml: Home Assistant modbus sensors, wire addresses ("# reg N+1" beside)
MKAISER_SH = (
    _in("nominal_power", 5000, "u16", "W", 100, "Inverter rated output"),
    _in("daily_output_energy", 5002, "u16", "kWh", 0.1, "Daily PV generation & battery discharge"),
    _in("total_output_energy", 5003, "u32", "kWh", 0.1, "Total PV generation & battery discharge"),
    _in("inverter_temperature", 5007, "s16", "°C", 0.1, "Inverter temperature"),
    _in("mppt1_voltage", 5010, "u16", "V", 0.1, "MPPT1 voltage"),
    _in("mppt1_current", 5011, "u16", "A", 0.1, "MPPT1 current"),
    _in("mppt2_voltage", 5012, "u16", "V", 0.1, "MPPT2 voltage"),
    _in("mppt2_current", 5013, "u16", "A", 0.1, "MPPT2 current"),
    _in("dc_power", 5016, "u32", "W", 1, "Total DC power"),
    _in("voltage_l1", 5018, "u16", "V", 0.1, "Phase A voltage"),
    _in("voltage_l2", 5019, "u16", "V", 0.1, "Phase B voltage"),
    _in("voltage_l3", 5020, "u16", "V", 0.1, "Phase C voltage"),
    _in("reactive_power", 5032, "s32", "W", 1, "Reactive power"),
    _in("power_factor", 5034, "s16", "%", 0.001, "Power factor"),
    _in("battery_power", 5213, "s32", "W", 1, "Battery power"),
    _in("grid_frequency", 5241, "u16", "Hz", 0.01, "Grid frequency"),
    _in("meter_power", 5600, "s32", "W", 1, "Meter active power"),
    _in("meter_power_l1", 5602, "s32", "W", 1, "Meter phase A active power"),
    _in("meter_power_l2", 5604, "s32", "W", 1, "Meter phase B active power"),
    _in("meter_power_l3", 5606, "s32", "W", 1, "Meter phase C active power"),
    _in("export_power_limit_min", 5621, "u16", "W", 10, "Export power limit min"),
    _in("export_power_limit_max", 5622, "u16", "W", 10, "Export power limit max"),
    _in("bdc_rated_power", 5627, "u16", "W", 100, "BDC rated power"),
    _in("battery_current", 5630, "s16", "A", 0.1, "Battery current"),
    _in("bms_max_charge_current", 5634, "u16", "A", 1, "BMS max. charging current"),
    _in("bms_max_discharge_current", 5635, "u16", "A", 1, "BMS max. discharging current"),
    _in("battery_capacity", 5638, "u16", "kWh", 0.01, "Battery capacity high precision"),
    _in("daily_pv_energy", 13001, "u16", "kWh", 0.1, "Daily PV generation"),
    _in("total_pv_energy", 13002, "u32", "kWh", 0.1, "Total PV generation"),
    _in("daily_pv_export", 13004, "u16", "kWh", 0.1, "Daily exported energy from PV"),
    _in("total_pv_export", 13005, "u32", "kWh", 0.1, "Total exported energy from PV"),
    _in("load_power", 13007, "s32", "W", 1, "Load power"),
    _in("export_power", 13009, "s32", "W", 1, "Export power raw"),
    _in("daily_battery_charge_pv", 13011, "u16", "kWh", 0.1, "Daily battery charge from PV"),
    _in("total_battery_charge_pv", 13012, "u32", "kWh", 0.1, "Total battery charge from PV"),
    _in("daily_direct_consumption", 13016, "u16", "kWh", 0.1, "Daily direct energy consumption"),
    _in("total_direct_consumption", 13017, "u32", "kWh", 0.1, "Total direct energy consumption"),
    _in("battery_voltage", 13019, "u16", "V", 0.1, "Battery voltage"),
    _in("battery_soc", 13022, "u16", "%", 0.1, "Battery level"),
    _in("battery_soh", 13023, "u16", "%", 0.1, "Battery state of health"),
    _in("battery_temperature", 13024, "s16", "°C", 0.1, "Battery temperature"),
    _in("daily_battery_discharge", 13025, "u16", "kWh", 0.1, "Daily battery discharge"),
    _in("total_battery_discharge", 13026, "u32", "kWh", 0.1, "Total battery discharge"),
    _in("current_l1", 13030, "s16", "A", 0.1, "Phase A current"),
    _in("current_l2", 13031, "s16", "A", 0.1, "Phase B current"),
    _in("current_l3", 13032, "s16", "A", 0.1, "Phase C current"),
    _in("active_power", 13033, "s32", "W", 1, "Total active power"),
    _in("daily_import", 13035, "u16", "kWh", 0.1, "Daily imported energy"),
    _in("total_import", 13036, "u32", "kWh", 0.1, "Total imported energy"),
    _in("daily_battery_charge", 13039, "u16", "kWh", 0.1, "Daily battery charge"),
    _in("total_battery_charge", 13040, "u32", "kWh", 0.1, "Total battery charge"),
    _in("daily_export", 13044, "u16", "kWh", 0.1, "Daily exported energy"),
    _in("total_export", 13045, "u32", "kWh", 0.1, "Total exported energy"),
    _hold("charge_discharge_power", 13051, "u16", "W", 1, "Battery forced charge discharge power"),
    _hold("max_soc", 13057, "u16", "%", 0.1, "Battery max SoC"),
    _hold("min_soc", 13058, "u16", "%", 0.1, "Battery min SoC"),
    _hold("export_power_limit", 13073, "u16", "W", 1, "Export power limit"),
    _hold("backup_reserved_soc", 13099, "u16", "%", 1, "Battery reserved SoC for backup"),
    _hold("battery_max_charge_power", 33046, "u16", "W", 10, "Battery max charge power"),
    _hold("battery_max_discharge_power", 33047, "u16", "W", 10, "Battery max discharge power"),
)

# SunGather/registers-sungrow.yaml: the rows valid for the SH-RT models (no models list, or
# one naming SH10RT), document number - 1
SUNGATHER_SH = (
    _in("nominal_power", 5000, "u16", "kW", 0.1, "nominal_active_power"),
    _in("daily_output_energy", 5002, "u16", "kWh", 0.1, "daily_power_yields"),
    _in("total_output_energy", 5003, "u32", "kWh", 1, "total_power_yields"),
    _in("inverter_temperature", 5007, "s16", "°C", 0.1, "internal_temperature"),
    _in("mppt1_voltage", 5010, "u16", "V", 0.1, "mppt_1_voltage"),
    _in("mppt1_current", 5011, "u16", "A", 0.1, "mppt_1_current"),
    _in("mppt2_voltage", 5012, "u16", "V", 0.1, "mppt_2_voltage"),
    _in("mppt2_current", 5013, "u16", "A", 0.1, "mppt_2_current"),
    _in("dc_power", 5016, "u32", "W", 1, "total_dc_power"),
    _in("voltage_l1", 5018, "u16", "V", 0.1, "phase_a_voltage"),
    _in("voltage_l2", 5019, "u16", "V", 0.1, "phase_b_voltage"),
    _in("voltage_l3", 5020, "u16", "V", 0.1, "phase_c_voltage"),
    _in("reactive_power", 5032, "s32", "var", 1, "total_reactive_power"),
    _in("power_factor", 5034, "s16", "", 0.001, "power_factor"),
    _in("grid_frequency_coarse", 5035, "u16", "Hz", 0.1, "grid_frequency"),
    _in("meter_power", 5600, "s32", "W", 1, "meter_total_power"),
    _in("meter_power_l1", 5602, "s32", "W", 1, "meter_phase_a_power"),
    _in("meter_power_l2", 5604, "s32", "W", 1, "meter_phase_b_power"),
    _in("meter_power_l3", 5606, "s32", "W", 1, "meter_phase_c_power"),
    _in("export_power_limit_min", 5621, "u16", "W", 10, "export_limit_min"),
    _in("export_power_limit_max", 5622, "u16", "W", 10, "export_limit_max"),
    _in("bdc_rated_power", 5627, "u16", "W", 100, "bdc_rated_power"),
    _in("bms_max_charge_current", 5634, "u16", "A", 1, "bms_max_charging_current"),
    _in("bms_max_discharge_current", 5635, "u16", "A", 1, "bms_max_discharging_current"),
    _in("daily_pv_energy", 13001, "u16", "kWh", 0.1, "daily_pv_generation"),
    _in("total_pv_energy", 13002, "u32", "kWh", 0.1, "total_pv_generation"),
    _in("daily_pv_export", 13004, "u16", "kWh", 0.1, "daily_pv_export"),
    _in("total_pv_export", 13005, "u32", "kWh", 0.1, "total_pv_export"),
    _in("load_power", 13007, "s32", "W", 1, "load_power_hybrid"),
    _in("export_power", 13009, "s32", "W", 1, "export_power_hybrid"),
    _in("daily_battery_charge_pv", 13011, "u16", "kWh", 0.1, "daily_battery_charge_from_pv"),
    _in("total_battery_charge_pv", 13012, "u32", "kWh", 0.1, "total_battery_charge_from_pv"),
    _in("daily_direct_consumption", 13016, "u16", "kWh", 0.1, "daily_direct_energy_consumption"),
    _in("total_direct_consumption", 13017, "u32", "kWh", 0.1, "total_direct_energy_consumption"),
    _in("battery_voltage", 13019, "u16", "V", 0.1, "battery_voltage"),
    _in("battery_soc", 13022, "u16", "%", 0.1, "battery_level"),
    _in("battery_soh", 13023, "u16", "%", 0.1, "battery_state_of_healthy"),
    _in("battery_temperature", 13024, "s16", "°C", 0.1, "battery_temperature"),
    _in("daily_battery_discharge", 13025, "u16", "kWh", 0.1, "daily_battery_discharge_energy"),
    _in("total_battery_discharge", 13026, "u32", "kWh", 0.1, "total_battery_discharge_energy"),
    _in("current_l1", 13030, "s16", "A", 0.1, "phase_a_current"),
    _in("current_l2", 13031, "s16", "A", 0.1, "phase_b_current"),
    _in("current_l3", 13032, "s16", "A", 0.1, "phase_c_current"),
    _in("active_power", 13033, "s32", "W", 1, "total_active_power"),
    _in("daily_import", 13035, "u16", "kWh", 0.1, "daily_import_energy"),
    _in("total_import", 13036, "u32", "kWh", 0.1, "total_import_energy"),
    _in("daily_battery_charge", 13039, "u16", "kWh", 0.1, "daily_charge_energy"),
    _in("total_battery_charge", 13040, "u32", "kWh", 0.1, "total_charge_energy"),
    _in("daily_export", 13044, "u16", "kWh", 0.1, "daily_export_energy"),
    _in("total_export", 13045, "u32", "kWh", 0.1, "total_export_energy"),
    _hold("charge_discharge_power", 13051, "u16", "W", 1, "charge_discharge_power"),
    _hold("backup_reserved_soc", 13099, "u16", "%", 1, "soc_reserve"),
    _hold("battery_max_charge_power", 33046, "u16", "W", 10, "battery_max_charge_power"),
    _hold("battery_max_discharge_power", 33047, "u16", "W", 10, "battery_max_discharge_power"),
)

# templates/definition/meter/sungrow-hybrid.yaml (grid, pv and battery usages)
EVCC_SH = (
    _in("nominal_power", 5000, "u16", "W", 100, "maxacpower"),
    _in("dc_power", 5016, "u32", "W", 1, "pv power"),
    _in("voltage_l1", 5018, "u16", "V", 0.1, "Phase A voltage"),
    _in("voltage_l2", 5019, "u16", "V", 0.1, "Phase B voltage"),
    _in("voltage_l3", 5020, "u16", "V", 0.1, "Phase C voltage"),
    _in("meter_power_l1", 5602, "s32", "W", 1, "Meter Phase A Active Power"),
    _in("meter_power_l2", 5604, "s32", "W", 1, "Meter Phase B Active Power"),
    _in("meter_power_l3", 5606, "s32", "W", 1, "Meter Phase C Active Power"),
    _in("battery_capacity", 5638, "u16", "kWh", 0.01, "capacity"),
    _in("total_pv_energy", 13002, "u32", "kWh", 0.1, "Total PV Generation"),
    _in("export_power", 13009, "s32", "W", 1, "Export power"),
    _in("battery_soc", 13022, "s16", "%", 0.1, "Battery level"),
    _in("total_battery_discharge", 13026, "u32", "kWh", 0.1, "Total battery discharge energy"),
    _in("total_import", 13036, "u32", "kWh", 0.1, "Total Import Energy"),
    _hold("charge_discharge_power", 13051, "u16", "W", 1, "maxchargepower"),
    _hold("battery_max_discharge_power", 33047, "u16", "W", 10, "maxdischargepower"),
)

# sungrow_sh/{inverter,counter,bat}.py (the WiNet-S path of counter.py for the voltages)
OPENWB_SH = (
    _in("dc_power", 5016, "u32", "W", 1, "dc_power"),
    _in("voltage_l1", 5018, "u16", "V", 0.1, "voltages[0]"),
    _in("voltage_l2", 5019, "u16", "V", 0.1, "voltages[1]"),
    _in("voltage_l3", 5020, "u16", "V", 0.1, "voltages[2]"),
    _in("power_factor", 5034, "s16", "", 0.001, "power_factor"),
    _in("grid_frequency_coarse", 5035, "u16", "Hz", 0.1, "frequency"),
    _in("battery_power", 5213, "s32", "W", 1, "bat_power (new_registers)"),
    _in("meter_power_l1", 5602, "s32", "W", 1, "powers[0]"),
    _in("meter_power_l2", 5604, "s32", "W", 1, "powers[1]"),
    _in("meter_power_l3", 5606, "s32", "W", 1, "powers[2]"),
    _in("battery_current", 5630, "s16", "A", 0.1, "bat_current (new_registers)"),
    _in("export_power", 13009, "s32", "W", 1, "counter power"),
    _in("battery_soc", 13022, "u16", "%", 0.1, "soc"),
    _in("current_l1", 13030, "s16", "A", 0.1, "currents[0]"),
    _in("current_l2", 13031, "s16", "A", 0.1, "currents[1]"),
    _in("current_l3", 13032, "s16", "A", 0.1, "currents[2]"),
    _in("active_power", 13033, "s32", "W", 1, "inverter power"),
)

# io.openems.edge.sungrow ess/EssSungrowImpl.java; its mV, mA, Wh and mHz channels (x100 or
# x10 of the registers) transcribed in V, A, kWh and Hz
OPENEMS_SH = (
    _in("nominal_power", 5000, "u16", "VA", 100, "MAX_APPARENT_POWER"),
    _in("daily_output_energy", 5002, "u16", "kWh", 0.1, "DAILY_OUTPUT_ENERGY"),
    _in("inverter_temperature", 5007, "s16", "°C", 0.1, "INSIDE_TEMPERATURE"),
    _in("mppt1_voltage", 5010, "u16", "V", 0.1, "MPPT1_VOLTAGE"),
    _in("mppt1_current", 5011, "u16", "A", 0.1, "MPPT1_CURRENT"),
    _in("mppt2_voltage", 5012, "u16", "V", 0.1, "MPPT2_VOLTAGE"),
    _in("mppt2_current", 5013, "u16", "A", 0.1, "MPPT2_CURRENT"),
    _in("dc_power", 5016, "u32", "W", 1, "TOTAL_DC_POWER"),
    _in("voltage_l1", 5018, "u16", "V", 0.1, "VOLTAGE_L1"),
    _in("voltage_l2", 5019, "u16", "V", 0.1, "VOLTAGE_L2"),
    _in("voltage_l3", 5020, "u16", "V", 0.1, "VOLTAGE_L3"),
    _in("reactive_power", 5032, "s32", "var", 1, "REACTIVE_POWER"),
    _in("power_factor", 5034, "s16", "", 0.001, "POWER_FACTOR"),
    _in("grid_frequency_coarse", 5035, "u16", "Hz", 0.01, "GRID_FREQUENCY"),
    _in("export_power_limit_min", 5621, "u16", "W", 10, "EXPORT_LIMIT_MIN"),
    _in("export_power_limit_max", 5622, "u16", "W", 10, "EXPORT_LIMIT_MAX"),
    _in("bdc_rated_power", 5627, "u16", "W", 100, "BDC_RATED_POWER"),
    _in("bms_max_charge_current", 5634, "u16", "A", 1, "CHARGE_MAX_CURRENT"),
    _in("bms_max_discharge_current", 5635, "u16", "A", 1, "DISCHARGE_MAX_CURRENT"),
    _in("daily_pv_energy", 13001, "u16", "kWh", 0.1, "DAILY_PV_GENERATION"),
    _in("total_pv_energy", 13002, "u32", "kWh", 0.1, "TOTAL_PV_GENERATION"),
    _in("total_pv_export", 13005, "u32", "kWh", 0.1, "TOTAL_EXPORT_ENERGY_FROM_PV"),
    _in("load_power", 13007, "s32", "W", 1, "LOAD_POWER"),
    _in("export_power", 13009, "s32", "W", 1, "EXPORT_POWER"),
    _in("daily_battery_charge_pv", 13011, "u16", "kWh", 0.1, "DAILY_BATTERY_CHARGE_ENERGY_FROM_PV"),
    _in("total_battery_charge_pv", 13012, "u32", "kWh", 0.1, "TOTAL_BATTERY_CHARGE_ENERGY_FROM_PV"),
    _in("daily_direct_consumption", 13016, "u16", "kWh", 0.1, "DAILY_DIRECT_ENERGY_CONSUMPTION"),
    _in("total_direct_consumption", 13017, "u32", "kWh", 0.1, "TOTAL_DIRECT_ENERGY_CONSUMPTION"),
    _in("battery_voltage", 13019, "u16", "V", 0.1, "BATTERY_VOLTAGE"),
    _in("battery_soc", 13022, "u16", "%", 0.1, "SOC"),
    _in("battery_soh", 13023, "u16", "%", 0.1, "SOH"),
    _in("battery_temperature", 13024, "s16", "°C", 0.1, "BATTERY_TEMPERATURE"),
    _in("daily_battery_discharge", 13025, "u16", "kWh", 0.1, "DAILY_BATTERY_DISCHARGE_ENERGY"),
    _in("current_l1", 13030, "s16", "A", 0.1, "CURRENT_L1"),
    _in("current_l2", 13031, "s16", "A", 0.1, "CURRENT_L2"),
    _in("current_l3", 13032, "s16", "A", 0.1, "CURRENT_L3"),
    _in("active_power", 13033, "s32", "W", 1, "ACTIVE_POWER"),
    _in("daily_import", 13035, "u16", "kWh", 0.1, "DAILY_IMPORT_ENERGY"),
    _in("total_import", 13036, "u32", "kWh", 0.1, "TOTAL_IMPORT_ENERGY"),
    _in("daily_battery_charge", 13039, "u16", "kWh", 0.1, "DAILY_CHARGE_ENERGY"),
    _in("daily_export", 13044, "u16", "kWh", 0.1, "DAILY_EXPORT_ENERGY"),
    _in("total_export", 13045, "u32", "kWh", 0.1, "TOTAL_EXPORT_ENERGY"),
    _hold("charge_discharge_power", 13051, "u16", "W", 1, "CHARGE_DISCHARGE_POWER"),
    _hold("max_soc", 13057, "u16", "%", 0.1, "MAX_SOC"),
    _hold("min_soc", 13058, "u16", "%", 0.1, "MIN_SOC"),
    _hold("backup_reserved_soc", 13099, "u16", "%", 1, "RESERVED_SOC_FOR_BACKUP"),
)

SH_RT = (
    SourceDefinition(
        device="sungrow_sh_rt",
        source="community:mkaiser/Sungrow-SHx-Inverter-Modbus-Home-Assistant",
        ref=f"{MKAISER}:modbus_sungrow.yaml",
        points=MKAISER_SH,
        notes=(
            "wire addresses, each with the document's number beside it as a comment",
            "cites TI_20251119 Communication Protocol of Residential Hybrid Inverter V1.1.11",
            "battery power (5213) is negative when charging: its templates negate it for a "
            "charging-positive sensor; battery current moved from 13020 to 5630 in 2025-12",
            "export power (13009) is + exporting, - importing, nan_value 0x7FFFFFFF",
            "labels reactive power W and the 0.001-scaled power factor %",
            "running state raw (input 12999) with a state map; power flow bits at input "
            "13000; device type codes 0x0E00.. (SH-RT), 0x0D0D.. (SH-RS)",
            "EMS mode 13049 (0 self-consumption, 2 forced, 3 external EMS, 4 VPP, 8 "
            "microgrid), charge command 13050 (0xAA charge, 0xBB discharge, 0xCC stop), "
            "start 0xCF / stop 0xCE to holding 12999, switches 13074 and 13086 (0xAA/0x55)",
        ),
    ),
    SourceDefinition(
        device="sungrow_sh_rt",
        source="community:bohdan-s/SunGather",
        ref=f"{SUNGATHER}:SunGather/registers-sungrow.yaml",
        points=SUNGATHER_SH,
        notes=(
            SUNGATHER_READS,
            "one row list for string and hybrid inverters: total_power_yields (5004) has no "
            "accuracy, so whole kWh, where mkaiser reads the hybrid's row in 0.1 kWh",
            "system state (13000) 0x2 stop .. 0x4000 EMS run; running state bits (13001); "
            "fault words 13050-13078 (U32) without bit lists",
            "holding ems_mode_selection 13050, charge_discharge_command 13051, marked "
            "undocumented (a pull request)",
        ),
    ),
    SourceDefinition(
        device="sungrow_sh_rt",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/sungrow-hybrid.yaml",
        points=EVCC_SH,
        notes=(
            "int32s/uint32s: 32-bit, low word first",
            "grid power is export power (13009) x -1; the grid currents are the meter phase "
            "powers divided by the inverter's phase voltages",
            "battery power is 13021 (int16) signed by the running state bit 1 or a negative "
            "13020 current (old and new firmware), not mapped here",
            "battery control writes EMS mode 13049, command 13050 and 33047",
        ),
    ),
    SourceDefinition(
        device="sungrow_sh_rt",
        source="openwb",
        ref=f"{OPENWB}:{OPENWB_SUNGROW}/sungrow_sh",
        points=OPENWB_SH,
        notes=(
            "Endian.Little word order for 32-bit values",
            "negates the inverter power (13033), DC power, phase currents, battery power "
            "(5213) and current (5630) and the export power (13009) for its own signs",
            "frequency 5035 / 10; on a WiNet-S a value of 400 or more is divided by 10 again",
            "with the LAN port (version SH) the voltages are the meter's (5740..)",
            "battery writes: EMS mode 13049 (0 or 2), command 13050, power 13051 capped at 5000 W",
        ),
    ),
)

# SunGather/registers-sungrow.yaml: the rows whose models list names the SG-RT (or that have
# none), document number - 1
SUNGATHER_SG = (
    _in("nominal_power", 5000, "u16", "kW", 0.1, "nominal_active_power"),
    _in("daily_energy", 5002, "u16", "kWh", 0.1, "daily_power_yields"),
    _in("total_energy_coarse", 5003, "u32", "kWh", 1, "total_power_yields"),
    _in("total_running_time", 5005, "u32", "h", 1, "total_running_time"),
    _in("inverter_temperature", 5007, "s16", "°C", 0.1, "internal_temperature"),
    _in("apparent_power", 5008, "u32", "VA", 1, "total_apparent_power"),
    _in("mppt1_voltage", 5010, "u16", "V", 0.1, "mppt_1_voltage"),
    _in("mppt1_current", 5011, "u16", "A", 0.1, "mppt_1_current"),
    _in("mppt2_voltage", 5012, "u16", "V", 0.1, "mppt_2_voltage"),
    _in("mppt2_current", 5013, "u16", "A", 0.1, "mppt_2_current"),
    _in("dc_power", 5016, "u32", "W", 1, "total_dc_power"),
    _in("voltage_l1", 5018, "u16", "V", 0.1, "phase_a_voltage"),
    _in("voltage_l2", 5019, "u16", "V", 0.1, "phase_b_voltage"),
    _in("voltage_l3", 5020, "u16", "V", 0.1, "phase_c_voltage"),
    _in("current_l1", 5021, "s16", "A", 0.1, "phase_a_current"),
    _in("current_l2", 5022, "s16", "A", 0.1, "phase_b_current"),
    _in("current_l3", 5023, "s16", "A", 0.1, "phase_c_current"),
    _in("active_power", 5030, "u32", "W", 1, "total_active_power"),
    _in("reactive_power", 5032, "s32", "var", 1, "total_reactive_power"),
    _in("power_factor", 5034, "s16", "", 0.001, "power_factor"),
    _in("grid_frequency_coarse", 5035, "u16", "Hz", 0.1, "grid_frequency"),
    _in("total_energy", 5143, "u32", "kWh", 0.1, "total_power_yields"),
    _in("grid_frequency", 5147, "u16", "Hz", 0.01, "grid_frequency"),
    _hold("power_limitation_setting", 5007, "u16", "%", 0.1, "power_limitation_setting"),
    _hold("power_limitation_adjustment", 5038, "u16", "kW", 0.1, "power_limitation_adjustment"),
)

# templates/definition/meter/sungrow-inverter.yaml (grid and pv usages)
EVCC_SG = (
    _in("total_energy_coarse", 5003, "u32", "kWh", 1, "Total power yields"),
    _in("active_power", 5030, "u32", "W", 1, "Total Active Power"),
    _in("meter_power", 5082, "s32", "W", 1, "Meter power"),
    _in("total_import", 5098, "u32", "kWh", 0.1, "Total import energy"),
)

# sungrow_sg/{inverter,counter}.py
OPENWB_SG = (
    _in("dc_power", 5016, "u32", "W", 1, "dc_power"),
    _in("voltage_l1", 5018, "u16", "V", 0.1, "voltages[0]"),
    _in("voltage_l2", 5019, "u16", "V", 0.1, "voltages[1]"),
    _in("voltage_l3", 5020, "u16", "V", 0.1, "voltages[2]"),
    _in("current_l1", 5021, "s16", "A", 0.1, "currents[0]"),
    _in("current_l2", 5022, "s16", "A", 0.1, "currents[1]"),
    _in("current_l3", 5023, "s16", "A", 0.1, "currents[2]"),
    _in("active_power", 5030, "s32", "W", 1, "inverter power"),
    _in("power_factor", 5034, "s16", "", 0.001, "power_factor"),
    _in("grid_frequency_coarse", 5035, "u16", "Hz", 0.1, "frequency"),
    _in("meter_power", 5082, "s32", "W", 1, "counter power"),
    _in("meter_power_l1", 5084, "s32", "W", 1, "powers[0]"),
    _in("meter_power_l2", 5086, "s32", "W", 1, "powers[1]"),
    _in("meter_power_l3", 5088, "s32", "W", 1, "powers[2]"),
)

# io.openems.edge.sungrow pvinverter/PvInverterSungrowImpl.java; its mV, mA and Wh channels
# (x100 of the 0.1 V, 0.1 A and 0.1 kWh registers) transcribed in V, A and kWh
OPENEMS_SG = (
    _in("nominal_power", 5000, "u16", "W", 100, "NOMINAL_OUTPUT_POWER"),
    _in("daily_energy", 5002, "u16", "kWh", 0.1, "DAILY_ENERGY"),
    _in("total_running_time", 5005, "u32", "h", 1, "TOTAL_RUNNING_TIME"),
    _in("inverter_temperature", 5007, "s16", "°C", 0.1, "INTERNAL_TEMPERATURE"),
    _in("apparent_power", 5008, "u32", "VA", 1, "APPARENT_POWER"),
    _in("mppt1_voltage", 5010, "u16", "V", 0.1, "DC_VOLTAGE_1"),
    _in("mppt1_current", 5011, "u16", "A", 0.1, "DC_CURRENT_1"),
    _in("mppt2_voltage", 5012, "u16", "V", 0.1, "DC_VOLTAGE_2"),
    _in("mppt2_current", 5013, "u16", "A", 0.1, "DC_CURRENT_2"),
    _in("dc_power", 5016, "u32", "W", 1, "DC_POWER"),
    _in("voltage_l1", 5018, "u16", "V", 0.1, "VOLTAGE_L1"),
    _in("voltage_l2", 5019, "u16", "V", 0.1, "VOLTAGE_L2"),
    _in("voltage_l3", 5020, "u16", "V", 0.1, "VOLTAGE_L3"),
    _in("current_l1", 5021, "u16", "A", 0.1, "CURRENT_L1"),
    _in("current_l2", 5022, "u16", "A", 0.1, "CURRENT_L2"),
    _in("current_l3", 5023, "u16", "A", 0.1, "CURRENT_L3"),
    _in("active_power", 5030, "u32", "W", 1, "ACTIVE_POWER"),
    _in("reactive_power", 5032, "s32", "var", 1, "REACTIVE_POWER"),
    _in("power_factor", 5034, "s16", "", 0.001, "POWER_FACTOR"),
    _hold("power_limitation_setting", 5007, "u16", "%", 0.1, "POWER_LIMITATION_SETTING"),
    _hold("power_limitation_adjustment", 5038, "u16", "W", 100, "ACTIVE_POWER_LIMIT"),
)

SG_RT = (
    SourceDefinition(
        device="sungrow_sg_rt",
        source="community:bohdan-s/SunGather",
        ref=f"{SUNGATHER}:SunGather/registers-sungrow.yaml",
        points=SUNGATHER_SG,
        notes=(
            SUNGATHER_READS,
            "phase currents S16: its comment says the document prints unsigned, the inverter "
            "answers signed",
            "work state 1 (5038) codes 0x0 run .. 0x2500 communication fault; alarm code 1 "
            "(5045, also given to the alarm time's second by mistake); work state 2 (5081)",
            "meter, load, import and export rows (5083..5104) listed for the SG-KTL-M and -D "
            "models only, not the SG-RT",
            "holding: start/stop 5006 (0xCF/0xCE), power limitation switch 5007 and export "
            "limitation 5010 (0xAA enable, 0x55 disable), export limitation value 5011 "
            "without a unit",
        ),
    ),
    SourceDefinition(
        device="sungrow_sg_rt",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/sungrow-inverter.yaml",
        points=EVCC_SG,
        notes=(
            "uint32s/int32s: 32-bit, low word first",
            "grid power is the meter power (5082) as read: + importing",
        ),
    ),
    SourceDefinition(
        device="sungrow_sg_rt",
        source="openwb",
        ref=f"{OPENWB}:{OPENWB_SUNGROW}/sungrow_sg",
        points=OPENWB_SG,
        notes=(
            "Endian.Little word order for 32-bit values",
            "negates the inverter power (5030, read signed), DC power and phase currents for "
            "its own signs; reads the meter power (5082) as it is",
        ),
    ),
    SourceDefinition(
        device="sungrow_sg_rt",
        source="openems",
        ref="OpenEMS/openems@519c1f07dde0806f9fdfd0c3691f6b15e65fa381:io.openems.edge.sungrow/"
        "src/io/openems/edge/sungrow/pvinverter/PvInverterSungrowImpl.java",
        points=OPENEMS_SG,
        notes=(
            OPENEMS_CONVENTION,
            "LSWMSW (low word first) for every 32-bit value",
            "reads the phase currents unsigned",
            "frequency 5147 x 10 into mHz (0.01 Hz on the wire; mHz has no unit in this "
            "harness, not listed)",
            "power limitation switch (holding 5006): reads 0xAA as on, writes 0xEE for off",
            "active power limit: holding 5038 x 100 W, written with function 6",
        ),
    ),
)

SH_RT_OPENEMS = SourceDefinition(
    device="sungrow_sh_rt",
    source="openems",
    ref="OpenEMS/openems@18fa9894badd72dea3ff7811b793ed89cda9e794:io.openems.edge.sungrow/"
    "src/io/openems/edge/sungrow/ess/EssSungrowImpl.java",
    points=OPENEMS_SH,
    notes=(
        OPENEMS_CONVENTION,
        "LSWMSW (low word first) for every 32-bit value",
        "takes the nominal output power (5000 x 100) as its maximum apparent power (VA)",
        "grid frequency: 5035 x 10 into mHz, so it reads the row in 0.01 Hz where openWB "
        "and SunGather read 0.1 Hz",
        "daily PV export (13004 x 100) goes into a channel labelled W: not transcribed",
        "battery current and power from the old rows 13020 (u16 x 0.1) and 13021 (u16); "
        "capacity 13038 x 10",
        "EMS mode, command and power (holding 13049-13051) written together with function 16; "
        "a heartbeat at holding 13079 written with function 6",
    ),
)

DEFINITIONS = {"sungrow_sh_rt": (*SH_RT, SH_RT_OPENEMS), "sungrow_sg_rt": SG_RT}
