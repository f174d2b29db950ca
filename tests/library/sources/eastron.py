"""Eastron SDM meters as volkszaehler/mbmd and evcc-io/evcc read them (facts only).

All SDM values are IEEE 754 float32, high word first, in input registers, at scale 1.
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
    pick,
)


def _f32(key: str, address: int, unit: str, name: str) -> SourcePoint:
    return SourcePoint(key, "input", address, "f32", unit, name=name)


# meters/rs485/sdm.go (producer "SDM", described as the SDM630 map)
MBMD_SDM630 = (
    _f32("voltage_l1", 0x0000, "V", "VoltageL1"),
    _f32("voltage_l2", 0x0002, "V", "VoltageL2"),
    _f32("voltage_l3", 0x0004, "V", "VoltageL3"),
    _f32("current_l1", 0x0006, "A", "CurrentL1"),
    _f32("current_l2", 0x0008, "A", "CurrentL2"),
    _f32("current_l3", 0x000A, "A", "CurrentL3"),
    _f32("power_l1", 0x000C, "W", "PowerL1"),
    _f32("power_l2", 0x000E, "W", "PowerL2"),
    _f32("power_l3", 0x0010, "W", "PowerL3"),
    _f32("apparent_power_l1", 0x0012, "VA", "ApparentPowerL1"),
    _f32("apparent_power_l2", 0x0014, "VA", "ApparentPowerL2"),
    _f32("apparent_power_l3", 0x0016, "VA", "ApparentPowerL3"),
    _f32("reactive_power_l1", 0x0018, "var", "ReactivePowerL1"),
    _f32("reactive_power_l2", 0x001A, "var", "ReactivePowerL2"),
    _f32("reactive_power_l3", 0x001C, "var", "ReactivePowerL3"),
    _f32("power_factor_l1", 0x001E, "", "CosphiL1"),
    _f32("power_factor_l2", 0x0020, "", "CosphiL2"),
    _f32("power_factor_l3", 0x0022, "", "CosphiL3"),
    _f32("power", 0x0034, "W", "Power"),
    _f32("apparent_power", 0x0038, "VA", "ApparentPower"),
    _f32("reactive_power", 0x003C, "var", "ReactivePower"),
    _f32("power_factor", 0x003E, "", "Cosphi"),
    _f32("phase_angle", 0x0042, "°", "PhaseAngle"),
    _f32("frequency", 0x0046, "Hz", "Frequency"),
    _f32("energy_import", 0x0048, "kWh", "Import"),
    _f32("energy_export", 0x004A, "kWh", "Export"),
    _f32("reactive_energy_import", 0x004C, "kvarh", "ReactiveImport"),
    _f32("reactive_energy_export", 0x004E, "kvarh", "ReactiveExport"),
    _f32("voltage_thd_l1", 0x00EA, "%", "THDL1"),
    _f32("voltage_thd_l2", 0x00EC, "%", "THDL2"),
    _f32("voltage_thd_l3", 0x00EE, "%", "THDL3"),
    _f32("voltage_thd", 0x00F8, "%", "THD"),
    _f32("energy_total", 0x0156, "kWh", "Sum"),
    _f32("reactive_energy_total", 0x0158, "kvarh", "ReactiveSum"),
    _f32("energy_import_l1", 0x015A, "kWh", "ImportL1"),
    _f32("energy_import_l2", 0x015C, "kWh", "ImportL2"),
    _f32("energy_import_l3", 0x015E, "kWh", "ImportL3"),
    _f32("energy_export_l1", 0x0160, "kWh", "ExportL1"),
    _f32("energy_export_l2", 0x0162, "kWh", "ExportL2"),
    _f32("energy_export_l3", 0x0164, "kWh", "ExportL3"),
    _f32("energy_total_l1", 0x0166, "kWh", "SumL1"),
    _f32("energy_total_l2", 0x0168, "kWh", "SumL2"),
    _f32("energy_total_l3", 0x016A, "kWh", "SumL3"),
    _f32("reactive_energy_import_l1", 0x016C, "kvarh", "ReactiveImportL1"),
    _f32("reactive_energy_import_l2", 0x016E, "kvarh", "ReactiveImportL2"),
    _f32("reactive_energy_import_l3", 0x0170, "kvarh", "ReactiveImportL3"),
    _f32("reactive_energy_export_l1", 0x0172, "kvarh", "ReactiveExportL1"),
    _f32("reactive_energy_export_l2", 0x0174, "kvarh", "ReactiveExportL2"),
    _f32("reactive_energy_export_l3", 0x0176, "kvarh", "ReactiveExportL3"),
    _f32("reactive_energy_total_l1", 0x0178, "kvarh", "ReactiveSumL1"),
    _f32("reactive_energy_total_l2", 0x017A, "kvarh", "ReactiveSumL2"),
    _f32("reactive_energy_total_l3", 0x017C, "kvarh", "ReactiveSumL3"),
)

# meters/rs485/sdm120.go
MBMD_SDM120 = (
    _f32("voltage", 0x0000, "V", "Voltage"),
    _f32("current", 0x0006, "A", "Current"),
    _f32("power", 0x000C, "W", "Power"),
    _f32("apparent_power", 0x0012, "VA", "ApparentPower"),
    _f32("reactive_power", 0x0018, "var", "ReactivePower"),
    _f32("power_factor", 0x001E, "", "Cosphi"),
    _f32("frequency", 0x0046, "Hz", "Frequency"),
    _f32("energy_import", 0x0048, "kWh", "Import"),
    _f32("energy_export", 0x004A, "kWh", "Export"),
    _f32("reactive_energy_import", 0x004C, "kvarh", "ReactiveImport"),
    _f32("reactive_energy_export", 0x004E, "kvarh", "ReactiveExport"),
    _f32("energy_total", 0x0156, "kWh", "Sum"),
    _f32("reactive_energy_total", 0x0158, "kvarh", "ReactiveSum"),
)

# meters/rs485/sdm230.go
MBMD_SDM230 = (
    _f32("voltage", 0x0000, "V", "Voltage"),
    _f32("current", 0x0006, "A", "Current"),
    _f32("power", 0x000C, "W", "Power"),
    _f32("apparent_power", 0x0012, "VA", "ApparentPower"),
    _f32("reactive_power", 0x0018, "var", "ReactivePower"),
    _f32("power_factor", 0x001E, "", "Cosphi"),
    _f32("phase_angle", 0x0024, "°", "PhaseAngle"),
    _f32("frequency", 0x0046, "Hz", "Frequency"),
    _f32("energy_import", 0x0048, "kWh", "Import"),
    _f32("energy_export", 0x004A, "kWh", "Export"),
    _f32("reactive_energy_import", 0x004C, "kvarh", "ReactiveImport"),
    _f32("reactive_energy_export", 0x004E, "kvarh", "ReactiveExport"),
    _f32("energy_total", 0x0156, "kWh", "Sum"),
    _f32("reactive_energy_total", 0x0158, "kvarh", "ReactiveSum"),
)

# meters/rs485/sdm220.go: the producer evcc uses for the SDM230 (only what evcc reads)
MBMD_SDM220_READ_BY_EVCC = (
    _f32("power", 0x000C, "W", "Power"),
    _f32("energy_import", 0x0048, "kWh", "Import"),
    _f32("energy_export", 0x004A, "kWh", "Export"),
)

# meters/rs485/sdm72v2.go
MBMD_SDM72V2 = (
    _f32("voltage_l1", 0x0000, "V", "VoltageL1"),
    _f32("voltage_l2", 0x0002, "V", "VoltageL2"),
    _f32("voltage_l3", 0x0004, "V", "VoltageL3"),
    _f32("current_l1", 0x0006, "A", "CurrentL1"),
    _f32("current_l2", 0x0008, "A", "CurrentL2"),
    _f32("current_l3", 0x000A, "A", "CurrentL3"),
    _f32("power_l1", 0x000C, "W", "PowerL1"),
    _f32("power_l2", 0x000E, "W", "PowerL2"),
    _f32("power_l3", 0x0010, "W", "PowerL3"),
    _f32("apparent_power_l1", 0x0012, "VA", "ApparentPowerL1"),
    _f32("apparent_power_l2", 0x0014, "VA", "ApparentPowerL2"),
    _f32("apparent_power_l3", 0x0016, "VA", "ApparentPowerL3"),
    _f32("reactive_power_l1", 0x0018, "var", "ReactivePowerL1"),
    _f32("reactive_power_l2", 0x001A, "var", "ReactivePowerL2"),
    _f32("reactive_power_l3", 0x001C, "var", "ReactivePowerL3"),
    _f32("power_factor_l1", 0x001E, "", "CosphiL1"),
    _f32("power_factor_l2", 0x0020, "", "CosphiL2"),
    _f32("power_factor_l3", 0x0022, "", "CosphiL3"),
    _f32("power", 0x0034, "W", "Power"),
    _f32("apparent_power", 0x0038, "VA", "ApparentPower"),
    _f32("reactive_power", 0x003C, "var", "ReactivePower"),
    _f32("power_factor", 0x003E, "", "Cosphi"),
    _f32("frequency", 0x0046, "Hz", "Frequency"),
    _f32("energy_import", 0x0048, "kWh", "Import"),
    _f32("energy_export", 0x004A, "kWh", "Export"),
    _f32("energy_total", 0x0156, "kWh", "Sum"),
    _f32("reactive_energy_total", 0x0158, "kvarh", "ReactiveSum"),
)


SDM630 = (
    SourceDefinition(
        device="eastron_sdm630",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/sdm.go",
        points=MBMD_SDM630,
        notes=(
            "mbmd reads each value on its own (function 4, 2 registers), never in blocks",
            "mbmd reads no line-to-line voltages, neutral current or demand registers",
        ),
    ),
    SourceDefinition(
        device="eastron_sdm630",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/eastron-sdm72v2_630.yaml",
        points=pick(MBMD_SDM630, EVCC_3P),
        notes=("evcc delegates to mbmd (type mbmd, model sdm)", EVCC_PINS_MBMD, EVCC_PV, EVCC_NAN),
    ),
)

SDM120 = (
    SourceDefinition(
        device="eastron_sdm120",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/sdm120.go",
        points=MBMD_SDM120,
    ),
    SourceDefinition(
        device="eastron_sdm120",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/eastron-sdm120.yaml",
        points=(
            _f32("power", 0x000C, "W", "power"),
            _f32("energy_import", 0x0048, "kWh", "energy"),
            _f32("energy_export", 0x004A, "kWh", "energy (usage pv)"),
        ),
        notes=(
            "evcc's own custom template (decode float32 = high word first), not via mbmd",
            "evcc reads one energy: 0x48 for grid/charge, 0x4a (export) for pv; "
            "with usage pv it negates power",
        ),
    ),
)

SDM230 = (
    SourceDefinition(
        device="eastron_sdm230",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/sdm230.go",
        points=MBMD_SDM230,
    ),
    SourceDefinition(
        device="eastron_sdm230",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/eastron-sdm220_230.yaml",
        points=MBMD_SDM220_READ_BY_EVCC,
        notes=(
            "evcc delegates to mbmd with model sdm220 (meters/rs485/sdm220.go), "
            "not mbmd's SDM230 producer; both list the same registers",
            EVCC_PINS_MBMD,
            EVCC_PV,
            EVCC_NAN,
        ),
    ),
)

SDM72D_M = (
    SourceDefinition(
        device="eastron_sdm72d_m",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/sdm72v2.go",
        points=MBMD_SDM72V2,
        notes=(
            "mbmd's SDM72 (v1) producer (meters/rs485/sdm72.go) reads only power 0x34, "
            "import 0x48, export 0x4a and total 0x156, same addresses and type",
        ),
    ),
    SourceDefinition(
        device="eastron_sdm72d_m",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/eastron-sdm72v2_630.yaml",
        points=pick(MBMD_SDM630, EVCC_3P),
        notes=(
            "evcc lists the SDM72DM-V2 under its SDM630 template and reads it with mbmd's "
            "SDM630 producer (model sdm, meters/rs485/sdm.go), not mbmd's sdm72v2",
            "evcc's eastron-sdm72.yaml (SDM72D-M v1) uses mbmd model sdm72: power, "
            "import and export only",
            EVCC_PINS_MBMD,
            EVCC_PV,
            EVCC_NAN,
        ),
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "eastron_sdm630": SDM630,
    "eastron_sdm120": SDM120,
    "eastron_sdm230": SDM230,
    "eastron_sdm72d_m": SDM72D_M,
}
