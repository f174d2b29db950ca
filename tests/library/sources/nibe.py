"""NIBE S-series as the nibe library's register data and evcc read them (facts only).

The nibe library (yozik04/nibe) keeps the pump's own register export per model; its
S1155/S1255 list is transcribed here (the S735, S320/S325, S2125 and SMO S40 lists hold
the same rows at the same registers). evcc's nibe-s-series heating template reads a few
of them. Enum rows (priority, SG-ready state and mode, hot water mode, operating mode)
are left out: the mapping decodes them to labels, which a numeric comparison cannot
check; their registers and values are named in the notes.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC

NIBE = "yozik04/nibe@3f3a9d0a7940fc75ea75a58c0065e6491afdd11a"


def _in(key: str, address: int, type_: str, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "input", address, type_, unit, scale, name=name)


def _in32(key: str, address: int, type_: str, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "input", address, type_, unit, scale, "little", name=name)


def _hold(key: str, address: int, type_: str, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "holding", address, type_, unit, scale, name=name)


# nibe/data/s1155_s1255.csv: "Register" is the wire address (the library keys it +1 with a
# 30000/40000 prefix and subtracts one again on the wire); value = raw / division factor;
# u8/s8 rows sit in one register (u16/s16 here); 32-bit rows low word first
NIBE_S1155 = (
    _in("outdoor_temperature", 1, "s16", "°C", 0.1, "Current outdoor temperature (BT1)"),
    _in("supply_temperature", 5, "s16", "°C", 0.1, "Supply line (BT2)"),
    _in("return_temperature", 7, "s16", "°C", 0.1, "Return line (BT3)"),
    _in("hot_water_top_temperature", 8, "s16", "°C", 0.1, "Hot water top (BT7)"),
    _in("hot_water_charging_temperature", 9, "s16", "°C", 0.1, "Hot water charging (BT6)"),
    _in("brine_in_temperature", 10, "s16", "°C", 0.1, "Brine in (BT10)"),
    _in("brine_out_temperature", 11, "s16", "°C", 0.1, "Brine out (BT11)"),
    _in("room_temperature", 26, "s16", "°C", 0.1, "Roomsensor 1-1"),
    _in("outdoor_temperature_average", 37, "s16", "°C", 0.1, "Average temperature (BT1)"),
    _in(
        "calculated_supply_temperature",
        1017,
        "s16",
        "°C",
        0.1,
        "Calculated supply climate system 1",
    ),
    _in("compressor_frequency", 1046, "u16", "Hz", 0.1, "Compressor frequency, current"),
    _in("compressor_power", 1048, "u16", "W", 1.0, "Compressor power input"),
    _in("alarm_number", 1975, "s16", "", 1.0, "Alarm number"),
    _in32(
        "power_consumption",
        2305,
        "u32",
        "kW",
        0.01,
        "Energy log - Current power consumption",
    ),
    _in32("energy_produced", 3821, "u32", "kWh", 0.1, "Tot. production"),
    _in32("energy_consumed", 3823, "u32", "kWh", 0.1, "Tot. consumption"),
    SourcePoint("degree_minutes", "holding", 11, "s32", "", 0.1, "little", "Degree minutes"),
    _hold("heating_offset", 30, "s16", "", 1.0, "Heating offset climate system 1"),
    _hold("room_set_point", 206, "s16", "°C", 0.1, "Room sensor set point value climate system 1"),
)

# templates/definition/charger/nibe-s-series.yaml (sgready): temp, power, energy, setmaxpower
EVCC_NIBE = (
    _in("hot_water_top_temperature", 8, "u16", "°C", 0.1, "temp (water_top)"),
    _in("hot_water_charging_temperature", 9, "u16", "°C", 0.1, "temp (water_mid)"),
    _in("power_consumption", 2305, "u16", "W", 10.0, "power"),
    _in("energy_consumed", 3823, "u16", "kWh", 0.1, "energy"),
    _hold("power_limit", 6007, "s16", "W", 100.0, "setmaxpower"),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "nibe_s": (
        SourceDefinition(
            device="nibe_s",
            source="community:yozik04/nibe",
            ref=f"{NIBE}:nibe/data/s1155_s1255.csv",
            points=NIBE_S1155,
            notes=(
                "the Register column is the wire address; the library's coil keys are "
                "register + 1 with a 30000 (input) or 40000 (holding) prefix",
                "32-bit values: the library decodes by its word_swap flag; Home Assistant's "
                "integration turns it on for Modbus (low word first), the order the pump "
                "answers reads in (home-assistant/core issue 180379)",
                "the labels: Priority 1028 = 10 off, 20 hot water, 30 heat, 40 pool, "
                "60 cooling; Operating mode (SG Ready) 1911 = 10 normal, 20 high, 30 low "
                "price, 40 free electricity; Hot water demand mode holding 56 = 0 small, "
                "1 medium, 2 large, 4 smart control; Oper. mode holding 237 = 0 auto, "
                "1 manual, 2 add. heat only; Activate SG Ready via API holding 3032 (0/1)",
                "smos40.csv (SMO S40) adds holding 6007 Power limitation (u16, 0.1 kW, "
                "11-1000) and 6008 Requested operating mode (SG Ready) (u8, 0-3); the "
                "S1155/S1255 list transcribed here has neither",
            ),
        ),
        SourceDefinition(
            device="nibe_s",
            source="evcc",
            ref=f"{EVCC}:templates/definition/charger/nibe-s-series.yaml",
            points=EVCC_NIBE,
            notes=(
                "Modbus TCP, unit id 1; requires firmware 4.7.5 and Modbus on in menu 7.5.9",
                "reads the SG-ready state at input 1911 (10 free, 20 block, 30 cheap "
                "energy, 40 forced on, in its own words)",
                "writes holding 6008 (int16) 0 to reduce, 1 for normal, 3 to boost, each "
                "after writing holding 2741 (AUX from Modbus) when power control is on, and "
                "asks the user to write 1 once to holding 3032",
                "reads the energy counter and the power as one uint16 register (the low word "
                "of the pump's u32)",
            ),
        ),
    ),
}
