"""Phoenix Contact EV Charge Control (EV-CC-AC1-M3-CBC-RCM-ETH) as evcc and nymea's
phoenixconnect plugin read it (facts only). 32-bit values low word first.

Enums (the state letter, the error code) and coils are not points: the harness compares
registers. What each source reads of them is in its notes.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources.upstream import EVCC

NYMEA = "nymea/nymea-plugins-modbus@fcffebb46865b603bbdfd840529eec07e33de45b"


def _in(key: str, address: int, type_: str, unit: str, name: str) -> SourcePoint:
    return SourcePoint(key, "input", address, type_, unit, 1.0, "little", name=name)


def _hold(
    key: str, address: int, type_: str, unit: str, scale: float, name: str, order: str = "big"
) -> SourcePoint:
    return SourcePoint(key, "holding", address, type_, unit, scale, order, name=name)


# charger/phoenix-ev-eth.go (Phoenix firmware: whole amperes at 528, energy u32 at 904)
EVCC_EV_ETH = (
    _in("voltage_l1", 108, "s32", "V", "phxRegVoltages"),
    _in("voltage_l2", 110, "s32", "V", "phxRegVoltages+2"),
    _in("voltage_l3", 112, "s32", "V", "phxRegVoltages+4"),
    _in("current_l1", 114, "s32", "A", "phxRegCurrents"),
    _in("current_l2", 116, "s32", "A", "phxRegCurrents+2"),
    _in("current_l3", 118, "s32", "A", "phxRegCurrents+4"),
    _in("power", 120, "s32", "W", "phxRegPower"),
    _hold("current_limit_setpoint", 528, "u16", "A", 1.0, "phxRegMaxCurrent"),
    _hold("energy", 904, "u32", "kWh", 0.001, "phxRegEnergyWh", "little"),
)

# phoenixconnect/phoenixconnect-registers.json (endianness LittleEndian)
NYMEA_PHOENIX = (
    _in("charging_time", 102, "u32", "s", "chargingTime"),
    _in("voltage_l1", 108, "u32", "V", "voltageI1"),
    _in("voltage_l2", 110, "u32", "V", "voltageI2"),
    _in("voltage_l3", 112, "u32", "V", "voltageI3"),
    _in("current_l1", 114, "u32", "A", "currentI1"),
    _in("current_l2", 116, "u32", "A", "currentI2"),
    _in("current_l3", 118, "u32", "A", "currentI3"),
    _in("power", 120, "u32", "W", "activePower"),
    _hold("signalled_current", 300, "u16", "A", 0.1, "chargingCurrent"),
    _hold("current_limit_setpoint", 528, "u16", "A", 0.1, "maximumChargingCurrent"),
    _hold("energy", 904, "u32", "kWh", 0.001, "totalEnergy", "little"),
)

DEFINITIONS: dict[str, tuple[SourceDefinition, ...]] = {
    "phoenix_contact_ev": (
        SourceDefinition(
            device="phoenix_contact_ev",
            source="evcc",
            ref=f"{EVCC}:charger/phoenix-ev-eth.go",
            points=EVCC_EV_ETH,
            notes=(
                "status: input 100, the low byte as the state letter (A-F)",
                "enable: coil 400 (FC05 on/off); RFID: coil 419, card UID at holding 606",
                "maximum current: holding 528 (FC06) in A; 0.1 A on the extended Wallbe "
                "firmware, detected by 528 reading 60 or more; below 6 A refused",
                "energy: holding 904 u32 Wh low word first (16-bit on Wallbe), Wallbe: "
                "holding 2980 u64 Wh low word first",
                "meter values only offered when voltage L1 reads above 0",
            ),
        ),
        SourceDefinition(
            device="phoenix_contact_ev",
            source="community:nymea/nymea-plugins-modbus",
            ref=f"{NYMEA}:phoenixconnect/phoenixconnect-registers.json",
            points=NYMEA_PHOENIX,
            notes=(
                "written for the Wallbe/Compleo/Scapo-branded controller",
                "status: input 100 as a word compared with 66 (plugged in) and 67 "
                "(charging): the ASCII letter",
                "error code: input 107, 0-15 (no error, cable rejected 13/20 A, cable "
                "rejected 13 A, invalid PP, invalid CP, charging unavailable, lock, unlock, "
                "locking error, overload protection, meter communication error, vehicle "
                "rejected, contactor fault, vehicle CP diode missing, unknown, DC error "
                "current)",
                "coils: 400 charging enabled (RW), 419 RFID enabled, 436 charging allowed "
                "(RO), 468 charging paused (RW)",
                "input 104 DIP switches, 105 firmware (2 registers, text); holding 304 "
                "serial (6), 310 device name (5)",
            ),
        ),
    ),
}
