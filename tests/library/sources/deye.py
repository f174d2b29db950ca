"""Deye SG04LP3 / SG01HP3 three-phase hybrids as independent sources read them (facts only).

All three read holding registers (function 3) at the decimal register number (offset 0);
32-bit energy totals low word first. The temperatures (0.1 °C, raw offset by 1000) are
read by sunsynk and solarman alike but are not points here: the source shape has no
offset. Enums, bits and text (running state, device type, relays, faults, serial) are
not compared either: only numbers are.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC

SUNSYNK = "kellerza/sunsynk@58193d5de98e272dbcc70d5fc82a0cb5c8044abd"
SOLARMAN = "StephanJoubert/home_assistant_solarman@d4296b16415dc9187a74fbaf249bfd71417c38aa"
OPENWB = "openWB/core@3039a21010759129b7dd182df0e7e183fed28baa"


def _p(
    key: str, address: int, kind: str, unit: str, scale: float = 1.0, name: str = ""
) -> SourcePoint:
    order = "little" if kind in ("u32", "s32") else "big"
    return SourcePoint(key, "holding", address, kind, unit, scale, order, name=name)


def _phases(
    key: str, first: int, kind: str, unit: str, scale: float, name: str
) -> tuple[SourcePoint, ...]:
    return tuple(
        _p(f"{key}_l{i}", first + i - 1, kind, unit, scale, f"{name} L{i}") for i in (1, 2, 3)
    )


# src/sunsynk/definitions/three_phase_common.py + three_phase_lv.py (LV, the default)
SUNSYNK_LV = (
    _p("rated_power", 20, "u32", "W", 0.1, "Rated power"),
    _p("battery_max_charge_current", 108, "u16", "A", 1.0, "Battery Max Charge current"),
    _p("battery_max_discharge_current", 109, "u16", "A", 1.0, "Battery Max Discharge current"),
    _p("max_sell_power", 143, "u16", "W", 1.0, "Export Limit power"),
    _p("battery_charge_energy_today", 514, "u16", "kWh", 0.1, "Day Battery Charge"),
    _p("battery_discharge_energy_today", 515, "u16", "kWh", 0.1, "Day Battery discharge"),
    _p("battery_charge_energy_total", 516, "u32", "kWh", 0.1, "Total Battery Charge"),
    _p("battery_discharge_energy_total", 518, "u32", "kWh", 0.1, "Total Battery Discharge"),
    _p("grid_import_energy_today", 520, "u16", "kWh", 0.1, "Day Grid Import"),
    _p("grid_export_energy_today", 521, "u16", "kWh", 0.1, "Day Grid Export"),
    _p("grid_import_energy_total", 522, "u32", "kWh", 0.1, "Total Grid Import"),
    _p("grid_export_energy_total", 524, "u32", "kWh", 0.1, "Total Grid Export"),
    _p("load_energy_today", 526, "u16", "kWh", 0.1, "Day Load Energy"),
    _p("load_energy_total", 527, "u32", "kWh", 0.1, "Total Load Energy"),
    _p("pv_energy_today", 529, "u16", "kWh", 0.1, "Day PV Energy"),
    _p("pv_energy_total", 534, "u32", "kWh", 0.1, "Total PV Energy"),
    _p("battery_voltage", 587, "u16", "V", 0.01, "Battery voltage"),
    _p("battery_soc", 588, "u16", "%", 1.0, "Battery SOC"),
    _p("battery_power", 590, "s16", "W", 1.0, "Battery power"),
    _p("battery_current", 591, "s16", "A", 0.01, "Battery current"),
    *_phases("grid_voltage", 598, "u16", "V", 0.1, "Grid voltage"),
    _p("grid_frequency", 609, "u16", "Hz", 0.01, "Grid frequency"),
    *_phases("external_ct_power", 616, "s16", "W", 1.0, "Grid CT power"),
    _p("external_ct_power", 619, "s16", "W", 1.0, "Grid CT power"),
    *_phases("grid_power", 622, "s16", "W", 1.0, "Grid power"),
    _p("grid_power", 625, "s16", "W", 1.0, "Grid power"),
    *_phases("inverter_voltage", 627, "u16", "V", 0.1, "Inverter voltage"),
    *_phases("inverter_current", 630, "s16", "A", 0.01, "Inverter current"),
    *_phases("inverter_power", 633, "s16", "W", 1.0, "Inverter power"),
    _p("inverter_power", 636, "s16", "W", 1.0, "Inverter power"),
    _p("inverter_frequency", 638, "u16", "Hz", 0.01, "Inverter frequency"),
    *_phases("load_voltage", 644, "u16", "V", 0.1, "Load voltage"),
    *_phases("load_power", 650, "s16", "W", 1.0, "Load power"),
    _p("load_power", 653, "s16", "W", 1.0, "Load power"),
    _p("pv1_power", 672, "s16", "W", 1.0, "PV1 power"),
    _p("pv2_power", 673, "s16", "W", 1.0, "PV2 power"),
    _p("pv1_voltage", 676, "u16", "V", 0.1, "PV1 voltage"),
    _p("pv1_current", 677, "u16", "A", 0.1, "PV1 current"),
    _p("pv2_voltage", 678, "u16", "V", 0.1, "PV2 voltage"),
    _p("pv2_current", 679, "u16", "A", 0.1, "PV2 current"),
)

# custom_components/solarman/inverter_definitions/deye_sg04lp3.yaml (hex register numbers)
SOLARMAN_SG04LP3 = (
    _p("battery_max_charge_current", 0x006C, "u16", "A", 1.0, "Battery Max A Charge"),
    _p("battery_max_discharge_current", 0x006D, "u16", "A", 1.0, "Battery Max A Discharge"),
    _p("battery_charge_energy_today", 0x0202, "u16", "kWh", 0.1, "Daily Battery Charge"),
    _p("battery_discharge_energy_today", 0x0203, "u16", "kWh", 0.1, "Daily Battery Discharge"),
    _p("battery_charge_energy_total", 0x0204, "u32", "kWh", 0.1, "Total Battery Charge"),
    _p("battery_discharge_energy_total", 0x0206, "u32", "kWh", 0.1, "Total Battery Discharge"),
    _p("grid_import_energy_today", 0x0208, "u16", "kWh", 0.1, "Daily Energy Bought"),
    _p("grid_export_energy_today", 0x0209, "u16", "kWh", 0.1, "Daily Energy Sold"),
    _p("grid_import_energy_total", 0x020A, "u32", "kWh", 0.1, "Total Energy Bought"),
    _p("grid_export_energy_total", 0x020C, "u32", "kWh", 0.1, "Total Energy Sold"),
    _p("load_energy_today", 0x020E, "u16", "kWh", 0.1, "Daily Load Consumption"),
    _p("load_energy_total", 0x020F, "u32", "kWh", 0.1, "Total Load Consumption"),
    _p("pv_energy_today", 0x0211, "u16", "kWh", 0.1, "Daily Production"),
    _p("pv_energy_total", 0x0216, "u32", "kWh", 0.1, "Total Production"),
    _p("battery_voltage", 0x024B, "u16", "V", 0.01, "Battery Voltage"),
    _p("battery_soc", 0x024C, "u16", "%", 1.0, "Battery SOC"),
    _p("battery_power", 0x024E, "s16", "W", 1.0, "Battery Power"),
    _p("battery_current", 0x024F, "s16", "A", 0.01, "Battery Current"),
    *_phases("grid_voltage", 0x0256, "u16", "V", 0.1, "Grid Voltage"),
    *_phases("external_ct_power", 0x0268, "s16", "W", 1.0, "External CT Power"),
    _p("grid_power", 0x0271, "s16", "W", 1.0, "Total Grid Power"),
    *_phases("inverter_current", 0x0276, "s16", "A", 0.01, "Current"),
    *_phases("inverter_power", 0x0279, "s16", "W", 1.0, "Inverter Power"),
    *_phases("load_voltage", 0x0284, "u16", "V", 0.1, "Load Voltage"),
    *_phases("load_power", 0x028A, "u16", "W", 1.0, "Load Power"),
    _p("load_power", 0x028D, "u16", "W", 1.0, "Total Load Power"),
    _p("pv1_power", 0x02A0, "u16", "W", 1.0, "PV1 Power"),
    _p("pv2_power", 0x02A1, "u16", "W", 1.0, "PV2 Power"),
    _p("pv1_voltage", 0x02A4, "u16", "V", 0.1, "PV1 Voltage"),
    _p("pv1_current", 0x02A5, "u16", "A", 0.1, "PV1 Current"),
    _p("pv2_voltage", 0x02A6, "u16", "V", 0.1, "PV2 Voltage"),
    _p("pv2_current", 0x02A7, "u16", "A", 0.1, "PV2 Current"),
)

# templates/definition/meter/deye-hybrid-3p.yaml, batterytype lv (firmware1098 off)
EVCC_LV = (
    _p("battery_max_discharge_current", 109, "u16", "A", 1.0, "Battery Max Discharging Current"),
    _p("max_sell_power", 143, "u16", "W", 1.0, "Max Sell Power"),
    _p("battery_charge_energy_total", 516, "u32", "kWh", 0.1, "battery returnenergy"),
    _p("battery_discharge_energy_total", 518, "u32", "kWh", 0.1, "battery energy"),
    _p("grid_import_energy_total", 522, "u32", "kWh", 0.1, "grid energy"),
    _p("grid_export_energy_total", 524, "u32", "kWh", 0.1, "grid returnenergy"),
    _p("pv_energy_total", 534, "u32", "kWh", 0.1, "pv energy"),
    _p("battery_soc", 588, "u16", "%", 1.0, "battery soc"),
    _p("battery_power", 590, "s16", "W", 1.0, "battery power"),
    *_phases("grid_voltage", 598, "u16", "V", 0.1, "grid voltages"),
    *_phases("external_ct_current", 613, "s16", "A", 0.01, "grid currents"),
    _p("grid_power", 625, "s16", "W", 1.0, "grid power"),
    _p("pv1_power", 672, "u16", "W", 1.0, "pv power (PV1)"),
    _p("pv2_power", 673, "u16", "W", 1.0, "pv power (PV2)"),
)

# packages/modules/devices/deye/deye/{bat,counter,inverter}.py: the three-phase branch (LV
# codes 0x0005/0x0500, HV 0x0006), every register read as INT_16
OPENWB_3P = (
    _p("battery_soc", 588, "s16", "%", 1.0, "bat soc"),
    _p("battery_power", 590, "s16", "W", 1.0, "bat power"),
    _p("grid_frequency", 609, "s16", "Hz", 0.01, "counter frequency"),
    *_phases("external_ct_current", 613, "s16", "A", 0.01, "counter currents"),
    *_phases("external_ct_power", 616, "s16", "W", 1.0, "counter powers"),
    *_phases("load_voltage", 644, "s16", "V", 0.1, "counter voltages"),
    _p("pv1_power", 672, "s16", "W", 1.0, "inverter power (PV1)"),
    _p("pv2_power", 673, "s16", "W", 1.0, "inverter power (PV2)"),
)

EVCC_NOTES = (
    "batterytype lv; with hv: battery power and PV power x10, max sell power in 10 W; "
    "hv with firmware 1098 or newer: energy totals in whole kWh (scale 1)",
    "its grid currents are the CT currents 613-615 ('out-of-grid current')",
    "writes with function 16 (writemultiple): 109, 127, 128, 130, 143, 146 (the whole "
    "word: 0x00FF = time of use on every weekday, 0 = off), 166-171",
)

DEYE_HYBRID = (
    SourceDefinition(
        device="deye_hybrid",
        source="community:kellerza/sunsynk",
        ref=f"{SUNSYNK}:src/sunsynk/definitions/three_phase_lv.py",
        points=SUNSYNK_LV,
        notes=(
            "the LV profile (three_phase_lv.py on top of three_phase_common.py); a negative "
            "factor means signed, so its PV powers are signed where solarman and evcc read "
            "them unsigned",
            "its 16-bit powers are Sensor16 pairs (the V104 high words 687-709 beside the low "
            "words), read as 32 bits only when the high word is steadily non-zero",
            "the HV profile (three_phase_hv.py): battery voltage x0.1 V, battery power x10 W, "
            "PV power x10 W, export limit (143) in 10 W",
            "grid currents 610-612 and CT currents 613-615 are read only as sums, no per-phase "
            "point",
            "device type at register 0 (identity.py): 0x0005/0x0500 LV three-phase, "
            "0x0006/0x0601/0x0602 HV three-phase; running state 500: 0 standby, 1 self-check, "
            "2 ok, 3 alarm, 4 fault, 5 activating; faults 555-558 as F01-F64",
            "temperatures 540, 541, 586: x0.1 minus 100 (not compared: no offset in the shape)",
        ),
    ),
    SourceDefinition(
        device="deye_hybrid",
        source="community:StephanJoubert/home_assistant_solarman",
        ref=f"{SOLARMAN}:custom_components/solarman/inverter_definitions/deye_sg04lp3.yaml",
        points=SOLARMAN_SG04LP3,
        notes=(
            "reads through the Solarman V5 data logger (port 8899), the same holding registers",
            "its load powers (650-653) are unsigned, sunsynk reads them signed",
            "register 630-632 it calls 'Current L1..L3' (the inverter's phase currents)",
            "reads the internal CT powers 604-606 (no entity here) and the alert words "
            "553-558 as one bit field",
            "temperatures 540, 541, 586: (raw - 1000) x 0.1 (not compared: no offset in the shape)",
        ),
    ),
    SourceDefinition(
        device="deye_hybrid",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/deye-hybrid-3p.yaml",
        points=EVCC_LV,
        notes=EVCC_NOTES,
    ),
    SourceDefinition(
        device="deye_hybrid",
        source="openwb",
        ref=f"{OPENWB}:packages/modules/devices/deye/deye/counter.py",
        points=OPENWB_3P,
        notes=(
            "the battery (bat.py) and PV (inverter.py) points are read the same way in the "
            "sibling files of that folder",
            "reads the device type at register 0 first: 0x0005 and 0x0500 LV, 0x0006 HV "
            "three-phase (device_type.py); the HV branch multiplies the battery and PV "
            "powers by 10",
            "every register is read as a signed 16-bit value, the SoC, voltages and "
            "frequency included",
            "negates the battery power (+ charging in openWB) and the PV power (- generation "
            "in openWB): same register and scale",
            "its grid meter takes the CT powers 616-618 summed, the CT currents 613-615 and "
            "the load-side voltages 644-646 as the grid voltages",
        ),
    ),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {"deye_hybrid": DEYE_HYBRID}
