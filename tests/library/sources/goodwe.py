"""GoodWe ET/EH/BT/BH hybrids (ARM platform 205) as independent sources read them (facts
only).

Both read holding registers (function 3) at the decimal register number (offset 0),
32-bit values high word first; the meter's energy counters are float32 in Wh.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC

GOODWE = "marcelblijleven/goodwe@66dfcdd9cd947bfd799f2bddb40b4e05ba9db6f6"


def _p(
    key: str, address: int, kind: str, unit: str, scale: float = 1.0, name: str = ""
) -> SourcePoint:
    return SourcePoint(key, "holding", address, kind, unit, scale, name=name)


# goodwe/et.py: class ET (running data 35100+, meter 36000+, battery 37000+, settings)
GOODWE_ET = (
    _p("protocol_version", 35000, "u16", "", 1.0, "modbus_version"),
    _p("rated_power", 35001, "u16", "W", 1.0, "rated_power"),
    _p("pv1_voltage", 35103, "u16", "V", 0.1, "vpv1"),
    _p("pv1_current", 35104, "u16", "A", 0.1, "ipv1"),
    _p("pv1_power", 35105, "u32", "W", 1.0, "ppv1"),
    _p("pv2_voltage", 35107, "u16", "V", 0.1, "vpv2"),
    _p("pv2_current", 35108, "u16", "A", 0.1, "ipv2"),
    _p("pv2_power", 35109, "u32", "W", 1.0, "ppv2"),
    _p("grid_voltage_l1", 35121, "u16", "V", 0.1, "vgrid"),
    _p("grid_current_l1", 35122, "u16", "A", 0.1, "igrid"),
    _p("grid_frequency", 35123, "s16", "Hz", 0.01, "fgrid"),
    _p("inverter_power_l1", 35125, "s16", "W", 1.0, "pgrid"),
    _p("grid_voltage_l2", 35126, "u16", "V", 0.1, "vgrid2"),
    _p("grid_current_l2", 35127, "u16", "A", 0.1, "igrid2"),
    _p("inverter_power_l2", 35130, "s16", "W", 1.0, "pgrid2"),
    _p("grid_voltage_l3", 35131, "u16", "V", 0.1, "vgrid3"),
    _p("grid_current_l3", 35132, "u16", "A", 0.1, "igrid3"),
    _p("inverter_power_l3", 35135, "s16", "W", 1.0, "pgrid3"),
    _p("inverter_power", 35138, "s16", "W", 1.0, "total_inverter_power"),
    _p("grid_power", 35140, "s16", "W", 1.0, "active_power"),
    _p("reactive_power", 35142, "s16", "var", 1.0, "reactive_power"),
    _p("apparent_power", 35144, "s16", "VA", 1.0, "apparent_power"),
    _p("backup_voltage_l1", 35145, "u16", "V", 0.1, "backup_v1"),
    _p("backup_power_l1", 35150, "s16", "W", 1.0, "backup_p1"),
    _p("backup_voltage_l2", 35151, "u16", "V", 0.1, "backup_v2"),
    _p("backup_power_l2", 35156, "s16", "W", 1.0, "backup_p2"),
    _p("backup_voltage_l3", 35157, "u16", "V", 0.1, "backup_v3"),
    _p("backup_power_l3", 35162, "s16", "W", 1.0, "backup_p3"),
    _p("load_power_l1", 35164, "s16", "W", 1.0, "load_p1"),
    _p("load_power_l2", 35166, "s16", "W", 1.0, "load_p2"),
    _p("load_power_l3", 35168, "s16", "W", 1.0, "load_p3"),
    _p("backup_power", 35170, "s16", "W", 1.0, "backup_ptotal"),
    _p("load_power", 35172, "s16", "W", 1.0, "load_ptotal"),
    _p("air_temperature", 35174, "s16", "°C", 0.1, "temperature_air"),
    _p("module_temperature", 35175, "s16", "°C", 0.1, "temperature_module"),
    _p("radiator_temperature", 35176, "s16", "°C", 0.1, "temperature"),
    _p("bus_voltage", 35178, "u16", "V", 0.1, "bus_voltage"),
    _p("battery_voltage", 35180, "u16", "V", 0.1, "vbattery1"),
    _p("battery_current", 35181, "s16", "A", 0.1, "ibattery1"),
    _p("battery_power", 35182, "s32", "W", 1.0, "pbattery1"),
    _p("pv_energy_total", 35191, "u32", "kWh", 0.1, "e_total"),
    _p("pv_energy_today", 35193, "u32", "kWh", 0.1, "e_day"),
    _p("grid_export_energy_total", 35195, "u32", "kWh", 0.1, "e_total_exp"),
    _p("run_hours", 35197, "u32", "h", 1.0, "h_total"),
    _p("grid_import_energy_total", 35200, "u32", "kWh", 0.1, "e_total_imp"),
    _p("load_energy_total", 35203, "u32", "kWh", 0.1, "e_load_total"),
    _p("battery_charge_energy_total", 35206, "u32", "kWh", 0.1, "e_bat_charge_total"),
    _p("battery_discharge_energy_total", 35209, "u32", "kWh", 0.1, "e_bat_discharge_total"),
    _p("meter_power_factor", 36013, "s16", "", 0.001, "meter_power_factor"),
    _p("meter_frequency", 36014, "s16", "Hz", 0.01, "meter_freq"),
    _p("meter_export_energy", 36015, "f32", "kWh", 0.001, "meter_e_total_exp"),
    _p("meter_import_energy", 36017, "f32", "kWh", 0.001, "meter_e_total_imp"),
    _p("meter_power_l1", 36019, "s32", "W", 1.0, "meter_active_power1"),
    _p("meter_power_l2", 36021, "s32", "W", 1.0, "meter_active_power2"),
    _p("meter_power_l3", 36023, "s32", "W", 1.0, "meter_active_power3"),
    _p("meter_power", 36025, "s32", "W", 1.0, "meter_active_power_total"),
    _p("battery_temperature", 37003, "s16", "°C", 0.1, "battery_temperature"),
    _p("battery_charge_limit", 37004, "u16", "A", 1.0, "battery_charge_limit"),
    _p("battery_discharge_limit", 37005, "u16", "A", 1.0, "battery_discharge_limit"),
    _p("battery_soc", 37007, "u16", "%", 1.0, "battery_soc"),
    _p("battery_soh", 37008, "u16", "%", 1.0, "battery_soh"),
    _p("export_limit", 47510, "u16", "W", 1.0, "grid_export_limit"),
    _p("ems_power", 47512, "u16", "W", 1.0, "ems_power_limit"),
)

# templates/definition/meter/goodwe-hybrid.yaml (usage grid, pv and battery 1)
EVCC_GOODWE = (
    _p("pv1_power", 35105, "u32", "W", 1.0, "pv power (Ppv1)"),
    _p("pv2_power", 35109, "u32", "W", 1.0, "pv power (Ppv2)"),
    _p("battery_power", 35182, "s32", "W", 1.0, "battery power"),
    _p("pv_energy_total", 35191, "u32", "kWh", 0.1, "pv energy"),
    _p("battery_discharge_energy_total", 35209, "u32", "kWh", 0.1, "battery energy"),
    _p("meter_import_energy", 36017, "f32", "kWh", 0.001, "grid energy"),
    _p("meter_power_l1", 36019, "s32", "W", 1.0, "grid powers L1"),
    _p("meter_power_l2", 36021, "s32", "W", 1.0, "grid powers L2"),
    _p("meter_power_l3", 36023, "s32", "W", 1.0, "grid powers L3"),
    _p("meter_power", 36025, "s32", "W", 1.0, "grid power"),
    _p("meter_voltage_l1", 36052, "u16", "V", 0.1, "grid voltages L1"),
    _p("meter_voltage_l2", 36053, "u16", "V", 0.1, "grid voltages L2"),
    _p("meter_voltage_l3", 36054, "u16", "V", 0.1, "grid voltages L3"),
    _p("meter_current_l1", 36055, "u16", "A", 0.1, "grid currents L1"),
    _p("meter_current_l2", 36056, "u16", "A", 0.1, "grid currents L2"),
    _p("meter_current_l3", 36057, "u16", "A", 0.1, "grid currents L3"),
    _p("battery_soc", 37007, "u16", "%", 1.0, "battery soc"),
)

GOODWE_ET_DEFINITIONS = (
    SourceDefinition(
        device="goodwe_et",
        source="community:marcelblijleven/goodwe",
        ref=f"{GOODWE}:goodwe/et.py",
        points=GOODWE_ET,
        notes=(
            "talks Modbus RTU frames over UDP 8899 (Wi-Fi dongle) or Modbus TCP 502 (LAN "
            "module), unit 0xF7 (247) by default",
            "tells the family by a model tag in the serial number (35003-35010): ETU, ETL, "
            "ETR, BHN, EHU, BHU, EHR, BTU for platform 205",
            "reads the frequencies signed (s16) where the other values of their kind are unsigned",
            "reads 0xFFFF (0xFFFFFFFF) as undefined and the temperatures' -1 and 32767 as none",
            "also reads the daily counters 35199, 35202, 35205, 35208, 35211 (u16, 0.1 kWh, "
            "0xFFFF undefined): not points here, the shape has no sentinel and the "
            "cross-check's draw for a u16 kWh counter saturates at 0xFFFF, which both read "
            "as not available",
            "reads the meter's 36045-36057 (2nd meter, phase voltages and currents) only on "
            "the 745 platform or from 15 kW: older units refuse them",
            "work mode 35187: 0 wait, 1 normal on grid, 2 normal off grid, 3 fault, 4 flash, "
            "5 check; error bits 35189 (u32); BMS alarm and warning bits at 37006/37012 and "
            "37010/37013",
            "settings: work mode 47000 (0 general, 1 off grid, 2 backup, 3 eco, 4 peak "
            "shaving, 5 self use), export limit switch 47509 and value 47510 (W), EMS mode "
            "47511 (1-12) and power 47512 (W), written with function 6",
        ),
    ),
    SourceDefinition(
        device="goodwe_et",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/goodwe-hybrid.yaml",
        points=EVCC_GOODWE,
        notes=(
            "modbus default 9600 baud, unit 247; offers rs485, tcpip and udp",
            "negates the meter powers (scale -1) into + import: the register and scale are "
            "the same, the sign is evcc's convention",
            "reads the meter's phase voltages and currents (36052-36057) unconditionally "
            "(uint16nan)",
            "battery control writes EMS mode 47511 (function 6) and EMS power 47512 (function 16)",
        ),
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {"goodwe_et": GOODWE_ET_DEFINITIONS}
