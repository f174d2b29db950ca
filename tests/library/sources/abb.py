"""ABB B23/B24 (A/B-series) as mbmd, evcc, openWB and Victron read them (facts only).

Holding registers, integers high word first; mbmd divides by a scaler (scale = 1/scaler).
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
    OPENWB,
    VICTRON,
    VICTRON_STYLE,
    pick,
)


def _p(key: str, address: int, type_: str, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "holding", address, type_, unit, scale, name=name)


# meters/rs485/abb.go
MBMD_ABB = (
    _p("voltage_l1", 0x5B00, "u32", "V", 0.1, "VoltageL1"),
    _p("voltage_l2", 0x5B02, "u32", "V", 0.1, "VoltageL2"),
    _p("voltage_l3", 0x5B04, "u32", "V", 0.1, "VoltageL3"),
    _p("current_l1", 0x5B0C, "u32", "A", 0.01, "CurrentL1"),
    _p("current_l2", 0x5B0E, "u32", "A", 0.01, "CurrentL2"),
    _p("current_l3", 0x5B10, "u32", "A", 0.01, "CurrentL3"),
    _p("power", 0x5B14, "s32", "W", 0.01, "Power"),
    _p("power_l1", 0x5B16, "s32", "W", 0.01, "PowerL1"),
    _p("power_l2", 0x5B18, "s32", "W", 0.01, "PowerL2"),
    _p("power_l3", 0x5B1A, "s32", "W", 0.01, "PowerL3"),
    _p("frequency", 0x5B2C, "u16", "Hz", 0.01, "Frequency"),
    _p("power_factor", 0x5B3A, "s16", "", 0.001, "Cosphi"),
    _p("power_factor_l1", 0x5B3B, "s16", "", 0.001, "CosphiL1"),
    _p("power_factor_l2", 0x5B3C, "s16", "", 0.001, "CosphiL2"),
    _p("power_factor_l3", 0x5B3D, "s16", "", 0.001, "CosphiL3"),
    _p("energy_import", 0x5000, "u64", "kWh", 0.01, "Import"),
    _p("energy_export", 0x5004, "u64", "kWh", 0.01, "Export"),
    _p("energy_import_l1", 0x5460, "u64", "kWh", 0.01, "ImportL1"),
    _p("energy_import_l2", 0x5464, "u64", "kWh", 0.01, "ImportL2"),
    _p("energy_import_l3", 0x5468, "u64", "kWh", 0.01, "ImportL3"),
    _p("energy_export_l1", 0x546C, "u64", "kWh", 0.01, "ExportL1"),
    _p("energy_export_l2", 0x5470, "u64", "kWh", 0.01, "ExportL2"),
    _p("energy_export_l3", 0x5474, "u64", "kWh", 0.01, "ExportL3"),
)

# packages/modules/common/b23.py (class B23): holding registers, one read per group
OPENWB_B23 = (
    _p("voltage_l1", 0x5B00, "u32", "V", 0.1, "voltages[0]"),
    _p("voltage_l2", 0x5B02, "u32", "V", 0.1, "voltages[1]"),
    _p("voltage_l3", 0x5B04, "u32", "V", 0.1, "voltages[2]"),
    _p("current_l1", 0x5B0C, "u32", "A", 0.01, "currents[0]"),
    _p("current_l2", 0x5B0E, "u32", "A", 0.01, "currents[1]"),
    _p("current_l3", 0x5B10, "u32", "A", 0.01, "currents[2]"),
    _p("power", 0x5B14, "s32", "W", 0.01, "power"),
    _p("power_l1", 0x5B16, "s32", "W", 0.01, "powers[0]"),
    _p("power_l2", 0x5B18, "s32", "W", 0.01, "powers[1]"),
    _p("power_l3", 0x5B1A, "s32", "W", 0.01, "powers[2]"),
    _p("frequency", 0x5B2C, "u16", "Hz", 0.01, "frequency"),
    _p("power_factor_l1", 0x5B3B, "s16", "", 0.001, "power_factors[0]"),
    _p("power_factor_l2", 0x5B3C, "s16", "", 0.001, "power_factors[1]"),
    _p("power_factor_l3", 0x5B3D, "s16", "", 0.001, "power_factors[2]"),
    _p("energy_import", 0x5000, "u64", "Wh", 10.0, "imported"),
    _p("energy_export", 0x5004, "u64", "Wh", 10.0, "exported"),
)

# abb.py (class ABB_Meter_3P: B23, B24)
VICTRON_B23 = (
    _p("power", 0x5B14, "s32", "W", 0.01, "/Ac/Power"),
    _p("frequency", 0x5B2C, "u16", "Hz", 0.01, "/Ac/Frequency"),
    _p("energy_import", 0x5000, "u64", "kWh", 0.01, "/Ac/Energy/Forward"),
    _p("energy_export", 0x5004, "u64", "kWh", 0.01, "/Ac/Energy/Reverse"),
    _p("voltage_l1", 0x5B00, "u32", "V", 0.1, "/Ac/L1/Voltage"),
    _p("current_l1", 0x5B0C, "u32", "A", 0.01, "/Ac/L1/Current"),
    _p("power_factor", 0x5B3A, "s16", "", 0.001, "/Ac/PowerFactor"),
    _p("voltage_l2", 0x5B02, "u32", "V", 0.1, "/Ac/L2/Voltage"),
    _p("voltage_l3", 0x5B04, "u32", "V", 0.1, "/Ac/L3/Voltage"),
    _p("current_l2", 0x5B0E, "u32", "A", 0.01, "/Ac/L2/Current"),
    _p("current_l3", 0x5B10, "u32", "A", 0.01, "/Ac/L3/Current"),
    _p("power_l1", 0x5B16, "s32", "W", 0.01, "/Ac/L1/Power"),
    _p("power_l2", 0x5B18, "s32", "W", 0.01, "/Ac/L2/Power"),
    _p("power_l3", 0x5B1A, "s32", "W", 0.01, "/Ac/L3/Power"),
    _p("energy_import_l1", 0x5460, "u64", "kWh", 0.01, "/Ac/L1/Energy/Forward"),
    _p("energy_import_l2", 0x5464, "u64", "kWh", 0.01, "/Ac/L2/Energy/Forward"),
    _p("energy_import_l3", 0x5468, "u64", "kWh", 0.01, "/Ac/L3/Energy/Forward"),
    _p("energy_export_l1", 0x546C, "u64", "kWh", 0.01, "/Ac/L1/Energy/Reverse"),
    _p("energy_export_l2", 0x5470, "u64", "kWh", 0.01, "/Ac/L2/Energy/Reverse"),
    _p("energy_export_l3", 0x5474, "u64", "kWh", 0.01, "/Ac/L3/Energy/Reverse"),
    _p("power_factor_l1", 0x5B3B, "s16", "", 0.001, "/Ac/L1/PowerFactor"),
    _p("power_factor_l2", 0x5B3C, "s16", "", 0.001, "/Ac/L2/PowerFactor"),
    _p("power_factor_l3", 0x5B3D, "s16", "", 0.001, "/Ac/L3/PowerFactor"),
)

B23 = (
    SourceDefinition(
        device="abb_b23",
        source="mbmd",
        ref=f"{MBMD}:meters/rs485/abb.go",
        points=MBMD_ABB,
        notes=(
            "one producer for the whole ABB A/B series (A43, A44, B23, B24)",
            "unknown value: every register read is 0xFFFF (unsigned types) or 0x7FFF then "
            "0xFFFF... (signed types) and mbmd reports NaN",
            "mbmd reads each value on its own (function 3), never in blocks",
        ),
    ),
    SourceDefinition(
        device="abb_b23",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/abb-ab.yaml",
        points=pick(MBMD_ABB, EVCC_3P),
        notes=(
            "evcc delegates to mbmd (type mbmd, model abb); the template lists A43, A44, B23, B24",
            EVCC_PINS_MBMD,
            EVCC_PV,
            EVCC_NAN,
        ),
    ),
    SourceDefinition(
        device="abb_b23",
        source="openwb",
        ref=f"{OPENWB}:packages/modules/common/b23.py",
        points=OPENWB_B23,
        notes=(
            "unknown value: the whole raw value equal to 0xffff.. (unsigned) or 0x7fff.. "
            "(signed) is reported as none; not checked for export energy",
            "its comment says the document puts the phase power factors at 0x5b3b, 0x5b3d, "
            "0x5b3f and that they are missing on some devices; the code reads 0x5b3b..0x5b3d",
            "also reads the serial number (0x8900, u32), no entity key",
        ),
    ),
    SourceDefinition(
        device="abb_b23",
        source="victron",
        ref=f"{VICTRON}:abb.py",
        points=VICTRON_B23,
        notes=(
            VICTRON_STYLE,
            "identifies the model by holding 0x8960 (u32, ASCII): 'B21 ', 'B23 ', 'B24 '; "
            "serial number 0x8900 (s32), firmware version 0x8908 (8 registers of text)",
            "unknown value: export counters 0xffffffffffffffff, power factors 0x7fff",
        ),
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {"abb_b23": B23}
