"""ORNO WE-514 and WE-516 as mbmd, evcc, Tasmota and a community bridge read them (facts only).

Holding registers, high word first.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import (
    EVCC,
    EVCC_3P,
    EVCC_NAN,
    EVCC_PINS_MBMD,
    EVCC_PV,
    MBMD,
    TASMOTA_STYLE,
    pick,
    tasmota_ref,
)


def _p(key: str, address: int, type_: str, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "holding", address, type_, unit, scale, name=name)


# meters/rs485/orno1p.go (producer ORNO1p: WE-514, WE-515); the tariff counters it lists
# (SumT1/T2 0xa002/0xa004, ReactiveSumT1/T2 0xa020/0xa022) are never read
MBMD_WE514 = (
    _p("frequency", 0x130, "u16", "Hz", 0.01, "Frequency"),
    _p("voltage", 0x131, "u16", "V", 0.01, "Voltage"),
    _p("current", 0x139, "u32", "A", 0.001, "Current"),
    _p("power", 0x140, "u32", "W", 1.0, "Power"),
    _p("reactive_power", 0x148, "u32", "var", 1.0, "ReactivePower"),
    _p("apparent_power", 0x150, "u32", "VA", 1.0, "ApparentPower"),
    _p("power_factor", 0x158, "u16", "", 0.001, "Cosphi"),
    _p("energy_total", 0xA000, "u32", "kWh", 0.01, "Sum"),
    _p("reactive_energy_total", 0xA01E, "u32", "kvarh", 0.01, "ReactiveSum"),
)


def _f32(key: str, address: int, unit: str, name: str, scale: float = 1.0) -> SourcePoint:
    return _p(key, address, "f32", unit, scale, name)


# meters/rs485/orno3p.go (producer ORNO3p: WE-516, WE-517): float32; powers are in
# kW/kvar/kVA on the wire and mbmd multiplies them by 1000
MBMD_WE516 = (
    _f32("voltage_l1", 0x000E, "V", "VoltageL1"),
    _f32("voltage_l2", 0x0010, "V", "VoltageL2"),
    _f32("voltage_l3", 0x0012, "V", "VoltageL3"),
    _f32("frequency", 0x0014, "Hz", "Frequency"),
    _f32("current_l1", 0x0016, "A", "CurrentL1"),
    _f32("current_l2", 0x0018, "A", "CurrentL2"),
    _f32("current_l3", 0x001A, "A", "CurrentL3"),
    _f32("power", 0x001C, "W", "Power", 1000.0),
    _f32("power_l1", 0x001E, "W", "PowerL1", 1000.0),
    _f32("power_l2", 0x0020, "W", "PowerL2", 1000.0),
    _f32("power_l3", 0x0022, "W", "PowerL3", 1000.0),
    _f32("reactive_power", 0x0024, "var", "ReactivePower", 1000.0),
    _f32("reactive_power_l1", 0x0026, "var", "ReactivePowerL1", 1000.0),
    _f32("reactive_power_l2", 0x0028, "var", "ReactivePowerL2", 1000.0),
    _f32("reactive_power_l3", 0x002A, "var", "ReactivePowerL3", 1000.0),
    _f32("apparent_power", 0x002C, "VA", "ApparentPower", 1000.0),
    _f32("apparent_power_l1", 0x002E, "VA", "ApparentPowerL1", 1000.0),
    _f32("apparent_power_l2", 0x0030, "VA", "ApparentPowerL2", 1000.0),
    _f32("apparent_power_l3", 0x0032, "VA", "ApparentPowerL3", 1000.0),
    _f32("power_factor", 0x0034, "", "Cosphi"),
    _f32("power_factor_l1", 0x0036, "", "CosphiL1"),
    _f32("power_factor_l2", 0x0038, "", "CosphiL2"),
    _f32("power_factor_l3", 0x003A, "", "CosphiL3"),
    _f32("energy_total", 0x0100, "kWh", "Sum"),
    _f32("energy_total_l1", 0x0102, "kWh", "SumL1"),
    _f32("energy_total_l2", 0x0104, "kWh", "SumL2"),
    _f32("energy_total_l3", 0x0106, "kWh", "SumL3"),
    _f32("energy_import", 0x0108, "kWh", "Import"),
    _f32("energy_import_l1", 0x010A, "kWh", "ImportL1"),
    _f32("energy_import_l2", 0x010C, "kWh", "ImportL2"),
    _f32("energy_import_l3", 0x010E, "kWh", "ImportL3"),
    _f32("energy_export", 0x0110, "kWh", "Export"),
    _f32("energy_export_l1", 0x0112, "kWh", "ExportL1"),
    _f32("energy_export_l2", 0x0114, "kWh", "ExportL2"),
    _f32("energy_export_l3", 0x0116, "kWh", "ExportL3"),
    _f32("reactive_energy_total", 0x0118, "kvarh", "ReactiveSum"),
    _f32("reactive_energy_total_l1", 0x011A, "kvarh", "ReactiveSumL1"),
    _f32("reactive_energy_total_l2", 0x011C, "kvarh", "ReactiveSumL2"),
    _f32("reactive_energy_total_l3", 0x011E, "kvarh", "ReactiveSumL3"),
    _f32("reactive_energy_import", 0x0120, "kvarh", "ReactiveImport"),
    _f32("reactive_energy_import_l1", 0x0122, "kvarh", "ReactiveImportL1"),
    _f32("reactive_energy_import_l2", 0x0124, "kvarh", "ReactiveImportL2"),
    _f32("reactive_energy_import_l3", 0x0126, "kvarh", "ReactiveImportL3"),
    _f32("reactive_energy_export", 0x0128, "kvarh", "ReactiveExport"),
    _f32("reactive_energy_export_l1", 0x012A, "kvarh", "ReactiveExportL1"),
    _f32("reactive_energy_export_l2", 0x012C, "kvarh", "ReactiveExportL2"),
    _f32("reactive_energy_export_l3", 0x012E, "kvarh", "ReactiveExportL3"),
    _f32("energy_total_t1", 0x0130, "kWh", "SumT1"),
    _f32("energy_import_t1", 0x0132, "kWh", "ImportT1"),
    _f32("energy_export_t1", 0x0134, "kWh", "ExportT1"),
    _f32("reactive_energy_total_t1", 0x0136, "kvarh", "ReactiveSumT1"),
    _f32("reactive_energy_import_t1", 0x0138, "kvarh", "ReactiveImportT1"),
    _f32("reactive_energy_export_t1", 0x013A, "kvarh", "ReactiveExportT1"),
    _f32("energy_total_t2", 0x013C, "kWh", "SumT2"),
    _f32("energy_import_t2", 0x013E, "kWh", "ImportT2"),
    _f32("energy_export_t2", 0x0140, "kWh", "ExportT2"),
    _f32("reactive_energy_total_t2", 0x0142, "kvarh", "ReactiveSumT2"),
    _f32("reactive_energy_import_t2", 0x0144, "kvarh", "ReactiveImportT2"),
    _f32("reactive_energy_export_t2", 0x0146, "kvarh", "ReactiveExportT2"),
)

# xnrg_17_ornowe517.ino: holding registers (function 3), 8E1
TASMOTA_WE517 = (
    _f32("voltage_l1", 0x000E, "V", "voltage[0]"),
    _f32("voltage_l2", 0x0010, "V", "voltage[1]"),
    _f32("voltage_l3", 0x0012, "V", "voltage[2]"),
    _f32("frequency", 0x0014, "Hz", "frequency"),
    _f32("current_l1", 0x0016, "A", "current[0]"),
    _f32("current_l2", 0x0018, "A", "current[1]"),
    _f32("current_l3", 0x001A, "A", "current[2]"),
    _f32("power_l1", 0x001E, "W", "active_power[0]", 1000.0),
    _f32("power_l2", 0x0020, "W", "active_power[1]", 1000.0),
    _f32("power_l3", 0x0022, "W", "active_power[2]", 1000.0),
    _f32("reactive_power_l1", 0x0026, "var", "reactive_power[0]"),
    _f32("reactive_power_l2", 0x0028, "var", "reactive_power[1]"),
    _f32("reactive_power_l3", 0x002A, "var", "reactive_power[2]"),
    _f32("power_factor_l1", 0x0036, "", "power_factor[0]"),
    _f32("power_factor_l2", 0x0038, "", "power_factor[1]"),
    _f32("power_factor_l3", 0x003A, "", "power_factor[2]"),
    _f32("energy_total", 0x0100, "kWh", "import_active"),
)

# gituser-rk/orno-modbus-mqtt modbus-mqtt.py (minimalmodbus, function 3), the repository
# that hosts the WE-514/515 register description mbmd cites
COMMUNITY_WE514 = (
    _p("frequency", 0x130, "s16", "Hz", 0.01, "Frequency"),
    _p("voltage", 0x131, "s16", "V", 0.01, "Voltage"),
    _p("current", 0x139, "u32", "A", 0.001, "Current"),
    _p("power", 0x140, "u32", "W", 1.0, "ActivePower"),
    _p("reactive_power", 0x148, "u32", "var", 1.0, "ReactivePower"),
    _p("apparent_power", 0x150, "u32", "VA", 1.0, "ApparentPower"),
    _p("power_factor", 0x158, "s16", "", 0.001, "PowerFactor"),
    _p("energy_total", 0xA000, "f64", "kWh", 1.0, "ActiveEnergy"),
    _p("reactive_energy_total", 0xA01E, "f64", "kvarh", 1.0, "ReactiveEnergy"),
)

WE514 = (
    SourceDefinition(
        device="orno_we514",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/orno1p.go",
        points=MBMD_WE514,
        notes=(
            "mbmd reads each value on its own (function 3), never in blocks",
            "power, reactive and apparent power are read unsigned (no export direction)",
            "voltage and frequency are single 16-bit registers in 1/100",
        ),
    ),
    SourceDefinition(
        device="orno_we514",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/orno-we514_515.yaml",
        points=pick(MBMD_WE514, ("power", "energy_total")),
        notes=(
            "evcc delegates to mbmd (type mbmd, model orno1p) and offers it only for usage "
            "pv and charge",
            "evcc takes the total energy 0xa000 (mbmd Sum) as its energy (import) counter",
            EVCC_PINS_MBMD,
            EVCC_NAN,
        ),
    ),
    SourceDefinition(
        device="orno_we514",
        source="community:gituser-rk/orno-modbus-mqtt",
        ref="gituser-rk/orno-modbus-mqtt@36a0a4487ef7e03c9b899fd1d9951107034ad62a:modbus-mqtt.py",
        points=COMMUNITY_WE514,
        notes=(
            "one read per value (minimalmodbus, function 3); 16-bit values read signed",
            "reads the energy counters 0xa000 and 0xa01e as 4-register float64 and publishes "
            "int(value) in kWh/kvarh, where mbmd reads u32 in 0.01 kWh; mbmd's tariff "
            "counters at 0xa002/0xa004 (2 registers apart) fit 32-bit values",
        ),
    ),
)

WE516 = (
    SourceDefinition(
        device="orno_we516",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/orno3p.go",
        points=MBMD_WE516,
        notes=(
            "mbmd reads each value on its own (function 3), never in blocks",
            "the producer's header comment names WE-514/515 but its description and map "
            "are the three-phase WE-516/517",
            "tariff T3/T4 counters (0x148..0x15e) are commented out and not read",
        ),
    ),
    SourceDefinition(
        device="orno_we516",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/orno.yaml",
        points=pick(MBMD_WE516, EVCC_3P),
        notes=(
            "evcc delegates to mbmd (type mbmd, model orno3p); the template lists WE-516 "
            "and WE-517 and sets the serial line to 8E1",
            EVCC_PINS_MBMD,
            EVCC_PV,
            EVCC_NAN,
        ),
    ),
    SourceDefinition(
        device="orno_we516",
        source="tasmota",
        ref=tasmota_ref("133cc25bdb7bbff01e6a2104a789c4ecc6703347", "xnrg_17_ornowe517.ino"),
        points=TASMOTA_WE517,
        notes=(
            TASMOTA_STYLE,
            "a driver for the WE-517 (the MID variant that mbmd and evcc read with the WE-516 map)",
            "active power is taken as kW (x1000) but reactive power as var, unscaled: "
            "mbmd scales reactive power x1000 like active power",
            "it counts the total energy 0x100 as import",
        ),
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "orno_we514": WE514,
    "orno_we516": WE516,
}
