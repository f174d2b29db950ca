"""Alfen Eve (NG9xx) socket registers as evcc and rhernaus/victron-alfen-charger read them
(facts only). Holding registers at the socket's unit (1 or 2), big-endian floats.

The Mode 3 state (a string) is not a point: the harness compares numbers. What each source
reads of it is in its notes.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC

RHERNAUS = "rhernaus/victron-alfen-charger@00a659c2d4dddd46fb57b5f9a4a99a18a7d83ee7"


def _p(key: str, address: int, type_: str, unit: str, scale: float, name: str) -> SourcePoint:
    return SourcePoint(key, "holding", address, type_, unit, scale, name=name)


# charger/alfen.go
EVCC_ALFEN = (
    _p("voltage_l1", 306, "f32", "V", 1.0, "alfenRegVoltages"),
    _p("voltage_l2", 308, "f32", "V", 1.0, "alfenRegVoltages+2"),
    _p("voltage_l3", 310, "f32", "V", 1.0, "alfenRegVoltages+4"),
    _p("current_l1", 320, "f32", "A", 1.0, "alfenRegCurrents"),
    _p("current_l2", 322, "f32", "A", 1.0, "alfenRegCurrents+2"),
    _p("current_l3", 324, "f32", "A", 1.0, "alfenRegCurrents+4"),
    _p("power", 344, "f32", "W", 1.0, "alfenRegPower"),
    _p("energy", 374, "f64", "kWh", 0.001, "alfenRegEnergy"),
    _p("current_limit_setpoint", 1210, "f32", "A", 1.0, "alfenRegAmpsConfig"),
)

# alfen_driver/constants.py with driver.py and controls.py (which registers, how decoded)
RHERNAUS_ALFEN = (
    _p("voltage_l1", 306, "f32", "V", 1.0, "VOLTAGES_L1"),
    _p("voltage_l2", 308, "f32", "V", 1.0, "VOLTAGES_L2"),
    _p("voltage_l3", 310, "f32", "V", 1.0, "VOLTAGES_L3"),
    _p("current_l1", 320, "f32", "A", 1.0, "CURRENTS_L1"),
    _p("current_l2", 322, "f32", "A", 1.0, "CURRENTS_L2"),
    _p("current_l3", 324, "f32", "A", 1.0, "CURRENTS_L3"),
    _p("power_l1", 338, "f32", "W", 1.0, "ACTIVE_POWER_TOTAL"),
    _p("power_l2", 340, "f32", "W", 1.0, "ACTIVE_POWER_TOTAL+2"),
    _p("power_l3", 342, "f32", "W", 1.0, "ACTIVE_POWER_TOTAL+4"),
    _p("power", 344, "f32", "W", 1.0, "ACTIVE_POWER_TOTAL+6"),
    _p("energy", 374, "f64", "kWh", 0.001, "METER_ACTIVE_ENERGY_TOTAL"),
    _p("current_limit", 1206, "f32", "A", 1.0, "SOCKET_MAX_CURRENT"),
    _p("setpoint_valid_time", 1208, "u32", "s", 1.0, "SOCKET_VALID_TIME"),
    _p("current_limit_setpoint", 1210, "f32", "A", 1.0, "SOCKET_MODBUS_MAX_CURRENT"),
    _p("safe_current", 1212, "f32", "A", 1.0, "SOCKET_SAFE_CURRENT"),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "alfen_eve": (
        SourceDefinition(
            device="alfen_eve",
            source="evcc",
            ref=f"{EVCC}:charger/alfen.go",
            points=EVCC_ALFEN,
            notes=(
                "Modbus TCP, unit 1 (template: the second socket of a Double at unit 2)",
                "status: the 5 registers from 1201 as text, A/B/C/D/E/F by the first letter",
                "writes the maximum current as a float32 at 1210 (FC16) and again every 25 s "
                "(the validity time); 0 to disable",
                "phases: reads and writes 1215 (u16 1 or 3, FC06), offered when L2 and L3 read a "
                "voltage (an enum here: not a compared point)",
                "energy: 374 float64 Wh / 1000 (390, consumed, named in a comment)",
            ),
        ),
        SourceDefinition(
            device="alfen_eve",
            source="community:rhernaus/victron-alfen-charger",
            ref=f"{RHERNAUS}:alfen_driver/constants.py",
            points=RHERNAUS_ALFEN,
            notes=(
                "socket registers at unit 1, station registers (100.., 1100..) at unit 200, "
                "as the document (a copy of document 2.3 in reference/)",
                "reads 338-345 in one request (three phases and the sum)",
                "Mode 3 state: 1201-1205 as a string (A, B1, B2, C1, C2, D1, D2, E, F)",
                "writes 1210 as a big-endian float32 and reads it back to verify",
                "phases: 1215 u16 (1 or 3), read and written (an enum here: not a compared point)",
            ),
        ),
    ),
}
