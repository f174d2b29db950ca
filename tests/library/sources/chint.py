"""Chint DTSU666 and DDSU666 as volkszaehler/mbmd reads them (facts only).

evcc has no Chint template (it names the DTSU666/DDSU666 only as the Huawei power
sensor it reads through the inverter), and neither source has a DDSU666 map.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import MBMD


def _f32(key: str, address: int, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "holding", address, "f32", unit, scale, name=name)


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
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "chint_dtsu666": DTSU666,
    "chint_ddsu666": (),
}
