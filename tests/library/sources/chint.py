"""Chint DTSU666 and DDSU666 as independent sources read them (facts only).

evcc has no Chint template (it names the DTSU666/DDSU666 only as the Huawei power
sensor it reads through the inverter) and mbmd has no DDSU666 map; OpenEMS has both,
Tasmota a DDSU666 driver, wschoenell/solariot a DTSU666 reader. All values are float32,
high word first.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import MBMD, OPENEMS_CONVENTION, TASMOTA_STYLE, tasmota_ref

OPENEMS_CHINT = (
    "OpenEMS/openems@{commit}:io.openems.edge.meter.chint/src/io/openems/edge/meter/chint"
)


def _f32(key: str, address: int, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "holding", address, "f32", unit, scale, name=name)


def _f32_input(key: str, address: int, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "input", address, "f32", unit, scale, name=name)


# meters/rs485/dtsu666.go: float32 high word first in holding registers, divided by a scaler
MBMD_DTSU666 = (
    _f32("energy_import", 0x101E, "kWh", 1.0, "Import"),
    _f32("energy_import_l1", 0x1020, "kWh", 1.0, "ImportL1"),
    _f32("energy_import_l2", 0x1022, "kWh", 1.0, "ImportL2"),
    _f32("energy_import_l3", 0x1024, "kWh", 1.0, "ImportL3"),
    _f32("energy_export", 0x1028, "kWh", 1.0, "Export"),
    _f32("energy_export_l1", 0x102A, "kWh", 1.0, "ExportL1"),
    _f32("energy_export_l2", 0x102C, "kWh", 1.0, "ExportL2"),
    _f32("energy_export_l3", 0x102E, "kWh", 1.0, "ExportL3"),
    _f32("voltage_l1", 0x2006, "V", 0.1, "VoltageL1"),
    _f32("voltage_l2", 0x2008, "V", 0.1, "VoltageL2"),
    _f32("voltage_l3", 0x200A, "V", 0.1, "VoltageL3"),
    _f32("current_l1", 0x200C, "A", 0.001, "CurrentL1"),
    _f32("current_l2", 0x200E, "A", 0.001, "CurrentL2"),
    _f32("current_l3", 0x2010, "A", 0.001, "CurrentL3"),
    _f32("power", 0x2012, "W", 0.1, "Power"),
    _f32("power_l1", 0x2014, "W", 0.1, "PowerL1"),
    _f32("power_l2", 0x2016, "W", 0.1, "PowerL2"),
    _f32("power_l3", 0x2018, "W", 0.1, "PowerL3"),
    _f32("reactive_power", 0x201A, "var", 0.1, "ReactivePower"),
    _f32("reactive_power_l1", 0x201C, "var", 0.1, "ReactivePowerL1"),
    _f32("reactive_power_l2", 0x201E, "var", 0.1, "ReactivePowerL2"),
    _f32("reactive_power_l3", 0x2020, "var", 0.1, "ReactivePowerL3"),
    _f32("power_factor", 0x202A, "", 0.001, "Cosphi"),
    _f32("power_factor_l1", 0x202C, "", 0.001, "CosphiL1"),
    _f32("power_factor_l2", 0x202E, "", 0.001, "CosphiL2"),
    _f32("power_factor_l3", 0x2030, "", 0.001, "CosphiL3"),
    _f32("frequency", 0x2044, "Hz", 0.01, "Frequency"),
)

# dtsu666/MeterChintDtsu666Impl.java: input registers (function 4)
OPENEMS_DTSU666 = (
    _f32_input("voltage_l1", 0x2006, "V", 0.1, "VOLTAGE_L1"),
    _f32_input("voltage_l2", 0x2008, "V", 0.1, "VOLTAGE_L2"),
    _f32_input("voltage_l3", 0x200A, "V", 0.1, "VOLTAGE_L3"),
    _f32_input("current_l1", 0x200C, "A", 0.001, "CURRENT_L1"),
    _f32_input("current_l2", 0x200E, "A", 0.001, "CURRENT_L2"),
    _f32_input("current_l3", 0x2010, "A", 0.001, "CURRENT_L3"),
    _f32_input("power", 0x2012, "W", 0.1, "ACTIVE_POWER"),
    _f32_input("power_l1", 0x2014, "W", 0.1, "ACTIVE_POWER_L1"),
    _f32_input("power_l2", 0x2016, "W", 0.1, "ACTIVE_POWER_L2"),
    _f32_input("power_l3", 0x2018, "W", 0.1, "ACTIVE_POWER_L3"),
    _f32_input("power_factor", 0x202A, "", 1.0, "TOTAL_POWER_FACTOR"),
    _f32_input("frequency", 0x2044, "Hz", 0.01, "FREQUENCY"),
    _f32_input("energy_export", 0x4000, "kWh", 1.0, "ACTIVE_CONSUMPTION_ENERGY"),
)

# ddsu666/MeterChintDdsu666Impl.java: holding registers (function 3), raw engineering units
OPENEMS_DDSU666 = (
    _f32("voltage", 0x2000, "V", 1.0, "VOLTAGE_L1"),
    _f32("current", 0x2002, "A", 1.0, "CURRENT_L1"),
    _f32("power", 0x2004, "W", 1000.0, "ACTIVE_POWER"),
    _f32("frequency", 0x200E, "Hz", 1.0, "FREQUENCY"),
    _f32("energy_export", 0x4000, "kWh", 1.0, "ACTIVE_CONSUMPTION_ENERGY"),
)

# tasmota/tasmota_xnrg_energy/xnrg_11_ddsu666.ino: input registers (function 4)
TASMOTA_DDSU666 = (
    _f32_input("voltage", 0x2000, "V", 1.0, "voltage"),
    _f32_input("current", 0x2002, "A", 1.0, "current"),
    _f32_input("power", 0x2004, "W", 1000.0, "active_power"),
    _f32_input("reactive_power", 0x2006, "var", 1000.0, "reactive_power"),
    _f32_input("power_factor", 0x200A, "", 1.0, "power_factor"),
    _f32_input("frequency", 0x200E, "Hz", 1.0, "frequency"),
    _f32_input("energy_import", 0x4000, "kWh", 1.0, "import_active"),
    _f32_input("energy_export", 0x400A, "kWh", 1.0, "export_active"),
)

# wschoenell/solariot dtsu666_meter.py: holding registers, one 2-register read per value
SOLARIOT_DTSU666 = (
    _f32("voltage_l1_l2", 0x2000, "V", 0.1, "Volts_AB"),
    _f32("voltage_l2_l3", 0x2002, "V", 0.1, "Volts_BC"),
    _f32("voltage_l3_l1", 0x2004, "V", 0.1, "Volts_CA"),
    _f32("voltage_l1", 0x2006, "V", 0.1, "Volts_L1"),
    _f32("voltage_l2", 0x2008, "V", 0.1, "Volts_L2"),
    _f32("voltage_l3", 0x200A, "V", 0.1, "Volts_L3"),
    _f32("current_l1", 0x200C, "A", 0.001, "Current_L1"),
    _f32("current_l2", 0x200E, "A", 0.001, "Current_L2"),
    _f32("current_l3", 0x2010, "A", 0.001, "Current_L3"),
    _f32("power", 0x2012, "W", 0.1, "Total_System_Active_Power"),
    _f32("power_l1", 0x2014, "W", 0.1, "Active_Power_L1"),
    _f32("power_l2", 0x2016, "W", 0.1, "Active_Power_L2"),
    _f32("power_l3", 0x2018, "W", 0.1, "Active_Power_L3"),
    _f32("reactive_power", 0x201A, "var", 0.1, "Total_System_Reactive_Power"),
    _f32("reactive_power_l1", 0x201C, "var", 0.1, "Reactive_Power_L1"),
    _f32("reactive_power_l2", 0x201E, "var", 0.1, "Reactive_Power_L2"),
    _f32("reactive_power_l3", 0x2020, "var", 0.1, "Reactive_Power_L3"),
    _f32("power_factor", 0x202A, "", 0.1, "Total_System_Power_Factor"),
    _f32("power_factor_l1", 0x202C, "", 0.001, "Power_Factor_L1"),
    _f32("power_factor_l2", 0x202E, "", 0.001, "Power_Factor_L2"),
    _f32("power_factor_l3", 0x2030, "", 0.001, "Power_Factor_L3"),
    _f32("frequency", 0x2044, "Hz", 0.01, "Frequency_Of_Supply_Voltages"),
    _f32("energy_import", 0x401E, "kWh", 1.0, "Total_import_kwh"),
    _f32("energy_export", 0x4028, "kWh", 1.0, "Total_export_kwh"),
)

DTSU666 = (
    SourceDefinition(
        device="chint_dtsu666",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/dtsu666.go",
        points=MBMD_DTSU666,
        notes=(
            "mbmd reads each value on its own (function 3), never in blocks",
            "the floats carry raw units: voltage in 0.1 V, current in mA, power in 0.1 W "
            "and 0.1 var, power factor in 1/1000, frequency in 0.01 Hz; energy in kWh",
            "mbmd reads no apparent power and no line-to-line voltages",
            "a stored mbmd version at 6a7eced7be4661d2bd8bacb9dfdb88779d2e90ba (not in the "
            "master snapshot) adds a DTSU666-H producer (Huawei firmware) with another map: "
            "current L1..L3 2102/2104/2106, voltage 2110/2112/2114, frequency 2124, power "
            "2126..2132, reactive power 2134..2140, power factor 2144..2150, import 2166, "
            "export 2180 (decimal, float32 holding)",
        ),
    ),
    SourceDefinition(
        device="chint_dtsu666",
        source="openems",
        ref=OPENEMS_CHINT.format(commit="4d8dd72cf6a2c91c64e37cf70f666f11be5e2a06")
        + "/dtsu666/MeterChintDtsu666Impl.java",
        points=OPENEMS_DTSU666,
        notes=(
            OPENEMS_CONVENTION,
            "reads input registers (function 4) where mbmd reads holding (function 3)",
            "energy: one counter at 0x4000 into its consumption energy (negative-power "
            "direction, hence energy_export here), not mbmd's 0x101e import / 0x1028 export",
            "power factor goes 1:1 into an integer channel without unit: OpenEMS keeps "
            "the raw per-mille value (scale 1 here, mbmd 0.001)",
            "reads in three blocks: 0x2006-0x2019, 0x202a-0x202b, 0x2044-0x2045, plus 0x4000",
        ),
    ),
    SourceDefinition(
        device="chint_dtsu666",
        source="community:wschoenell/solariot",
        ref="wschoenell/solariot@24f9b14aca94a2afece9a1c2b519a5218aa1bb26:dtsu666_meter.py",
        points=SOLARIOT_DTSU666,
        notes=(
            "reads the energy counters at 0x401e (import) and 0x4028 (export), where mbmd "
            "reads 0x101e and 0x1028 and OpenEMS reads one counter at 0x4000",
            "it picks each scale by matching the value's name: the total power factor "
            "(0x202a) falls under the power rule (x0.1) where the phase power factors get "
            "x0.001",
            "also reads four reactive quadrant counters from 0x4028 (Q1, the same register as "
            "its export counter) to 0x4050, no library key",
        ),
    ),
)

DDSU666 = (
    SourceDefinition(
        device="chint_ddsu666",
        source="openems",
        ref=OPENEMS_CHINT.format(commit="b80b477a17ae3724787c8545e3684f16f58e2c09")
        + "/ddsu666/MeterChintDdsu666Impl.java",
        points=OPENEMS_DDSU666,
        notes=(
            OPENEMS_CONVENTION,
            "reads holding registers (function 3) where Tasmota reads input (function 4)",
            "power is in kW on the wire (OpenEMS multiplies by 1000)",
            "energy: one counter at 0x4000 into its consumption energy (negative-power "
            "direction, hence energy_export here), where Tasmota reads 0x4000 as import "
            "and 0x400a as export",
            "also reads 0x0006 (u16, the meter's Modbus address), no entity key",
        ),
    ),
    SourceDefinition(
        device="chint_ddsu666",
        source="tasmota",
        ref=tasmota_ref("57c7c6b01564dc00b6fdae37d80369141b091cfb", "xnrg_11_ddsu666.ino"),
        points=TASMOTA_DDSU666,
        notes=(
            TASMOTA_STYLE,
            "reads input registers (function 4)",
            "power and reactive power are kW/kvar on the wire (Tasmota multiplies by 1000)",
        ),
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "chint_dtsu666": DTSU666,
    "chint_ddsu666": DDSU666,
}
