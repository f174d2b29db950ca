"""The Marstek Venus E (hardware v1/v2) as independent sources read it (facts only).

WargamingPlayer/HA-Marstek-Venus-E-Modbus (a Home Assistant modbus package for an Elfin
EW11 gateway), ViperRNMC/marstek_venus_modbus (a Home Assistant integration, its
registers/e_v12.yaml) and evcc (templates/definition/meter/marstek-venus-e.yaml,
generation 2). All read holding registers (function 3), 32-bit values high word first.
Enums, switches and bit words are not compared (the cross-check compares numbers), nor the
software version (31100), whose decimal point the two integrations place differently.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC

WARGAMINGPLAYER = (
    "WargamingPlayer/HA-Marstek-Venus-E-Modbus@81c84d5fbe08df98981e834451bf9dd2ef0117ce"
)
VIPERRNMC = "ViperRNMC/marstek_venus_modbus@c8e79ed73402aebe617e313b3c7e8ad05194f9a2"


def _h(
    key: str, address: int, kind: str, unit: str, scale: float = 1.0, name: str = ""
) -> SourcePoint:
    return SourcePoint(key, "holding", address, kind, unit, scale, name=name)


# ElfinEW11B/packages/marstek_venus_battery_1_control.yaml: modbus sensors and writes
WARGAMINGPLAYER_VENUS_E = (
    _h("ems_version", 31101, "u16", "", name="EMS version"),
    _h("bms_version", 31102, "u16", "", name="BMS version"),
    _h("battery_voltage", 32100, "u16", "V", 0.01, name="Battery Voltage"),
    _h("battery_current", 32101, "s16", "A", 0.01, name="Battery Current"),
    _h("battery_power", 32102, "s32", "W", name="Battery Power"),
    _h("battery_soc", 32104, "u16", "%", name="Battery SOC"),
    _h("battery_energy", 32105, "u16", "kWh", 0.001, name="Battery Energy"),
    _h("ac_voltage", 32200, "u16", "V", 0.1, name="AC Voltage"),
    _h("ac_current", 32201, "s16", "A", 0.01, name="AC Current"),
    _h("ac_power", 32202, "s32", "W", name="AC Power"),
    _h("ac_frequency", 32204, "u16", "Hz", 0.01, name="AC Frequency"),
    _h("ac_offgrid_voltage", 32300, "u16", "V", 0.1, name="AC Offgrid Voltage"),
    _h("ac_offgrid_current", 32301, "s16", "A", 0.01, name="AC Offgrid Current"),
    _h("ac_offgrid_power", 32302, "s32", "W", name="AC Offgrid Power"),
    _h("energy_charge", 33000, "u32", "kWh", 0.01, name="Total Charging Energy"),
    _h("energy_discharge", 33002, "u32", "kWh", 0.01, name="Total Discharging Energy"),
    _h("internal_temperature", 35000, "s16", "°C", 0.1, name="Internal Temperature"),
    _h("mos1_temperature", 35001, "s16", "°C", 0.1, name="Internal MOS1 Temperature"),
    _h("mos2_temperature", 35002, "s16", "°C", 0.1, name="Internal MOS2 Temperature"),
    _h("max_cell_temperature", 35010, "s16", "°C", name="Max Cell Temperature"),
    _h("min_cell_temperature", 35011, "s16", "°C", name="Min Cell Temperature"),
    _h("max_cell_voltage", 37007, "u16", "V", 0.001, name="Battery Maximum Cell Voltage"),
    _h("min_cell_voltage", 37008, "u16", "V", 0.001, name="Battery Minimum Cell Voltage"),
    _h("charge_to_soc", 42011, "u16", "%", name="Charge to SOC"),
    _h("force_charge_power", 42020, "u16", "W", name="Forcible Charge Power"),
    _h("force_discharge_power", 42021, "u16", "W", name="Forcible Discharge Power"),
)

# custom_components/marstek_modbus/registers/e_v12.yaml (Venus E v1/v2)
VIPERRNMC_VENUS_E = (
    _h("ems_version", 31101, "u16", "", name="ems_version"),
    _h("bms_version", 31102, "u16", "", name="bms_version"),
    _h("battery_voltage", 32100, "u16", "V", 0.01, name="battery_voltage"),
    _h("battery_current", 32101, "s16", "A", 0.01, name="battery_current"),
    _h("battery_power", 32102, "s32", "W", name="battery_power"),
    _h("battery_soc", 32104, "u16", "%", name="battery_soc"),
    _h("battery_energy", 32105, "u16", "kWh", 0.001, name="battery_total_energy"),
    _h("ac_voltage", 32200, "u16", "V", 0.1, name="ac_voltage"),
    _h("ac_current", 32201, "s16", "A", 0.01, name="ac_current"),
    _h("ac_power", 32202, "s32", "W", name="ac_power"),
    _h("ac_frequency", 32204, "s16", "Hz", 0.01, name="ac_frequency"),
    _h("ac_offgrid_voltage", 32300, "u16", "V", 0.1, name="ac_offgrid_voltage"),
    _h("ac_offgrid_current", 32301, "u16", "A", 0.01, name="ac_offgrid_current"),
    _h("ac_offgrid_power", 32302, "s32", "W", name="ac_offgrid_power"),
    _h("energy_charge", 33000, "u32", "kWh", 0.01, name="total_charging_energy"),
    _h("energy_discharge", 33002, "s32", "kWh", 0.01, name="total_discharging_energy"),
    _h("internal_temperature", 35000, "s16", "°C", 0.1, name="internal_temperature"),
    _h("mos1_temperature", 35001, "s16", "°C", 0.1, name="internal_mos1_temperature"),
    _h("mos2_temperature", 35002, "s16", "°C", 0.1, name="internal_mos2_temperature"),
    _h("max_cell_temperature", 35010, "s16", "°C", name="max_cell_temperature"),
    _h("min_cell_temperature", 35011, "s16", "°C", name="min_cell_temperature"),
    _h("max_cell_voltage", 37007, "s16", "V", 0.001, name="max_cell_voltage"),
    _h("min_cell_voltage", 37008, "s16", "V", 0.001, name="min_cell_voltage"),
    _h("modbus_address", 41100, "u16", "", name="modbus_address"),
    _h("charge_to_soc", 42011, "u16", "%", name="charge_to_soc"),
    _h("force_charge_power", 42020, "u16", "W", name="set_charge_power"),
    _h("force_discharge_power", 42021, "u16", "W", name="set_discharge_power"),
    _h("charge_cutoff_soc", 44000, "u16", "%", 0.1, name="charging_cutoff_capacity"),
    _h("discharge_cutoff_soc", 44001, "u16", "%", 0.1, name="discharging_cutoff_capacity"),
    _h("max_charge_power", 44002, "u16", "W", name="max_charge_power"),
    _h("max_discharge_power", 44003, "u16", "W", name="max_discharge_power"),
)

# templates/definition/meter/marstek-venus-e.yaml, generation 2
EVCC_VENUS_E = (
    _h("ac_power", 32202, "s32", "W", name="AC Power"),
    _h("energy_discharge", 33002, "u32", "kWh", 0.01, name="Total energy discharged"),
    _h("battery_soc", 32104, "u16", "%", name="Battery SOC"),
    _h("force_charge_power", 42020, "u16", "W", name="Forcible Charge Power"),
    _h("max_charge_power", 44002, "u16", "W", name="Max Charge Power"),
)

VENUS_E = (
    SourceDefinition(
        device="marstek_venus_e",
        source="community:WargamingPlayer/HA-Marstek-Venus-E-Modbus",
        ref=f"{WARGAMINGPLAYER}:ElfinEW11B/packages/marstek_venus_battery_1_control.yaml",
        points=WARGAMINGPLAYER_VENUS_E,
        notes=(
            "a fork of Superduper1969/MarstekVenus-ElfinEW11; keeps the Duravolt (Marstek "
            "rebrand) protocol PDF, V1.1 of 30-07-2024, whose tables are images",
            "reads one value per request with 35 ms between messages; unit 1",
            "36000 (2 words) and 36100 (4 words) read raw; templates decode the alarm bits: "
            "word 0 bits 0-6, word 1 bits 0-3",
            "35100: 0 sleep, 1 standby, 2 charge, 3 discharge, 4 backup mode or fault, 5 OTA "
            "upgrade, 6 bypass",
            "42000 0x55AA enables, 0x55BB disables RS485 control; 42010 0 stop, 1 charge, "
            "2 discharge; 43000 0 manual, 1 anti-feed, 2 trade (AI)",
            "44000-44003 read as one block: the templates divide 44000/44001 by 10 (SoC %), "
            "44002/44003 are W",
            "41200 backup: 0 = on, 1 = off; 30303 WiFi signal int16 with scale -1 (not "
            "transcribed: a source scale here is positive)",
            "31100 software version x0.1 where ViperRNMC has x0.01 (a version number's "
            "decimal point, not a measurement: not transcribed, the mapping publishes it raw)",
        ),
    ),
    SourceDefinition(
        device="marstek_venus_e",
        source="community:ViperRNMC/marstek_venus_modbus",
        ref=f"{VIPERRNMC}:custom_components/marstek_modbus/registers/e_v12.yaml",
        points=VIPERRNMC_VENUS_E,
        notes=(
            "reads strictly contiguous blocks, 80 ms between messages, unit 1 by default",
            "names every bit of 36000 (alarm: 0-6, 16-19) and 36100 (fault: 0-6, 16-21, "
            "32-35, 48-58) without decoding them in code",
            "reads 32204 and 37007/37008 as int16, 32301 as uint16, the discharge counters "
            "as int32, where WargamingPlayer reads uint16, int16 and uint32",
            "number ranges: 42020/42021 and 44002/44003 0-2500 W, 44000 80-100 %, 44001 "
            "12-30 %, 42011 10-100 %",
            "hardware v3 (e_v3.yaml) has another map (30000-30200, 34000-34017)",
        ),
    ),
    SourceDefinition(
        device="marstek_venus_e",
        source="evcc",
        ref=f"{EVCC}:templates/definition/meter/marstek-venus-e.yaml",
        points=EVCC_VENUS_E,
        notes=(
            "generation 2 (Venus E, Gen 2.0, Venus C); generation 3 reads 30006 (int16 AC "
            "power) and 34002 (SoC x0.1)",
            "serial 115200 8N1",
            "battery modes write 42000 (0x55AA / 0x55BB), 42010, 42020, 43000 and 44002 "
            "with function 6; it leaves RS485 control enabled after hold and charge",
        ),
    ),
)

DEFINITIONS = {"marstek_venus_e": VENUS_E}
