"""Huawei SUN2000 inverters as independent sources read them (facts only).

All three read holding registers (function 3), integers high word first, at the decimal
addresses of Huawei's "Solar Inverter Modbus Interface Definitions". wlcrs/huawei-solar-lib
transcribes the document's tables (register, type, gain, unit) for its Home Assistant
integration; evcc's huawei-sun2000 templates and openWB's huawei module read the few points
their energy managers need, with their own sign conventions.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC, OPENWB

HUAWEI_SOLAR_LIB = "wlcrs/huawei-solar-lib@873c1b3b664e1eadad731cf65901dfb54749c529"


def _h(
    key: str, address: int, type_: str, unit: str, scale: float = 1.0, name: str = ""
) -> SourcePoint:
    return SourcePoint(key, "holding", address, type_, unit, scale, name=name)


# src/huawei_solar/registers.py: REGISTERS, PV_REGISTERS, BATTERY_REGISTERS, METER_REGISTERS
# (value = raw / gain)
LIB_SUN2000 = (
    _h("rated_power", 30073, "u32", "W", 1.0, "rated_power"),
    _h("max_active_power", 30075, "u32", "W", 1.0, "P_max"),
    _h("pv1_voltage", 32016, "s16", "V", 0.1, "pv_01_voltage"),
    _h("pv1_current", 32017, "s16", "A", 0.01, "pv_01_current"),
    _h("pv2_voltage", 32018, "s16", "V", 0.1, "pv_02_voltage"),
    _h("pv2_current", 32019, "s16", "A", 0.01, "pv_02_current"),
    _h("pv3_voltage", 32020, "s16", "V", 0.1, "pv_03_voltage"),
    _h("pv3_current", 32021, "s16", "A", 0.01, "pv_03_current"),
    _h("pv4_voltage", 32022, "s16", "V", 0.1, "pv_04_voltage"),
    _h("pv4_current", 32023, "s16", "A", 0.01, "pv_04_current"),
    _h("input_power", 32064, "s32", "W", 1.0, "input_power"),
    _h("voltage_l1_l2", 32066, "u16", "V", 0.1, "line_voltage_A_B"),
    _h("voltage_l2_l3", 32067, "u16", "V", 0.1, "line_voltage_B_C"),
    _h("voltage_l3_l1", 32068, "u16", "V", 0.1, "line_voltage_C_A"),
    _h("voltage_l1", 32069, "u16", "V", 0.1, "phase_A_voltage"),
    _h("voltage_l2", 32070, "u16", "V", 0.1, "phase_B_voltage"),
    _h("voltage_l3", 32071, "u16", "V", 0.1, "phase_C_voltage"),
    _h("current_l1", 32072, "s32", "A", 0.001, "phase_A_current"),
    _h("current_l2", 32074, "s32", "A", 0.001, "phase_B_current"),
    _h("current_l3", 32076, "s32", "A", 0.001, "phase_C_current"),
    _h("peak_power_today", 32078, "s32", "W", 1.0, "day_active_power_peak"),
    _h("power", 32080, "s32", "W", 1.0, "active_power"),
    _h("reactive_power", 32082, "s32", "var", 1.0, "reactive_power"),
    _h("power_factor", 32084, "s16", "", 0.001, "power_factor"),
    _h("frequency", 32085, "u16", "Hz", 0.01, "grid_frequency"),
    _h("efficiency", 32086, "u16", "%", 0.01, "efficiency"),
    _h("internal_temperature", 32087, "s16", "°C", 0.1, "internal_temperature"),
    _h("energy_total", 32106, "u32", "kWh", 0.01, "accumulated_yield_energy"),
    _h("dc_energy_total", 32108, "u32", "kWh", 0.01, "total_dc_input_energy"),
    _h("energy_today", 32114, "u32", "kWh", 0.01, "daily_yield_energy"),
    _h("battery_power", 37001, "s32", "W", 1.0, "storage_unit_1_charge_discharge_power"),
    _h("battery_bus_voltage", 37003, "u16", "V", 0.1, "storage_unit_1_bus_voltage"),
    _h("battery_soc", 37004, "u16", "%", 0.1, "storage_unit_1_state_of_capacity"),
    _h("battery_charge_today", 37015, "u32", "kWh", 0.01, "storage_unit_1_current_day_charge"),
    _h("battery_discharge_today", 37017, "u32", "kWh", 0.01, "storage_unit_1_current_day_dis"),
    _h("battery_bus_current", 37021, "s16", "A", 0.1, "storage_unit_1_bus_current"),
    _h("battery_temperature", 37022, "s16", "°C", 0.1, "storage_unit_1_battery_temperature"),
    _h("battery_rated_charge_power", 37046, "u32", "W", 1.0, "storage_maximum_charge_power"),
    _h("battery_rated_discharge_power", 37048, "u32", "W", 1.0, "storage_maximum_discharge_pow"),
    _h("battery_energy_charged", 37066, "u32", "kWh", 0.01, "storage_unit_1_total_charge"),
    _h("battery_energy_discharged", 37068, "u32", "kWh", 0.01, "storage_unit_1_total_discharge"),
    _h("grid_voltage_l1", 37101, "s32", "V", 0.1, "grid_A_voltage"),
    _h("grid_voltage_l2", 37103, "s32", "V", 0.1, "grid_B_voltage"),
    _h("grid_voltage_l3", 37105, "s32", "V", 0.1, "grid_C_voltage"),
    _h("grid_current_l1", 37107, "s32", "A", 0.01, "active_grid_A_current"),
    _h("grid_current_l2", 37109, "s32", "A", 0.01, "active_grid_B_current"),
    _h("grid_current_l3", 37111, "s32", "A", 0.01, "active_grid_C_current"),
    _h("grid_power", 37113, "s32", "W", 1.0, "power_meter_active_power"),
    _h("grid_reactive_power", 37115, "s32", "var", 1.0, "power_meter_reactive_power"),
    _h("grid_power_factor", 37117, "s16", "", 0.001, "active_grid_power_factor"),
    _h("grid_frequency", 37118, "s16", "Hz", 0.01, "active_grid_frequency"),
    _h("grid_energy_export", 37119, "s32", "kWh", 0.01, "grid_exported_energy"),
    _h("grid_energy_import", 37121, "s32", "kWh", 0.01, "grid_accumulated_energy"),
    _h("grid_voltage_l1_l2", 37126, "s32", "V", 0.1, "active_grid_A_B_voltage"),
    _h("grid_voltage_l2_l3", 37128, "s32", "V", 0.1, "active_grid_B_C_voltage"),
    _h("grid_voltage_l3_l1", 37130, "s32", "V", 0.1, "active_grid_C_A_voltage"),
    _h("grid_power_l1", 37132, "s32", "W", 1.0, "active_grid_A_power"),
    _h("grid_power_l2", 37134, "s32", "W", 1.0, "active_grid_B_power"),
    _h("grid_power_l3", 37136, "s32", "W", 1.0, "active_grid_C_power"),
    _h("storage_capacity", 37758, "u32", "Wh", 1.0, "storage_rated_capacity"),
    _h("storage_soc", 37760, "u16", "%", 0.1, "storage_state_of_capacity"),
    _h("storage_power", 37765, "s32", "W", 1.0, "storage_charge_discharge_power"),
    _h("storage_energy_charged", 37780, "u32", "kWh", 0.01, "storage_total_charge"),
    _h("storage_energy_discharged", 37782, "u32", "kWh", 0.01, "storage_total_discharge"),
    _h("battery_charge_power_limit", 47075, "u32", "W", 1.0, "storage_maximum_charging_power"),
    _h("battery_discharge_power_limit", 47077, "u32", "W", 1.0, "storage_maximum_discharging"),
    _h("battery_charge_cutoff_soc", 47081, "u16", "%", 0.1, "storage_charging_cutoff_capacity"),
    _h("battery_discharge_cutoff_soc", 47082, "u16", "%", 0.1, "storage_discharging_cutoff"),
    _h("forced_period", 47083, "u16", "min", 1.0, "storage_forced_charging_and_dis_period"),
    _h("forced_target_soc", 47101, "u16", "%", 0.1, "storage_forcible_charge_discharge_soc"),
    _h("forced_charge_power", 47247, "u32", "W", 1.0, "storage_forcible_charge_power"),
    _h("forced_discharge_power", 47249, "u32", "W", 1.0, "storage_forcible_discharge_power"),
    _h("export_limit", 47416, "s32", "W", 1.0, "maximum_feed_grid_power_watt"),
    _h("export_limit_percent", 47418, "s16", "%", 0.1, "maximum_feed_grid_power_percent"),
)

# templates/definition/meter/huawei-sun2000-inverter.yaml and huawei-sun2000-hybrid.yaml
# (register scale; evcc's own sign flips are in the notes)
EVCC_SUN2000 = (
    _h("max_active_power", 30075, "u32", "W", 1.0, "maxacpower"),
    _h("input_power", 32064, "s32", "W", 1.0, "pv power"),
    _h("power", 32080, "s32", "W", 1.0, "inverter power"),
    _h("energy_total", 32106, "u32", "kWh", 0.01, "inverter energy"),
    _h("dc_energy_total", 32108, "u32", "kWh", 0.01, "pv energy"),
    _h("battery_rated_charge_power", 37046, "u32", "W", 1.0, "maxchargepower"),
    _h("battery_rated_discharge_power", 37048, "u32", "W", 1.0, "maxdischargepower"),
    _h("grid_voltage_l1", 37101, "s32", "V", 0.1, "voltages[0]"),
    _h("grid_voltage_l2", 37103, "s32", "V", 0.1, "voltages[1]"),
    _h("grid_voltage_l3", 37105, "s32", "V", 0.1, "voltages[2]"),
    _h("grid_current_l1", 37107, "s32", "A", 0.01, "currents[0]"),
    _h("grid_current_l2", 37109, "s32", "A", 0.01, "currents[1]"),
    _h("grid_current_l3", 37111, "s32", "A", 0.01, "currents[2]"),
    _h("grid_power", 37113, "s32", "W", 1.0, "grid power"),
    _h("grid_energy_export", 37119, "u32", "kWh", 0.01, "grid returnenergy"),
    _h("grid_energy_import", 37121, "u32", "kWh", 0.01, "grid energy"),
    _h("grid_power_l1", 37132, "s32", "W", 1.0, "powers[0]"),
    _h("grid_power_l2", 37134, "s32", "W", 1.0, "powers[1]"),
    _h("grid_power_l3", 37136, "s32", "W", 1.0, "powers[2]"),
    _h("storage_capacity", 37758, "u32", "kWh", 0.001, "capacity"),
    _h("storage_soc", 37760, "u16", "%", 0.1, "battery soc"),
    _h("storage_power", 37765, "s32", "W", 1.0, "battery power"),
    _h("storage_energy_charged", 37780, "u32", "kWh", 0.01, "battery returnenergy"),
    _h("storage_energy_discharged", 37782, "u32", "kWh", 0.01, "battery energy"),
    _h("battery_charge_power_limit", 47075, "u32", "W", 1.0, "Max. Charge Power"),
    _h("battery_discharge_power_limit", 47077, "u32", "W", 1.0, "Max. Discharge Power"),
    _h("battery_charge_cutoff_soc", 47081, "u16", "%", 0.1, "maxsoc"),
    _h("battery_discharge_cutoff_soc", 47082, "u16", "%", 0.1, "minsoc"),
    _h("forced_period", 47083, "u16", "min", 1.0, "forced period"),
    _h("forced_charge_power", 47247, "u32", "W", 1.0, "forcible charge power"),
    _h("export_limit_percent", 47418, "u16", "%", 0.1, "maximum feed grid power"),
)

# packages/modules/devices/huawei/huawei/{inverter,counter,bat}.py (register scale; openWB's
# own sign flips are in the notes)
OPENWB_SUN2000 = (
    _h("input_power", 32064, "s32", "W", 1.0, "inverter power"),
    _h("grid_current_l1", 37107, "s32", "A", 0.01, "currents[0]"),
    _h("grid_current_l2", 37109, "s32", "A", 0.01, "currents[1]"),
    _h("grid_current_l3", 37111, "s32", "A", 0.01, "currents[2]"),
    _h("grid_power", 37113, "s32", "W", 1.0, "counter power"),
    _h("storage_soc", 37760, "s16", "%", 0.1, "bat soc"),
    _h("storage_power", 37765, "s32", "W", 1.0, "bat power"),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "huawei_sun2000": (
        SourceDefinition(
            device="huawei_sun2000",
            source="community:wlcrs/huawei-solar-lib",
            ref=f"{HUAWEI_SOLAR_LIB}:src/huawei_solar/registers.py",
            points=LIB_SUN2000,
            notes=(
                "transcribes the document's register tables: U16/I16/U32/I32 big-endian, "
                "value = raw / gain; reads U16 0xFFFF, I16 0x7FFF, U32 0xFFFFFFFF and I32 "
                "0x7FFFFFFF as no value (not for alarm words 1 and 2)",
                "register_values.py gives the device status codes (32089), the state and "
                "alarm bit lists (32000-32010), the storage status, working mode (47086), "
                "forcible charge/discharge (47100, 47246) and active power control mode "
                "(47415) values the mapping's enums and alarm bits follow",
                "the meter's exported energy (37119) is an I32 whose absolute value it "
                "takes: some power sensors report it negative",
                "batches at most 64 registers a read, across gaps of up to 16; waits 1 s "
                "after a TCP connection; default timeout 10 s (the dongle answers slowly)",
                "reads every storage and meter row with 03, writes with 06/16",
            ),
        ),
        SourceDefinition(
            device="huawei_sun2000",
            source="evcc",
            ref=f"{EVCC}:templates/definition/meter/huawei-sun2000-hybrid.yaml",
            points=EVCC_SUN2000,
            notes=(
                "huawei-sun2000-inverter.yaml (pv without battery) reads 32080 and 32106; "
                "huawei-sun2000-hybrid.yaml reads 32064, 32108, the meter block "
                "37101-37137 and the battery block 37760-37783",
                "evcc multiplies the meter's power, phase powers and currents and the "
                "battery power by -1 (its convention: import and discharge positive); the "
                "document's meter power is + for export, battery power + for charging; the "
                "points give the register's own scale",
                "reads the meter's energy counters as uint32 (the document's I32)",
                "connectdelay 1s on the power read; timeout 5 s (hybrid), 15 s (inverter)",
                "writes 47415 (0 unlimited, 7 percent limit) with 47418 (percent x 10), "
                "47087 charge from grid, 47100 forcible charge/discharge (1 charge, 0 "
                "stop) re-written every 30 s, 47083 period 2 min, 47246 mode 0, 47247 "
                "charge power, 47075/47077 clamped to 37046/37048",
            ),
        ),
        SourceDefinition(
            device="huawei_sun2000",
            source="openwb",
            ref=f"{OPENWB}:packages/modules/devices/huawei/huawei",
            points=OPENWB_SUN2000,
            notes=(
                "inverter.py, counter.py, bat.py: one read per value (function 3)",
                "openWB multiplies PV power (32064), the meter currents and the meter "
                "power by -1 (its convention: generation negative, import positive); "
                "battery power as read (+ charging); the points give the register's scale",
                "reads the total SoC 37760 as a signed 16-bit value",
                "device.py: through an SDongle it sleeps 7 s after the connection and 1 s "
                "before each read",
            ),
        ),
    ),
}
