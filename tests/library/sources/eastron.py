"""Eastron SDM meters as mbmd, evcc, OpenEMS, Tasmota and openWB read them (facts only).

All SDM values are IEEE 754 float32, high word first, in input registers, at scale 1
(one source reads the SDM630 frequency at another: see its notes).
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
    OPENEMS,
    OPENEMS_CONVENTION,
    OPENWB,
    TASMOTA_STYLE,
    pick,
    tasmota_ref,
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


# io.openems.edge.meter.eastron/.../sdm630/MeterEastronSdm630Impl.java (one block, function 4)
OPENEMS_SDM630 = (
    _f32("voltage_l1", 0x0000, "V", "VOLTAGE_L1"),
    _f32("voltage_l2", 0x0002, "V", "VOLTAGE_L2"),
    _f32("voltage_l3", 0x0004, "V", "VOLTAGE_L3"),
    _f32("current_l1", 0x0006, "A", "CURRENT_L1"),
    _f32("current_l2", 0x0008, "A", "CURRENT_L2"),
    _f32("current_l3", 0x000A, "A", "CURRENT_L3"),
    _f32("power_l1", 0x000C, "W", "ACTIVE_POWER_L1"),
    _f32("power_l2", 0x000E, "W", "ACTIVE_POWER_L2"),
    _f32("power_l3", 0x0010, "W", "ACTIVE_POWER_L3"),
    _f32("reactive_power_l1", 0x0018, "var", "REACTIVE_POWER_L1"),
    _f32("reactive_power_l2", 0x001A, "var", "REACTIVE_POWER_L2"),
    _f32("reactive_power_l3", 0x001C, "var", "REACTIVE_POWER_L3"),
    _f32("current_sum", 0x0030, "A", "CURRENT"),
    _f32("power", 0x0034, "W", "ACTIVE_POWER"),
    _f32("reactive_power", 0x003C, "var", "REACTIVE_POWER"),
    SourcePoint("frequency", "input", 0x0046, "f32", "Hz", 0.001, name="FREQUENCY"),
    _f32("reactive_energy_import", 0x004C, "kvarh", "REACTIVE_PRODUCTION_ENERGY"),
    _f32("reactive_energy_export", 0x004E, "kvarh", "REACTIVE_CONSUMPTION_ENERGY"),
)

# io.openems.edge.meter.eastron/.../sdm120/MeterEastronSdm120Impl.java (one block, function 4)
OPENEMS_SDM120 = (
    _f32("voltage", 0x0000, "V", "VOLTAGE"),
    _f32("current", 0x0006, "A", "CURRENT"),
    _f32("power", 0x000C, "W", "ACTIVE_POWER"),
    _f32("reactive_power", 0x0018, "var", "REACTIVE_POWER"),
    _f32("frequency", 0x0046, "Hz", "FREQUENCY"),
)

# xnrg_10_sdm630.ino (default build)
TASMOTA_SDM630 = (
    _f32("voltage_l1", 0x0000, "V", "voltage[0]"),
    _f32("voltage_l2", 0x0002, "V", "voltage[1]"),
    _f32("voltage_l3", 0x0004, "V", "voltage[2]"),
    _f32("current_l1", 0x0006, "A", "current[0]"),
    _f32("current_l2", 0x0008, "A", "current[1]"),
    _f32("current_l3", 0x000A, "A", "current[2]"),
    _f32("power_l1", 0x000C, "W", "active_power[0]"),
    _f32("power_l2", 0x000E, "W", "active_power[1]"),
    _f32("power_l3", 0x0010, "W", "active_power[2]"),
    _f32("reactive_power_l1", 0x0018, "var", "reactive_power[0]"),
    _f32("reactive_power_l2", 0x001A, "var", "reactive_power[1]"),
    _f32("reactive_power_l3", 0x001C, "var", "reactive_power[2]"),
    _f32("power_factor_l1", 0x001E, "", "power_factor[0]"),
    _f32("power_factor_l2", 0x0020, "", "power_factor[1]"),
    _f32("power_factor_l3", 0x0022, "", "power_factor[2]"),
    _f32("frequency", 0x0046, "Hz", "frequency"),
    _f32("energy_import_l1", 0x015A, "kWh", "import_active[0]"),
    _f32("energy_import_l2", 0x015C, "kWh", "import_active[1]"),
    _f32("energy_import_l3", 0x015E, "kWh", "import_active[2]"),
    _f32("energy_export_l1", 0x0160, "kWh", "export_active[0]"),
    _f32("energy_export_l2", 0x0162, "kWh", "export_active[1]"),
    _f32("energy_export_l3", 0x0164, "kWh", "export_active[2]"),
)

# xnrg_08_sdm120.ino (one driver for SDM120 and SDM220)
TASMOTA_SDM120 = (
    _f32("voltage", 0x0000, "V", "voltage"),
    _f32("current", 0x0006, "A", "current"),
    _f32("power", 0x000C, "W", "active_power"),
    _f32("apparent_power", 0x0012, "VA", "apparent_power"),
    _f32("reactive_power", 0x0018, "var", "reactive_power"),
    _f32("power_factor", 0x001E, "", "power_factor"),
    _f32("phase_angle", 0x0024, "°", "phase_angle"),
    _f32("frequency", 0x0046, "Hz", "frequency"),
    _f32("energy_import", 0x0048, "kWh", "import_active"),
    _f32("energy_export", 0x004A, "kWh", "export_active"),
    _f32("reactive_energy_import", 0x004C, "kvarh", "import_reactive"),
    _f32("reactive_energy_export", 0x004E, "kvarh", "export_reactive"),
    _f32("energy_total", 0x0156, "kWh", "total_active"),
)

# xnrg_21_sdm230.ino (default build)
TASMOTA_SDM230 = (
    _f32("voltage", 0x0000, "V", "voltage"),
    _f32("current", 0x0006, "A", "current"),
    _f32("power", 0x000C, "W", "active_power"),
    _f32("apparent_power", 0x0012, "VA", "apparent_power"),
    _f32("reactive_power", 0x0018, "var", "reactive_power"),
    _f32("power_factor", 0x001E, "", "power_factor"),
    _f32("frequency", 0x0046, "Hz", "frequency"),
    _f32("energy_import", 0x0048, "kWh", "import_active"),
    _f32("energy_export", 0x004A, "kWh", "export_active"),
)

# xnrg_18_sdm72.ino (default build)
TASMOTA_SDM72 = (
    _f32("power", 0x0034, "W", "active_power"),
    _f32("energy_total", 0x0156, "kWh", "total_active"),
)

# packages/modules/common/sdm.py: class Sdm630_72 (SDM630 and SDM72) and class Sdm120
OPENWB_SDM630_72 = (
    _f32("voltage_l1", 0x0000, "V", "voltages[0]"),
    _f32("voltage_l2", 0x0002, "V", "voltages[1]"),
    _f32("voltage_l3", 0x0004, "V", "voltages[2]"),
    _f32("current_l1", 0x0006, "A", "currents[0]"),
    _f32("current_l2", 0x0008, "A", "currents[1]"),
    _f32("current_l3", 0x000A, "A", "currents[2]"),
    _f32("power_l1", 0x000C, "W", "powers[0]"),
    _f32("power_l2", 0x000E, "W", "powers[1]"),
    _f32("power_l3", 0x0010, "W", "powers[2]"),
    _f32("power_factor_l1", 0x001E, "", "power_factors[0]"),
    _f32("power_factor_l2", 0x0020, "", "power_factors[1]"),
    _f32("power_factor_l3", 0x0022, "", "power_factors[2]"),
    _f32("frequency", 0x0046, "Hz", "frequency"),
    _f32("energy_import", 0x0048, "kWh", "imported"),
    _f32("energy_export", 0x004A, "kWh", "exported"),
)
OPENWB_SDM120 = (
    _f32("voltage", 0x0000, "V", "voltages[0]"),
    _f32("current", 0x0006, "A", "currents[0]"),
    _f32("power", 0x000C, "W", "power"),
    _f32("power_factor", 0x001E, "", "power_factors[0]"),
    _f32("frequency", 0x0046, "Hz", "frequency"),
    _f32("energy_import", 0x0048, "kWh", "imported"),
    _f32("energy_export", 0x004A, "kWh", "exported"),
)
OPENWB_NOTES = (
    "a frequency above 100 is divided by 10 (a guard for meters that report 0.1 Hz)",
    "also reads the serial number (holding 0xfc00, u32), no entity key",
)
OPENWB_3P = (
    *OPENWB_NOTES,
    "class Sdm630_72 for the SDM630 and the SDM72: blocks 0x00-0x11, 0x1e-0x23, "
    "0x46-0x4b, one read per group after a failed block read",
    "total power is the sum of the phase powers, 0x34 is not read",
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
    SourceDefinition(
        device="eastron_sdm630",
        source="openems",
        ref=f"{OPENEMS}:io.openems.edge.meter.eastron/src/io/openems/edge/meter/eastron/"
        "sdm630/MeterEastronSdm630Impl.java",
        points=OPENEMS_SDM630,
        notes=(
            OPENEMS_CONVENTION,
            "frequency 0x46 goes 1:1 into OpenEMS's mHz channel (no factor 1000, unlike its "
            "SDM120), so OpenEMS takes the float for mHz: scale 0.001 Hz here",
            "0x30 is the sum of the line currents (key current_sum)",
            "OpenEMS reads no active energy register: it integrates power itself",
            "a phase-rotation option may reassign L1..L3 (default L1, L2, L3)",
        ),
    ),
    SourceDefinition(
        device="eastron_sdm630",
        source="tasmota",
        ref=tasmota_ref("38f1a33d38eb091b81003a407d810acab27a8af3", "xnrg_10_sdm630.ino"),
        points=TASMOTA_SDM630,
        notes=(
            TASMOTA_STYLE,
            "it also reads 0x156 (total energy) but leaves it unused; a high-rate build option "
            "reads 0x00-0x23, 0x46 and 0x156-0x165 in three blocks instead",
        ),
    ),
    SourceDefinition(
        device="eastron_sdm630",
        source="openwb",
        ref=f"{OPENWB}:packages/modules/common/sdm.py",
        points=OPENWB_SDM630_72,
        notes=OPENWB_3P,
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
    SourceDefinition(
        device="eastron_sdm120",
        source="openems",
        ref=f"{OPENEMS}:io.openems.edge.meter.eastron/src/io/openems/edge/meter/eastron/"
        "sdm120/MeterEastronSdm120Impl.java",
        points=OPENEMS_SDM120,
        notes=(
            OPENEMS_CONVENTION,
            "OpenEMS reads no energy register: it integrates power itself",
        ),
    ),
    SourceDefinition(
        device="eastron_sdm120",
        source="tasmota",
        ref=tasmota_ref("4001f875cc5ea13d6b14f3ffba090dddbc768226", "xnrg_08_sdm120.ino"),
        points=TASMOTA_SDM120,
        notes=(
            TASMOTA_STYLE,
            "when import 0x48 reads NaN (older SDM120) it stops reading 0x48-0x4e and 0x24 "
            "and counts the total 0x156 as import",
        ),
    ),
    SourceDefinition(
        device="eastron_sdm120",
        source="openwb",
        ref=f"{OPENWB}:packages/modules/common/sdm.py",
        points=OPENWB_SDM120,
        notes=(*OPENWB_NOTES, "class Sdm120: blocks 0x00-0x0d, 0x1e-0x1f, 0x46-0x4b"),
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
    SourceDefinition(
        device="eastron_sdm230",
        source="tasmota",
        ref=tasmota_ref("115105bf7c7b1bcdc783f90bb226d340f1e6d3b1", "xnrg_21_sdm230.ino"),
        points=TASMOTA_SDM230,
        notes=(
            TASMOTA_STYLE,
            "a build option adds phase angle 0x24, max total demand 0x56, resettable total 0x180",
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
    SourceDefinition(
        device="eastron_sdm72d_m",
        source="tasmota",
        ref=tasmota_ref("0446e08613d1507423ab5ff3a80d9281c6ab452f", "xnrg_18_sdm72.ino"),
        points=TASMOTA_SDM72,
        notes=(
            TASMOTA_STYLE,
            "one driver for the SDM72 (no v1/v2 split); it counts the total 0x156 as import",
            "a build option adds import power 0x500, export power 0x502, import 0x48, export 0x4a",
        ),
    ),
    SourceDefinition(
        device="eastron_sdm72d_m",
        source="openwb",
        ref=f"{OPENWB}:packages/modules/common/sdm.py",
        points=OPENWB_SDM630_72,
        notes=OPENWB_3P,
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "eastron_sdm630": SDM630,
    "eastron_sdm120": SDM120,
    "eastron_sdm230": SDM230,
    "eastron_sdm72d_m": SDM72D_M,
}
